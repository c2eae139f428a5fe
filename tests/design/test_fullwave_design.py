"""Routers designed through Maxwell's equations (splitcam.design.fullwave): the filter and the
projection, the torch reduction against the pattern classes, the image error against the
closed-form LMMSE of the same pattern, and gradients against finite differences."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
import torch

pytest.importorskip("torcwa")

from splitcam.design.fullwave import FullwaveDesign, conic_filter, project, rgb_kernels
from splitcam.patterns.spectral import SpectralPattern
from splitcam.physics.fullwave import (
    FullwaveError,
    RouterDesign,
    quadrant_spectra,
    torcwa_quadrants,
)


def test_the_conic_filter_keeps_the_mean_and_spreads_a_cell_over_its_radius():
    x = torch.zeros(8, 8, dtype=torch.float64)
    x[0, 0] = 1.0  # at the corner: the filter wraps around
    y = conic_filter(x, 2.0)
    assert float(y.sum()) == pytest.approx(1.0)
    # weights max(0, 2 - distance): centre 2, edge neighbours 1, diagonal 2 - sqrt 2
    total = 2 + 4 * 1 + 4 * (2 - math.sqrt(2))
    assert float(y[0, 0]) == pytest.approx(2 / total)
    assert float(y[7, 0]) == pytest.approx(1 / total)  # wrapped
    assert float(y[7, 7]) == pytest.approx((2 - math.sqrt(2)) / total)
    assert float(y[2, 0]) == 0.0  # distance 2: outside
    const = torch.full((5, 7), 0.3, dtype=torch.float64)
    assert torch.allclose(conic_filter(const, 2.5), const)
    assert conic_filter(x, 0.5) is x


def test_the_projection_fixes_0_eta_and_1_and_steepens():
    x = torch.tensor([0.0, 0.25, 0.5, 0.75, 1.0], dtype=torch.float64)
    for beta in (1.0, 8.0, 64.0):
        y = project(x, beta)
        assert float(y[0]) == pytest.approx(0.0, abs=1e-12)
        assert float(y[2]) == pytest.approx(0.5)
        assert float(y[4]) == pytest.approx(1.0)
        assert bool((y[1:] >= y[:-1]).all())
    assert float(project(x, 64.0)[1]) < 1e-6 and float(project(x, 64.0)[3]) > 1 - 1e-6
    assert torch.equal(project(x, 0.0), x)


def test_rgb_kernels_are_the_spectral_patterns_reduction():
    """The torch reduction against SpectralPattern.from_transmission(...).to_pattern(), the
    numpy path every pattern file takes."""
    rng = np.random.default_rng(2)
    lams = [420.0, 480.0, 550.0, 610.0, 680.0]
    t = rng.random((2, 2, len(lams)))
    t /= t.sum(axis=(0, 1), keepdims=True) * 1.05  # a little light lost
    ours = rgb_kernels(torch.from_numpy(t), lams).numpy()
    pattern = SpectralPattern.from_transmission("x", lams, t).to_pattern()
    assert pattern.layout.tolist() == [[0, 1], [2, 3]]
    np.testing.assert_allclose(ours, np.asarray(pattern.kernels), atol=1e-12)
    with pytest.raises(FullwaveError, match="transmission must be"):
        rgb_kernels(torch.zeros(2, 2, 3), lams)


def _lmmse(pattern, photons: float) -> float:
    """The closed-form LMMSE error of a pattern at an exposure (read noise 2 e-, linear light),
    by the path every pattern takes."""
    from splitcam.physics.noise import Exposure
    from splitcam.recon.closed_form import closed_form_mse, shipped_image_statistics

    stats = shipped_image_statistics("linear")
    return float(closed_form_mse(pattern, Exposure(photons, read_noise=2.0), statistics=stats))


def test_the_image_error_is_the_closed_form_lmmse_of_the_pattern():
    rng = np.random.default_rng(3)
    lams = [450.0, 550.0, 650.0]
    t = rng.random((2, 2, 3)) / 4.2
    design = FullwaveDesign(RouterDesign(np.eye(4)), wavelengths=lams, photons=50.0)
    ours = float(design.image_error(torch.from_numpy(t)))
    pattern = SpectralPattern.from_transmission("x", lams, t).to_pattern()
    assert ours == pytest.approx(_lmmse(pattern, 50.0), rel=1e-9)
    # more light, less error
    brighter = FullwaveDesign(RouterDesign(np.eye(4)), wavelengths=lams, photons=500.0)
    assert float(brighter.image_error(torch.from_numpy(t))) < ours


def test_the_image_error_behind_a_stack_is_that_of_the_stacked_pattern():
    """With ``optics``, the loss is the closed-form LMMSE of the spectral pattern behind the
    stack, as the exposure study applies it (OpticalStack.apply): lower transmission in the
    blue (silicon) and none past the IR cut cost image quality."""
    from splitcam.physics.stack import stack_of

    rng = np.random.default_rng(5)
    lams = [433.0, 500.0, 567.0, 633.0, 667.0]
    t = rng.random((2, 2, len(lams))) / 4.2
    optics = stack_of(["silicon", "ir-cut"])
    assert str(stack_of("silicon, ir-cut")) == str(optics)  # the option's text, the same stack
    design = FullwaveDesign(RouterDesign(np.eye(4)), wavelengths=lams, photons=30.0, optics=optics)
    ours = float(design.image_error(torch.from_numpy(t)))
    stacked = optics.apply(SpectralPattern.from_transmission("x", lams, t).to_pattern())
    assert ours == pytest.approx(_lmmse(stacked, 30.0), rel=1e-9)
    bare = FullwaveDesign(RouterDesign(np.eye(4)), wavelengths=lams, photons=30.0)
    assert float(bare.image_error(torch.from_numpy(t))) < ours


def test_a_design_from_saved_settings_is_the_one_built_by_hand():
    """``from_settings`` reads a run's settings as the command writes them: materials given as
    numbers are indices, the feature in µm becomes the filter's radius in cells, ``f_number``
    the cone's directions (0: normal incidence), ``optics`` the stack in front of the pixels."""
    from splitcam.physics.fullwave import cone_directions
    from splitcam.physics.stack import stack_of

    grid = np.eye(8)
    settings = {
        "stack": [1.0, 0.5, 1.0, "2.0", "vacuum", "SiO2"],
        "wavelengths": [460.0, 620.0],
        "photons": 30.0,
        "read_noise": 1.5,
        "f_number": 2.0,
        "order": 3,
        "samples": 8,
        "feature": 0.5,  # µm; the cell is 2 µm / 8 = 0.25 µm
        "solver": "torcwa",
        "terms": None,
    }
    by_hand = FullwaveDesign(
        RouterDesign(grid, 1.0, 0.5, 1.0, 2.0, "vacuum", "SiO2"),
        wavelengths=[460.0, 620.0],
        photons=30.0,
        read_noise=1.5,
        directions=cone_directions(2.0),
        order=3,
        samples=8,
        radius=2.0,
        feature=2,
    )
    ours = FullwaveDesign.from_settings(grid, settings)
    assert repr(ours) == repr(by_hand)
    assert ours.feature_cells == 2 == FullwaveDesign(by_hand.geometry, radius=2.0).feature_cells
    narrow = FullwaveDesign.from_settings(grid, {**settings, "filter": 0.25})
    assert narrow.radius == 1.0 and narrow.feature_cells == 2  # the filter apart from the rule
    assert ours.optics is None
    behind = FullwaveDesign.from_settings(grid, {**settings, "optics": "silicon,ir-cut"})
    assert str(behind.optics) == str(stack_of(["silicon", "ir-cut"]))
    normal = FullwaveDesign.from_settings(grid, {**settings, "f_number": 0})
    assert list(normal.directions) == [(0.0, 0.0, 1.0)]
    with pytest.raises(FullwaveError, match="below the grid step"):
        FullwaveDesign.from_settings(grid, {**settings, "feature": 0.2})


def test_the_solve_is_the_spectra_solve_and_its_gradient_is_the_finite_difference():
    """torcwa_quadrants is what quadrant_spectra solves; its gradient with respect to the
    cell densities matches central differences."""
    rng = np.random.default_rng(1)
    grid = rng.random((4, 4))
    design = RouterDesign(grid, thickness=0.4, depth=0.8)
    x = torch.tensor(grid, requires_grad=True)
    quads, _ = torcwa_quadrants(design, x, 550.0, 0.1, 0.3, order=2, samples=8)
    spectra = quadrant_spectra(design, [550.0], order=2, samples=8, directions=[(0.1, 0.3, 1.0)])
    np.testing.assert_allclose(
        quads.mean(0).detach().numpy(), spectra["transmission"][..., 0], atol=1e-12
    )
    loss = quads.mean(0)[0, 1] - 0.5 * quads.mean(0)[1, 0]
    loss.backward()
    h = 1e-6
    for i, j in [(0, 0), (1, 2), (3, 1)]:
        values = []
        for sign in (1, -1):
            y = torch.tensor(grid)
            y[i, j] += sign * h
            with torch.no_grad():
                q, _ = torcwa_quadrants(design, y, 550.0, 0.1, 0.3, order=2, samples=8)
            values.append(float(q.mean(0)[0, 1] - 0.5 * q.mean(0)[1, 0]))
        fd = (values[0] - values[1]) / (2 * h)
        assert float(x.grad[i, j]) == pytest.approx(fd, rel=1e-5, abs=1e-9)


def test_the_whole_objective_differentiates_to_its_finite_difference():
    """Design variables → filter → projection → RCWA → kernels → LMMSE error: one gradient,
    checked against central differences; and a few steps of gradient descent lower it."""
    rng = np.random.default_rng(4)
    geometry = RouterDesign(rng.random((6, 6)), thickness=0.5, depth=1.0)
    design = FullwaveDesign(
        geometry, wavelengths=[460.0, 620.0], photons=100.0, order=2, samples=8, radius=1.5
    )
    theta = design.start().clone().requires_grad_(True)
    loss, info = design.objective(theta, beta=2.0)
    loss.backward()
    assert info["psnr"] == pytest.approx(-float(loss.detach()))
    h = 1e-5
    for i, j in [(0, 0), (2, 3), (5, 1)]:
        values = []
        for sign in (1, -1):
            y = design.start().clone()
            y[i, j] += sign * h
            with torch.no_grad():
                values.append(float(design.objective(y, beta=2.0)[0]))
        fd = (values[0] - values[1]) / (2 * h)
        assert float(theta.grad[i, j]) == pytest.approx(fd, rel=1e-4, abs=1e-8)
    opt = torch.optim.Adam([theta], lr=0.2)
    first = float(loss.detach())
    for _ in range(5):
        opt.zero_grad()
        loss, _ = design.objective(theta, beta=2.0)
        loss.backward()
        opt.step()
    assert float(design.objective(theta, beta=2.0)[0].detach()) < first
    binary = design.binary(theta, beta=2.0)
    assert set(np.unique(binary)) <= {0.0, 1.0}


def test_the_binarised_layer_is_the_binary_design_with_the_densities_gradient():
    """The straight-through layer: its values are the thresholded design's, its gradient the
    projected densities' (checked against the densities' own backward pass)."""
    rng = np.random.default_rng(7)
    design = FullwaveDesign(RouterDesign(rng.random((6, 6))), radius=1.5)
    theta = torch.from_numpy(rng.normal(size=(6, 6))).requires_grad_(True)
    weights = torch.from_numpy(rng.normal(size=(6, 6)))
    layer = design.binarised(theta, 8.0)
    assert np.array_equal(layer.detach().numpy(), design.binary(theta, 8.0))
    (layer * weights).sum().backward()
    straight = theta.grad.clone()
    theta.grad = None
    (design.densities(theta, 8.0) * weights).sum().backward()
    torch.testing.assert_close(straight, theta.grad)


@pytest.mark.slow  # about a minute: fmmax's solve and its gradient compiled
def test_a_design_solved_by_fmmax_descends_and_the_command_says_its_solver(tmp_path, capsys):
    """The design loss through fmmax's Jones-direct solve (its gradient holds the
    formulation's vector field fixed): a few steps of gradient descent lower it, and the
    command's pattern file and report name the solver and its terms."""
    pytest.importorskip("fmmax")
    from splitcam import patterns
    from splitcam.cli import main

    rng = np.random.default_rng(4)
    geometry = RouterDesign(rng.random((6, 6)), thickness=0.5, depth=1.0)
    design = FullwaveDesign(
        geometry,
        wavelengths=[460.0, 620.0],
        photons=100.0,
        samples=8,
        radius=1.5,
        solver="fmmax-jones",
        terms=21,
    )
    theta = design.start().clone().requires_grad_(True)
    opt = torch.optim.Adam([theta], lr=0.2)
    first = float(design.objective(theta, beta=2.0)[0].detach())
    for _ in range(4):
        opt.zero_grad()
        loss, _ = design.objective(theta, beta=2.0)
        loss.backward()
        opt.step()
    assert float(design.objective(theta, beta=2.0)[0].detach()) < first
    out = tmp_path / "d"
    args = ["optics", "rcwa-design", "noise:6x6", "--steps", "2", "--samples", "8"]
    args += ["--feature", "0.4", "--wavelengths", "460,620", "--quiet", "--out", str(out)]
    assert main([*args, "--solver", "fmmax-jones", "--terms", "21"]) == 0
    assert "fmmax-jones, 21 terms" in patterns.get(str(out / "d.toml")).provenance
    assert "fmmax-jones, 21 terms" in (out / "report.md").read_text()
    capsys.readouterr()
    assert main([*args[:-1], str(tmp_path / "t"), "--terms", "21"]) == 1  # torcwa takes order
    assert "for an fmmax solver" in capsys.readouterr().err


def test_bad_settings_are_refused():
    with pytest.raises(FullwaveError, match="exposure must be > 0"):
        FullwaveDesign(RouterDesign(np.eye(4)), photons=0.0)
    with pytest.raises(FullwaveError, match="radius"):
        FullwaveDesign(RouterDesign(np.eye(4)), radius=-1)
    with pytest.raises(FullwaveError, match=r"feature \(5 cells\) is wider than the layer"):
        FullwaveDesign(RouterDesign(np.eye(4)), radius=5)
    with pytest.raises(FullwaveError, match="density of shape"):
        torcwa_quadrants(RouterDesign(np.eye(4)), torch.zeros(3, 3, dtype=torch.float64), 500.0)
    with pytest.raises(FullwaveError, match="unknown solver 'meep'"):
        FullwaveDesign(RouterDesign(np.eye(4)), solver="meep")
    with pytest.raises(FullwaveError, match="for an fmmax solver"):
        FullwaveDesign(RouterDesign(np.eye(4)), terms=100)
    for workers in (0, 1.5, True):
        with pytest.raises(FullwaveError, match="workers must be an integer >= 1"):
            FullwaveDesign(RouterDesign(np.eye(4)), workers=workers)


@pytest.mark.slow  # about 10 s, most of it starting the workers (the command's test has one)
def test_solves_shared_by_worker_processes_give_the_same_loss_spectra_and_gradient():
    """Behind a cone, two worker processes share a step's solves (forward, then each solve's
    pullback): the loss, the spectra, the reflection and the gradient equal one process's to
    rounding (the workers' single thread sums in another order); leaving the with-block stops
    the workers."""
    from splitcam.physics.fullwave import cone_directions

    rng = np.random.default_rng(11)
    geometry = RouterDesign(rng.random((6, 6)), thickness=0.5, depth=1.0)
    kw = dict(
        wavelengths=[470.0, 610.0], photons=50.0, order=1, samples=4, radius=1.0,
        directions=cone_directions(2.0)[:2],
    )  # fmt: skip
    serial = FullwaveDesign(geometry, **kw)
    with FullwaveDesign(geometry, **kw, workers=2) as pooled:
        results = []
        for design in (serial, pooled):
            theta = design.start().clone().requires_grad_(True)
            loss, info = design.objective(theta, beta=2.0)
            loss.backward()
            results.append((float(loss.detach()), info, theta.grad.clone()))
        (loss1, info1, grad1), (loss2, info2, grad2) = results
        assert loss2 == pytest.approx(loss1, rel=1e-13)
        np.testing.assert_allclose(info2["transmission"], info1["transmission"], rtol=1e-12)
        assert info2["reflection"] == pytest.approx(info1["reflection"], rel=1e-12)
        assert torch.allclose(grad2, grad1, rtol=1e-10, atol=1e-15)
        assert float(grad1.abs().max()) > 0
        with torch.no_grad():  # without a gradient to take: the forward round alone
            t = pooled.transmission(pooled.densities(pooled.start(), 2.0))[0]
        np.testing.assert_allclose(t.numpy(), info1["transmission"], rtol=1e-12)
        assert pooled._pool is not None
    assert pooled._pool is None  # the with-block stopped the workers


@pytest.mark.slow
def test_the_design_command_writes_a_solved_binary_design_and_continues_a_stopped_run(
    tmp_path, capsys, monkeypatch
):
    """`optics rcwa-design` from noise: the binary design, its spectra and pattern file, a
    report; a run stopped after one step and started again ends where an unstopped run ends
    (the design variables and Adam's moments are saved every step), also when the run is
    continued with its solves shared by worker processes (`--workers`)."""
    import splitcam.design.fullwave as fd
    from splitcam import patterns
    from splitcam.cli import main

    args = [
        "optics",
        "rcwa-design",
        "noise:6x6",
        "--steps",
        "3",
        "--order",
        "1",
        "--samples",
        "8",
        "--feature",
        "0.4",
        "--wavelengths",
        "460,620",
        "--binary-steps",
        "2",
        "--binary-lr",
        "0.05",
        "--quiet",
    ]
    assert main([*args, "--out", str(tmp_path / "whole")]) == 0
    files = {p.name for p in (tmp_path / "whole").iterdir()}
    assert {
        "whole.csv",
        "whole-density.csv",
        "whole-spectra.csv",
        "whole.toml",
        "report.md",
        "report.png",
        "state.json",
        "state.safetensors",
    } <= files
    binary = np.loadtxt(tmp_path / "whole" / "whole.csv", delimiter=",")
    assert binary.shape == (6, 6) and set(np.unique(binary)) <= {0.0, 1.0}
    assert (
        "designed through RCWA" in patterns.get(str(tmp_path / "whole" / "whole.toml")).provenance
    )
    said = capsys.readouterr().out
    assert "LMMSE PSNR at N = 100" in said
    # Three steps of continuation, two on the binary layer; the design is the best binary one,
    # and solved again as a binary layer it scores what its step scored.
    history = json.loads((tmp_path / "whole" / "state.json").read_text())["history"]
    assert [r["binary"] for r in history] == [False, False, False, True, True]
    best = max(r["psnr"] for r in history if r["binary"])
    solved_again = float(re.search(r"-> ([0-9.]+) dB \(binary", said)[1])
    assert solved_again == pytest.approx(best, abs=0.006)  # both printed to 0.01 dB
    report = (tmp_path / "whole" / "report.md").read_text()
    assert "best of 2 binary steps" in report
    assert "| the start as given |" in report and "| the design |" in report  # bands
    # The saved settings describe the run's problem: the binary design, solved again through
    # the design they rebuild, scores what the run said.
    settings = json.loads((tmp_path / "whole" / "state.json").read_text())["settings"]
    assert "filter" not in settings  # recorded only where given: older runs continue
    again = fd.FullwaveDesign.from_settings(binary, settings)
    with torch.no_grad():
        t = again.transmission(torch.from_numpy(binary))[0].clamp_min(0.0)
    assert -10 * math.log10(float(again.image_error(t))) == pytest.approx(solved_again, abs=0.006)

    real = fd.FullwaveDesign.objective
    count = {"n": 0}

    def stopping(self, theta, beta, binary=False):
        count["n"] += 1
        if count["n"] in (2, 6):  # once in the continuation, once in the binary steps
            raise KeyboardInterrupt
        return real(self, theta, beta, binary)

    monkeypatch.setattr(fd.FullwaveDesign, "objective", stopping)
    for _ in range(2):
        assert main([*args, "--out", str(tmp_path / "stopped")]) == 130  # Ctrl-C
        assert "interrupted" in capsys.readouterr().err
        assert not (tmp_path / "stopped" / "stopped.csv").exists()
    monkeypatch.setattr(fd.FullwaveDesign, "objective", real)
    # Continued with its solves shared by two worker processes: the same descent.
    assert main([*args, "--workers", "2", "--out", str(tmp_path / "stopped")]) == 0
    a = np.loadtxt(tmp_path / "whole" / "whole-density.csv", delimiter=",")
    b = np.loadtxt(tmp_path / "stopped" / "stopped-density.csv", delimiter=",")
    np.testing.assert_allclose(a, b, atol=1e-4)
    assert np.array_equal(binary, np.loadtxt(tmp_path / "stopped" / "stopped.csv", delimiter=","))
    # Another setting into the same folder is refused, not mixed in.
    assert main([*args[:-1], "--lr", "0.5", "--quiet", "--out", str(tmp_path / "whole")]) == 1
    assert "other settings" in capsys.readouterr().err


def test_the_binary_steps_start_a_fresh_optimiser_at_their_own_rate(tmp_path):
    """Adam's first step moves every variable with a gradient by its learning rate: the first
    binary step, by a fresh optimiser, moves them by ``binary_lr``, whatever the continuation's
    moments were; the design returned is the layer the binary step scored."""
    from splitcam.design.fullwave import run_design
    from splitcam.io.tensorfiles import load_pair

    rng = np.random.default_rng(4)
    design = FullwaveDesign(
        RouterDesign(rng.random((6, 6)), thickness=0.5, depth=1.0),
        wavelengths=[460.0, 620.0],
        order=1,
        samples=8,
        radius=1.5,
    )
    result = run_design(
        design, tmp_path / "b", steps=2, lr=0.5, binary_steps=1, binary_lr=0.01, beta_end=8.0
    )
    after = load_pair(tmp_path / "b" / "state", "splitcam-fullwave-design", 1, "", ValueError)[0]
    continued = run_design(design, tmp_path / "c", steps=2, lr=0.5, beta_end=8.0)["theta"]
    # The binary phase's length may change when a run is continued: three more steps extend
    # it from where it stopped; asking for fewer than were done ends it with the best so far.
    shown = []
    longer = run_design(
        design,
        tmp_path / "b",
        steps=2,
        lr=0.5,
        binary_steps=3,
        binary_lr=0.01,
        beta_end=8.0,
        progress=shown.append,
    )
    assert [r["step"] for r in longer["history"]] == [1, 2, 3, 4, 5]
    assert [r["step"] for r in shown] == [3, 4, 5]  # where it stood, then each new step
    assert all(r["binary"] for r in longer["history"][2:])
    best = max(longer["history"][2:], key=lambda r: r["psnr"])
    shorter = run_design(
        design, tmp_path / "b", steps=2, lr=0.5, binary_steps=1, binary_lr=0.01, beta_end=8.0
    )
    assert len(shorter["history"]) == 5  # nothing more solved
    torch.testing.assert_close(shorter["theta"], longer["theta"])
    assert max(r["psnr"] for r in shorter["history"][2:]) == best["psnr"]
    with pytest.raises(FullwaveError, match="other settings"):
        run_design(design, tmp_path / "b", steps=2, lr=0.5, binary_steps=3, beta_end=8.0)
    torch.testing.assert_close(result["theta"], continued)  # the layer the binary step scored
    moved = (after["theta"] - continued).abs()  # carried moments would not move by 0.01 exactly
    assert float(moved.max()) == pytest.approx(0.01, rel=1e-6)
    assert float(moved.median()) == pytest.approx(0.01, rel=1e-3)
    with pytest.raises(FullwaveError, match="learning rates > 0"):
        run_design(design, tmp_path / "d", steps=2, binary_steps=1, binary_lr=0.0)


def test_a_run_of_binary_steps_only_descends_on_fabricable_layers_from_a_binary_start(
    tmp_path, capsys
):
    """``--steps 0``: every step scores the binary layer that keeps the minimum feature,
    from the first; a state saved before binary layers kept it is not continued."""
    from splitcam.cli import main
    from splitcam.design.fullwave import _save_state
    from splitcam.design.lengthscale import keeps_minimum_feature

    rows, cols = np.indices((16, 16))
    start = ((rows - 7.5) ** 2 + (cols - 4.5) ** 2 < 16) | ((rows - 3) ** 2 + (cols - 12) ** 2 < 9)
    np.savetxt(tmp_path / "start.csv", start.astype(float), delimiter=",", fmt="%g")
    args = ["optics", "rcwa-design", str(tmp_path / "start.csv"), "--steps", "0"]
    args += ["--binary-steps", "2", "--binary-lr", "0.3", "--order", "1", "--samples", "8"]
    args += ["--feature", "0.5", "--wavelengths", "460,620", "--quiet"]  # 4 cells of 0.125 µm
    args += ["--filter", "0.25"]  # narrower than the feature: the start's discs survive it
    assert main([*args, "--out", str(tmp_path / "b")]) == 0
    state = json.loads((tmp_path / "b" / "state.json").read_text())
    assert state["settings"]["filter"] == 0.25
    assert [r["binary"] for r in state["history"]] == [True, True]
    design = np.loadtxt(tmp_path / "b" / "b.csv", delimiter=",")
    assert keeps_minimum_feature(design, 4)
    report = (tmp_path / "b" / "report.md").read_text()
    assert "first step" not in report and "best of 2 binary steps" in report
    found = re.search(r"solid (\d+) cells .* void (\d+) cells", report)
    solid, void = map(int, found.groups())
    assert min(solid, void) >= 4 and keeps_minimum_feature(design, min(solid, void))
    # A run saved before binary layers kept the feature scored other layers: refused.
    old = {k: v for k, v in state["settings"].items() if k != "binary_layer"}
    theta = torch.zeros(16, 16, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.Adam([theta])
    theta.sum().backward()
    opt.step()
    _save_state(tmp_path / "old" / "state", theta, opt, None, old, state["history"][:1])
    capsys.readouterr()
    assert main([*args, "--out", str(tmp_path / "old")]) == 1
    assert "saved before binary layers kept their minimum feature" in capsys.readouterr().err


def test_layers_stacked_are_designed_together_and_their_files_solve_to_the_design(tmp_path, capsys):
    """`optics rcwa-design` of two layers (a noise start each, their own thicknesses, a spacer):
    a design file per layer, both binary and different, the report measures each; the saved
    settings rebuild the design problem, and `optics rcwa` of the two files written, in the
    same stack, solves to the spectra of the pattern the run wrote."""
    import splitcam.design.fullwave as fd
    from splitcam import patterns
    from splitcam.cli import main

    stack = ["--thickness", "0.3", "0.2", "--spacer", "0.1", "--order", "1"]
    args = ["optics", "rcwa-design", "noise:6x6", "noise:6x6", *stack, "--samples", "64"]
    args += ["--steps", "2", "--binary-steps", "1", "--feature", "0.4", "--quiet"]
    args += ["--wavelengths", "460,620", "--out", str(tmp_path / "two")]
    assert main(args) == 0
    out = tmp_path / "two"
    files = {p.name for p in out.iterdir()}
    assert {"two-layer1.csv", "two-layer2.csv", "two-layer1-density.csv", "two.toml"} <= files
    assert "two.csv" not in files
    layers = [np.loadtxt(out / f"two-layer{i}.csv", delimiter=",") for i in (1, 2)]
    assert all(layer.shape == (6, 6) and set(np.unique(layer)) <= {0.0, 1.0} for layer in layers)
    assert not np.array_equal(*layers)  # each layer its own
    report = (out / "report.md").read_text()
    assert "layer `two-layer1.csv`" in report and "layer `two-layer2.csv`" in report
    said = capsys.readouterr().out
    settings = json.loads((out / "state.json").read_text())["settings"]
    assert settings["stack"][1] == [0.3, 0.2] and settings["spacer"] == 0.1
    again = fd.FullwaveDesign.from_settings(np.stack(layers), settings)
    assert again.geometry.thicknesses == (0.3, 0.2) and again.geometry.spacer == 0.1
    with torch.no_grad():
        t = again.transmission(torch.from_numpy(np.stack(layers)))[0].clamp_min(0.0)
    solved_again = float(re.search(r"-> ([0-9.]+) dB \(binary", said)[1])
    assert -10 * math.log10(float(again.image_error(t))) == pytest.approx(solved_again, abs=0.006)
    files = [str(out / f"two-layer{i}.csv") for i in (1, 2)]
    rcwa = ["optics", "rcwa", *files, *stack, "--wavelengths", "460,620", "--quiet"]
    assert main([*rcwa, "--name", "check", "--out", str(tmp_path / "check")]) == 0
    spectra = [
        np.loadtxt(p, delimiter=",", skiprows=1)
        for p in (out / "two-spectra.csv", tmp_path / "check" / "check-spectra.csv")
    ]
    np.testing.assert_allclose(spectra[1], spectra[0], atol=1e-9)
    assert spectra[0][:, 1:5].std() > 0.01  # the layers sort light
    text = (tmp_path / "check" / "check.toml").read_text()
    assert "2 layers of Si3N4 (0.3 / 0.2 µm, 0.1 µm apart)" in text
    assert "2 layers of Si3N4" in patterns.get(str(out / "two.toml")).description


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["noise:6x6", "--feature", "0.1"], "below the grid step"),
        (["noise:6x6", "--feature", "2.4"], "wider than the layer"),
        (["noise:6x6", "--feature", "0.4", "--photons", "0"], "exposure must be > 0"),
        (["noise:1x1"], "at least 2x2"),
        (["nowhere.csv"], "cannot read design"),
        (["noise:6x6", "--feature", "0.4", "--stack", "silicon,glass"], "unknown"),
        (["noise:6x6", "noise:4x4", "--feature", "0.4"], "must have one grid"),
        (["noise:6x6", "noise:6x6", "--thickness", "0.3", "0.2", "0.1"], "3 thicknesses"),
        (["noise:6x6", "noise:6x6", "--feature", "0.4", "--spacer", "-1"], "spacer must be"),
        (["noise:6x6", "--feature", "0.4", "--workers", "0"], "workers must be an integer >= 1"),
    ],
)
def test_bad_design_settings_are_one_line_and_write_nothing(tmp_path, capsys, extra, message):
    from splitcam.cli import main

    out = tmp_path / "o"
    assert main(["optics", "rcwa-design", *extra, "--out", str(out), "--quiet"]) == 1
    assert message in capsys.readouterr().err and not out.exists()


@pytest.mark.slow  # about 15 s: fmmax's solve and its gradient, direction by direction
def test_a_gradient_holds_one_solve_at_a_time_and_equals_the_solves_held_together(monkeypatch):
    """Behind a cone (several directions) the design's gradient is taken solve by solve: the
    forward pass keeps no solve's intermediates (each solve is run again in the backward), and
    the gradient is the one of the same solves held together, built by hand."""
    pytest.importorskip("fmmax")
    from splitcam.physics import fullwave as physics
    from splitcam.physics.fullwave import cone_directions

    rng = np.random.default_rng(7)
    geometry = RouterDesign(rng.random((6, 6)), thickness=0.5, depth=1.0)
    directions = cone_directions(2.0)[:3]
    design = FullwaveDesign(
        geometry, wavelengths=[470.0, 610.0], photons=50.0, samples=8, radius=1.0,
        directions=directions, solver="fmmax-jones", terms=21,
    )  # fmt: skip
    theta = design.start().clone().requires_grad_(True)
    import jax

    calls, vjp = [], jax.vjp
    monkeypatch.setattr(jax, "vjp", lambda *a, **k: (calls.append(1), vjp(*a, **k))[1])
    loss, _ = design.objective(theta, beta=2.0)
    assert calls == []  # nothing kept for the backward
    loss.backward()
    assert len(calls) == 2 * len(directions)  # each solve once more, with its pullback
    # The same loss with every solve's pullback held at once.
    theta_ref = design.start().clone().requires_grad_(True)
    layer = design.densities(theta_ref, 2.0)
    w = torch.tensor([d[2] for d in directions], dtype=torch.float64)
    w = w / w.sum()
    spectra = []
    for lam in design.wavelengths:
        t = sum(
            wk * physics.fmmax_quadrants(geometry, layer, lam, th, ph, 21, 8)[0].mean(0)
            for (th, ph, _), wk in zip(directions, w, strict=True)
        )
        spectra.append(t)
    ref = 10 * torch.log10(design.image_error(torch.stack(spectra, dim=-1)))
    ref.backward()
    assert float(loss.detach()) == pytest.approx(float(ref.detach()), rel=1e-12)
    assert torch.allclose(theta.grad, theta_ref.grad, rtol=1e-9, atol=1e-14)


class _Bowl:
    """A stand-in design for the descent alone: the loss is ``sum((theta - 0.3)^2)`` (its
    gradient known in closed form) and every theta scored is recorded. At a rate of 1 Adam
    overshoots the bowl, so the binary steps fall below their best."""

    def __init__(self):
        self.scored = []

    def start(self):
        return torch.tensor([1.1, -1.1, 0.7], dtype=torch.float64)

    def objective(self, theta, beta, binary=False):
        self.scored.append(theta.detach().clone())
        loss = ((theta - 0.3) ** 2).sum()
        psnr = -10 * math.log10(float(loss.detach()))
        return loss, {"psnr": psnr, "mse": float(loss.detach()), "reflection": 0.0}


def test_backtracking_returns_to_the_best_layer_at_half_the_rate_and_continues_exactly(tmp_path):
    from splitcam.design.fullwave import run_design
    from splitcam.io.tensorfiles import load_pair, save_pair

    kw = {"steps": 0, "binary_steps": 12, "binary_lr": 1.0}
    plain = _Bowl()
    flat = run_design(plain, tmp_path / "plain", **kw)["history"]
    bowl = _Bowl()
    rows = run_design(bowl, tmp_path / "b", backtrack=True, **kw)["history"]
    assert [r["lr"] for r in flat] == [1.0] * 12  # without it: the same rate throughout
    fell = [k for k in range(1, 11) if rows[k]["psnr"] < max(r["psnr"] for r in rows[:k])]
    assert fell, "the bowl at rate 1 must overshoot"
    for k in fell:
        best = max(range(k), key=lambda j: (rows[j]["psnr"], j))
        rate = rows[k]["lr"] / 2
        assert rows[k + 1]["lr"] == rate
        # the step taken from the best layer (to the next layer scored), again at that rate
        step = bowl.scored[best + 1] - bowl.scored[best]
        expected = bowl.scored[best] + step * rate / rows[best]["lr"]
        torch.testing.assert_close(bowl.scored[k + 1], expected)
    assert max(r["psnr"] for r in rows) > max(r["psnr"] for r in flat)
    # Continued after any step, the run is the one that never stopped.
    for stop in (2, fell[0] + 1, fell[0] + 2):
        again = _Bowl()
        run_design(again, tmp_path / f"s{stop}", backtrack=True, **{**kw, "binary_steps": stop})
        rest = run_design(again, tmp_path / f"s{stop}", backtrack=True, **kw)["history"]
        assert [r["psnr"] for r in rest] == [r["psnr"] for r in rows]
        torch.testing.assert_close(torch.stack(again.scored), torch.stack(bowl.scored))
    # The backtracked step's optimiser carries on from the best layer's moments: its count is
    # the best step's plus one (a fresh Adam's would be 1).
    k = fell[0]
    best = max(range(k), key=lambda j: (rows[j]["psnr"], j))
    short = tmp_path / "short"
    run_design(_Bowl(), short, backtrack=True, **{**kw, "binary_steps": k + 2})
    meta = load_pair(short / "state", "splitcam-fullwave-design", 1, "", ValueError)[1]
    assert meta["adam_step"] == best + 2
    # Switched on when a run saved without the step from its best layer (as runs were before
    # backtracking) is continued after a fall: the best layer is scored once more, then the
    # descent goes on at half the rate.
    late = _Bowl()
    first = next(k for k in range(1, 8) if flat[k]["psnr"] < max(r["psnr"] for r in flat[:k]))
    run_design(late, tmp_path / "late", **{**kw, "binary_steps": first + 1})
    state = tmp_path / "late" / "state"
    tensors, meta, _ = load_pair(state, "splitcam-fullwave-design", 1, "", ValueError)
    tensors = {k: v for k, v in tensors.items() if k == "best" or not k.startswith("best")}
    del meta["adam_step"]
    save_pair(state, tensors, "splitcam-fullwave-design", 1, meta)
    on = run_design(late, tmp_path / "late", backtrack=True, **kw)["history"]
    best = max(range(first), key=lambda j: (flat[j]["psnr"], j))
    torch.testing.assert_close(late.scored[first + 1], late.scored[best])
    assert on[first + 1]["psnr"] == flat[best]["psnr"] and on[first + 1]["lr"] == 0.5
    assert on[first + 2]["lr"] == 0.5 and not torch.equal(late.scored[first + 2], late.scored[best])


def test_the_reports_band_table_scores_each_band_and_leaves_one_without_wavelengths_empty():
    """The report's band table: efficiency into a band's own pixels and purity of what they
    receive, computed here by hand; with no design wavelength in the red band, its cells say
    so instead of NaN."""
    from splitcam.cli.rcwa_design import _band_table

    lams = [450.0, 550.0]  # blue and green only
    # Pixels (row-major) at 450 / 550 nm: blue peaks at pixel 0, the longest wavelength at
    # pixel 3 (red), so green is pixels 1 and 2.
    t = np.array([[[0.6, 0.1], [0.1, 0.3]], [[0.1, 0.3], [0.2, 0.5]]])
    table = _band_table(lams, {"a router": t})
    head, row = table[-3], table[-1]
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert head.startswith("| router |")
    assert cells[0] == "a router"
    blue_eff, green_eff = 0.6, 0.3 + 0.3
    blue_pur, green_pur = 0.6 / (0.6 + 0.1), (0.3 + 0.3) / (0.1 + 0.3 + 0.1 + 0.3)
    assert [float(cells[1]), float(cells[2])] == pytest.approx([blue_eff, green_eff], abs=5e-4)
    assert [float(cells[4]), float(cells[5])] == pytest.approx([blue_pur, green_pur], abs=5e-4)
    assert cells[3] == cells[6] == "–"
