"""One optical stack for every pixel (splitcam.physics.stack): the curves, their checks, and
what putting a sensor behind them does, against reductions written out here."""

from __future__ import annotations

import json

import colour
import numpy as np
import pytest

from splitcam import patterns
from splitcam.cli import main
from splitcam.patterns.spectral import scene_basis
from splitcam.physics.radiometry import SiliconQE
from splitcam.physics.stack import (
    IRCut,
    OpticalStack,
    TabulatedCurve,
    d5100_ir_cut,
    stack_of,
)

GRID = np.arange(400.0, 701.0, 10.0)


def test_the_stack_is_the_product_of_its_curves_and_refuses_bad_ones(tmp_path):
    cut, qe = IRCut(640.0, 15.0), SiliconQE(3.0)
    stack = OpticalStack((cut, qe))
    np.testing.assert_allclose(stack(GRID), cut(GRID) * qe(GRID))
    assert OpticalStack(())(GRID).tolist() == [1.0] * len(GRID)
    with pytest.raises(ValueError, match="must lie within \\[0, 1\\]"):
        TabulatedCurve((400.0, 700.0), (0.5, 1.2), "too bright")
    with pytest.raises(ValueError, match="covers 450-700 nm; a stack curve must cover 400-700"):
        TabulatedCurve((450.0, 700.0), (0.5, 0.5), "short")
    with pytest.raises(ValueError, match="unknown stack element 'glass'; known: silicon, ir-cut"):
        stack_of(["glass"])
    csv = tmp_path / "cut.csv"
    csv.write_text("wavelength_nm,transmission\n380,1\n550,0.9\n720,0.1\n")
    curve = stack_of([str(csv)]).elements[0]
    assert curve(550.0) == pytest.approx(0.9) and curve(635.0) == pytest.approx(0.5)


def test_the_d5100_cut_fitted_to_its_red_channel_tracks_it():
    """Above 590 nm a red filter passes nearly all: the cut times silicon's QE follows the
    camera's red curve there (both scaled to 1 at 590 nm)."""
    cut = d5100_ir_cut()
    assert 630 < cut.edge_nm < 660 and cut.width_nm < 30
    red = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    lams = np.arange(590.0, 661.0, 10.0)
    measured = np.interp(lams, red.wavelengths, red.values[:, 0])
    model = cut(lams) * SiliconQE(3.0)(lams)
    np.testing.assert_allclose(model / model[0], measured / measured[0], atol=0.12)


def test_a_spectral_sensor_behind_the_stack_is_its_reduction_of_the_filtered_spectra():
    stack = stack_of(["silicon", "ir-cut"])
    router = patterns.get("router-best-fullwave")
    spectral = router.metadata["spectral"]
    lams, kernels = np.asarray(spectral["wavelengths"]), np.asarray(spectral["kernels"])
    naive = np.einsum("slhw,l,lc->schw", kernels, stack(lams), scene_basis(lams))
    behind = stack.apply(router)
    np.testing.assert_allclose(behind.kernels, naive, rtol=1e-12, atol=1e-15)
    assert behind.name == router.name and "IR cut" in behind.metadata["stack"]
    assert np.all(behind.kernels <= router.kernels + 1e-12)  # a stack only takes light


def test_an_rgb_sensor_is_scaled_by_the_stacks_mean_over_each_colour():
    stack = stack_of(["silicon", "ir-cut"])
    factors = [float(np.sum(stack(GRID) * scene_basis(GRID)[:, c])) for c in range(3)]
    assert factors[0] < factors[1] < factors[2] <= 1  # deep red is what silicon and cuts lose
    for name in ("bayer", "rgbw", "A"):
        pattern = patterns.get(name)
        behind = stack.apply(pattern)
        for c in range(3):
            np.testing.assert_allclose(behind.kernels[:, c], pattern.kernels[:, c] * factors[c])


def test_measured_filters_keep_their_shape_and_a_flat_stack_scales_them_like_any_pixel():
    """A measured curve holds its camera's stack: under a flat stack (a constant c) the array
    is c times itself, as every other sensor is; under any stack no estimated filter passes
    more than all of the light."""
    half = OpticalStack((TabulatedCurve((400.0, 700.0), (0.5, 0.5), "grey glass"),))
    for name in ("rgbw-d5100", "bayer-d5100"):
        array = patterns.get(name)
        np.testing.assert_allclose(half.apply(array).kernels, 0.5 * array.kernels, atol=1e-12)
    stack = stack_of(["silicon", "ir-cut"])
    rgbw = stack.apply(patterns.get("rgbw-d5100"))
    spectral = np.asarray(rgbw.metadata["spectral"]["kernels"])
    lams = np.asarray(rgbw.metadata["spectral"]["wavelengths"])
    assert np.all(spectral.sum((2, 3)) <= stack(lams)[None] + 1e-12)
    # the W pixel (splitter 0) is the bare pixel behind the stack
    np.testing.assert_allclose(spectral[0, :, 0, 0], stack(lams))


def test_study_exposure_puts_every_sensor_behind_the_stack(tmp_path, capsys):
    args = ["study", "exposure", "--max-images", "1", "--crop", "48", "--photons", "30", "3000"]
    args += ["--patterns", "bayer,router-best-fullwave", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "bare")]) == 0
    assert main([*args, "--stack", "silicon,ir-cut", "--out", str(tmp_path / "cut")]) == 0
    bare = json.loads((tmp_path / "bare" / "exposure.json").read_text())["results"]
    cut = json.loads((tmp_path / "cut" / "exposure.json").read_text())["results"]
    for name in ("lmmse-bayer", "lmmse-router-best-fullwave"):
        key = next(k for k in bare if k.endswith(name.split("-", 1)[1]))
        assert cut[key]["30"]["psnr"] < bare[key]["30"]["psnr"]  # less light, more noise
    assert (
        "Every pixel behind: silicon 3 µm deep × IR cut"
        in (tmp_path / "cut" / "exposure.md").read_text()
    )
    capsys.readouterr()
    for extra, message in [
        (["--stack", "glass"], "unknown stack element 'glass'"),
        (["--stack", "silicon", "--silicon-depth", "3"], "leave --silicon-depth out"),
        (["--stack", "silicon", "--model", "A-photon"], "knows its sensor without the stack"),
    ]:
        out = tmp_path / "refused"
        assert main([*args, *extra, "--out", str(out)]) == 1
        assert message in capsys.readouterr().err and not out.exists()
