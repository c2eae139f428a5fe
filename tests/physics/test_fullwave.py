"""The full-wave solver of metasurface routers (splitcam.physics.fullwave): material fits, a
flat interface and a thin film against Fresnel and Airy, energy conservation, the lens-cone
quadrature, the published Zou router, and refusals."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from splitcam.physics.fullwave import (
    MATERIALS,
    SOLVERS,
    FullwaveError,
    RouterDesign,
    band_efficiencies,
    band_purities,
    cone_directions,
    quadrant_spectra,
    read_design,
)

pytest.importorskip("torcwa")

DESIGNS = Path(__file__).resolve().parents[2] / "experiments" / "fullwave" / "designs"


def test_silica_matches_its_published_d_line_index():
    # Fused silica at the helium d line, 587.56 nm: n_d = 1.4585 (Malitson 1965).
    assert float(MATERIALS["SiO2"](0.58756)) == pytest.approx(1.4585, abs=2e-4)
    # Silicon nitride (Luke et al. 2015) lies near 2.0 across the visible, higher in the blue.
    n = MATERIALS["Si3N4"](np.array([0.45, 0.55, 0.65]))
    assert np.all((n > 1.98) & (n < 2.1)) and n[0] > n[1] > n[2]


def _airy(n_film: float, thickness: float, n_sub: float, lam: float) -> float:
    """Transmittance of a film on a substrate at normal incidence from vacuum (characteristic
    matrix of the film)."""
    delta = 2 * math.pi * n_film * thickness / lam
    m = np.array(
        [
            [math.cos(delta), 1j * math.sin(delta) / n_film],
            [1j * n_film * math.sin(delta), math.cos(delta)],
        ]
    )
    b, c = m @ np.array([1.0, n_sub])
    return float(4 * n_sub / abs(b + c) ** 2)


@pytest.mark.parametrize("density", [0.0, 1.0, 0.5])
def test_a_uniform_layer_transmits_what_a_thin_film_does(density):
    lam = 530.0
    design = RouterDesign(np.full((4, 4), density), thickness=0.31, depth=0.7)
    out = quadrant_spectra(design, [lam], order=1, samples=8)
    eps_p = MATERIALS["Si3N4"](lam / 1000) ** 2
    n_film = math.sqrt(1 + density * (eps_p - 1))
    expect = _airy(n_film, 0.31, float(MATERIALS["SiO2"](lam / 1000)), lam / 1000)
    np.testing.assert_allclose(out["transmission"][:, :, 0], expect / 4, rtol=1e-6)
    assert out["reflection"][0] == pytest.approx(1 - expect, abs=1e-6)


def test_light_is_conserved_and_the_quadrants_split_it():
    rng = np.random.default_rng(0)
    design = RouterDesign(rng.random((8, 8)) > 0.5, thickness=0.5, depth=1.0)
    out = quadrant_spectra(design, [470.0, 610.0], order=3, samples=16)
    total = out["transmission"].sum(axis=(0, 1)) + out["reflection"]
    np.testing.assert_allclose(total, 1.0, atol=1e-6)
    assert out["transmission"].std(axis=(0, 1)).min() > 1e-3  # a patterned layer sorts light
    # The two polarisations differ for a pattern without symmetry; their mean is reported.
    np.testing.assert_allclose(out["by_polarisation"].mean(axis=0), out["transmission"])


def test_the_cone_quadrature_integrates_low_polynomials_over_the_pupil():
    points = cone_directions(2.0)
    radius = 1 / 4
    w = np.array([p[2] for p in points])
    assert w.sum() == pytest.approx(1.0)
    u = np.array([math.sin(t) * math.cos(f) for t, f, _ in points]) / radius
    v = np.array([math.sin(t) * math.sin(f) for t, f, _ in points]) / radius
    # Means over the unit disk: x^2 and y^2 1/4, odd and mixed terms 0.
    for values, mean in [(u**2, 0.25), (v**2, 0.25), (u, 0), (u * v, 0), (u**3, 0), (u * v**2, 0)]:
        assert float(w @ values) == pytest.approx(mean, abs=1e-12)
    assert max(t for t, _, _ in points) < math.asin(radius)


def test_oblique_light_is_conserved():
    design = RouterDesign(np.eye(6), thickness=0.4, depth=0.5)
    out = quadrant_spectra(design, [520.0], order=2, samples=16, directions=cone_directions(2.0))
    assert out["transmission"].sum() + out["reflection"][0] == pytest.approx(1.0, abs=1e-6)


def test_a_tilted_cone_is_the_pupil_disk_moved_to_the_chief_ray():
    """Off the centre of the field the cone's direction sines fill the same disk, centred on
    the chief ray's sines: the weighted mean is the chief ray, the spread about it the pupil's
    (1/4 of the radius squared per axis, as in the centre)."""
    radius = 1 / (2 * 1.4)
    chief, azimuth = math.radians(25), math.radians(45)
    points = cone_directions(1.4, chief, azimuth)
    w = np.array([p[2] for p in points])
    u = np.array([math.sin(t) * math.cos(f) for t, f, _ in points])
    v = np.array([math.sin(t) * math.sin(f) for t, f, _ in points])
    cu, cv = math.sin(chief) * math.cos(azimuth), math.sin(chief) * math.sin(azimuth)
    assert float(w @ u) == pytest.approx(cu, abs=1e-12)
    assert float(w @ v) == pytest.approx(cv, abs=1e-12)
    assert float(w @ (u - cu) ** 2) == pytest.approx(radius**2 / 4, abs=1e-12)
    assert float(w @ ((u - cu) * (v - cv))) == pytest.approx(0.0, abs=1e-12)
    # Without a lens: the chief ray alone.
    assert cone_directions(None, chief, azimuth) == [(pytest.approx(chief), azimuth, 1.0)]
    assert cone_directions(None) == [(0.0, 0.0, 1.0)]
    for bad, message in [
        ((1.4, math.radians(50)), "reaches grazing incidence"),
        ((None, math.radians(90)), r"in \[0, 90\) degrees"),
        ((2.0, -0.1), r"in \[0, 90\) degrees"),
    ]:
        with pytest.raises(FullwaveError, match=message):
            cone_directions(*bad)


def test_a_chief_ray_along_y_sees_the_transposed_design_as_one_along_x_sees_the_design():
    """Mirror symmetry across the diagonal: the design transposed (x and y swapped) lit from
    azimuth 90 degrees sends into each quadrant what the design lit from azimuth 0 sends into
    the transposed quadrant. A check of the azimuth's convention, and light is conserved."""
    rng = np.random.default_rng(3)
    grid = (rng.random((6, 6)) > 0.5).astype(float)
    # Collimated: the 7-point cone is not symmetric under the swap (its points sit at
    # multiples of 60 degrees about the chief ray).
    along_x = cone_directions(None, math.radians(20), 0.0)
    along_y = cone_directions(None, math.radians(20), math.pi / 2)
    a = quadrant_spectra(
        RouterDesign(grid, thickness=0.4, depth=0.5),
        [560.0],
        order=2,
        samples=16,
        directions=along_x,
    )
    b = quadrant_spectra(
        RouterDesign(grid.T, thickness=0.4, depth=0.5),
        [560.0],
        order=2,
        samples=16,
        directions=along_y,
    )
    np.testing.assert_allclose(b["transmission"][..., 0], a["transmission"][..., 0].T, atol=1e-9)
    assert a["transmission"].sum() + a["reflection"][0] == pytest.approx(1.0, abs=1e-6)
    # and the tilt matters: normal incidence sends the light elsewhere
    c = quadrant_spectra(RouterDesign(grid, thickness=0.4, depth=0.5), [560.0], order=2, samples=16)
    assert np.abs(c["transmission"] - a["transmission"]).max() > 1e-3


def test_an_interrupted_solve_continues_from_its_log(tmp_path, monkeypatch):
    """Every solve is appended to the log as it finishes: a run stopped part-way is continued
    by the next with the same log, which solves only what is missing and returns what an
    unlogged run returns; a line cut short by the interruption is skipped; another setting
    (here the order) solves afresh."""
    import splitcam.physics.fullwave as fw

    design = RouterDesign(np.eye(6), thickness=0.4, depth=0.5)
    lams = [470.0, 560.0, 650.0]
    directions = cone_directions(3.0)[:2]
    plain = quadrant_spectra(design, lams, order=2, samples=16, directions=directions)
    log = tmp_path / "solves.jsonl"
    real = fw._spectra_solver
    calls = []

    def stopping(*a, **k):
        solve, count = real(*a, **k)

        def once(*args):
            calls.append(args)
            if len(calls) == 4:
                raise KeyboardInterrupt
            return solve(*args)

        return once, count

    monkeypatch.setattr(fw, "_spectra_solver", stopping)
    with pytest.raises(KeyboardInterrupt):
        quadrant_spectra(design, lams, order=2, samples=16, directions=directions, cache=log)
    assert len(log.read_text().splitlines()) == 3
    with log.open("a") as f:
        f.write('{"setting": "cut sh')  # killed mid-line
    calls.clear()
    again = quadrant_spectra(design, lams, order=2, samples=16, directions=directions, cache=log)
    assert len(calls) == 3 and again["cost"] == {**again["cost"], "solves": 6, "reused": 3}
    # the cut line was closed, not extended: every solve of the second run is in the log
    calls.clear()
    quadrant_spectra(design, lams, order=2, samples=16, directions=directions, cache=log)
    assert calls == []
    for key in ("transmission", "by_polarisation", "reflection"):
        np.testing.assert_array_equal(again[key], plain[key])
    calls.clear()
    quadrant_spectra(design, lams[:1], order=1, samples=16, directions=directions, cache=log)
    assert len(calls) == 2


def test_worker_processes_share_the_solves_a_log_lacks(tmp_path, monkeypatch):
    """With workers, the solves the log lacks are shared by processes (none is solved in this
    one) and logged; the log's own are taken from it: the spectra are one process's (to
    rounding: the workers run one thread), and a later run finds every solve in the log."""
    import splitcam.physics.fullwave as fw

    design = RouterDesign(np.eye(6), thickness=0.4, depth=0.5)
    lams = [470.0, 560.0, 650.0]
    kw = dict(order=2, samples=16, directions=cone_directions(3.0)[:2])
    plain = quadrant_spectra(design, lams, **kw)
    log = tmp_path / "solves.jsonl"
    quadrant_spectra(design, lams[1:2], **kw, cache=log)  # two of the six solves logged
    real = fw._spectra_solver

    def here(*a, **k):  # a solve in this process fails; the spawned workers solve for real
        def refused(*args):
            raise AssertionError("solved in the parent process")

        return refused, real(*a, **k)[1]

    monkeypatch.setattr(fw, "_spectra_solver", here)
    shared = quadrant_spectra(design, lams, **kw, cache=log, workers=2)
    assert shared["cost"] == {**shared["cost"], "solves": 6, "reused": 2}
    assert shared["cost"]["seconds"] > 0
    for key in ("transmission", "by_polarisation", "reflection"):
        np.testing.assert_allclose(shared[key], plain[key], rtol=1e-12, atol=1e-15)
    assert len(log.read_text().splitlines()) == 6
    again = quadrant_spectra(design, lams, **kw, cache=log, workers=2)
    assert again["cost"]["reused"] == 6
    np.testing.assert_array_equal(again["transmission"], shared["transmission"])
    with pytest.raises(FullwaveError, match="workers must be an integer >= 1"):
        quadrant_spectra(design, lams, **kw, workers=0)


def test_the_command_at_a_chief_ray_continues_an_interrupted_run(tmp_path, capsys):
    """--chief-ray tilts the cone; a second run of the same command takes every solve from
    the first's log and writes the same spectra; a cone that reaches grazing is refused in
    one line and writes nothing."""
    from splitcam.cli import main

    out = tmp_path / "o"
    args = [
        "optics",
        "rcwa",
        str(DESIGNS / "zou2022-16x16.csv"),
        "--order",
        "1",
        "--quiet",
        "--wavelengths",
        "450,650",
        "--f-number",
        "2.8",
        "--chief-ray",
        "25",
        "--chief-ray-azimuth",
        "45",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    first = (out / "zou2022-16x16-spectra.csv").read_text()
    assert "chief ray 25 degrees" in (out / "zou2022-16x16.toml").read_text()
    capsys.readouterr()
    assert main(args) == 0
    assert "14 of 14 solves taken from" in capsys.readouterr().out
    assert (out / "zou2022-16x16-spectra.csv").read_text() == first
    bad = tmp_path / "bad"
    assert main([*args[:-1], str(bad), "--chief-ray", "70"]) == 1
    assert "reaches grazing incidence" in capsys.readouterr().err and not bad.exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("0,1\n1\n", "row 2: 1 cells"),
        ("0,a\n", "not a list of numbers"),
        ("0,1.5\n", "densities in \\[0, 1\\]"),
        ("", "empty"),
    ],
)
def test_bad_designs_are_refused_in_one_line(tmp_path, text, message):
    path = tmp_path / "d.csv"
    path.write_text(text)
    with pytest.raises(FullwaveError, match=message):
        read_design(path)


def test_a_missing_solver_names_its_install_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "torcwa", None)
    with pytest.raises(FullwaveError, match=r"pip install 'splitcam\[fullwave\]'"):
        quadrant_spectra(RouterDesign(np.ones((2, 2))), [500.0], order=0)


def test_the_zou_router_sends_blue_and_red_to_opposite_pixels():
    """At a coarse order the published design already sorts: blue peaks in row 0, column 1 and
    red in row 1, column 0 of the file's grid (the public simulation flips the rows)."""
    design = RouterDesign(read_design(DESIGNS / "zou2022-16x16.csv"))
    t = quadrant_spectra(design, [450.0, 650.0], order=5, samples=16)["transmission"]
    assert np.unravel_index(t[:, :, 0].argmax(), (2, 2)) == (0, 1)
    assert np.unravel_index(t[:, :, 1].argmax(), (2, 2)) == (1, 0)


@pytest.mark.slow
def test_the_zou_router_lands_within_the_published_tolerances():
    """Order 12 (625 Fourier terms), about 90 s per wavelength on one core."""
    design = RouterDesign(read_design(DESIGNS / "zou2022-16x16.csv"))
    t = quadrant_spectra(design, [450.0, 540.0, 650.0], order=12)["transmission"]
    published = {0: (0.436, 0.394, 0.133), 1: (0.160, 0.575, 0.237), 2: (0.117, 0.270, 0.589)}
    tolerance = {0: (0.27, 0.26, 0.27), 1: (0.25, 0.26, 0.44), 2: (0.11, 0.19, 0.19)}
    for i in range(3):
        got = (t[0, 1, i], t[0, 0, i] + t[1, 1, i], t[1, 0, i])
        for value, ref, tol in zip(got, published[i], tolerance[i], strict=True):
            assert abs(value - ref) <= tol * ref, (i, got)


def test_the_command_writes_spectra_a_chart_and_a_pattern_file(tmp_path, capsys):
    from splitcam import patterns
    from splitcam.cli import main

    out = tmp_path / "zou"
    args = ["optics", "rcwa", str(DESIGNS / "zou2022-16x16.csv"), "--out", str(out)]
    # Order 5: at order 2 blue and red peak in one pixel (an unconverged solve), which is said.
    assert main([*args, "--order", "5", "--wavelengths", "450,550,650", "--quiet"]) == 0
    # Named after the design (the file's stem here).
    written = {"zou2022-16x16-spectra.csv", "zou2022-16x16-spectra.png", "zou2022-16x16.toml"}
    written.add("zou2022-16x16-solves.jsonl")  # every solve, kept as it finishes
    assert {p.name for p in out.iterdir()} == written
    rows = (out / "zou2022-16x16-spectra.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[0].startswith("wavelength_nm,T_row0_col0")
    pattern = patterns.get(str(out / "zou2022-16x16.toml"))
    assert pattern.period == (2, 2) and "full-wave" in pattern.provenance
    assert "band efficiency" in capsys.readouterr().out
    # Bad input: one line, nothing written.
    bad = tmp_path / "bad.csv"
    bad.write_text("0,1\n2,0\n")
    assert main(["optics", "rcwa", str(bad), "--out", str(tmp_path / "x")]) == 1
    assert "densities in [0, 1]" in capsys.readouterr().err and not (tmp_path / "x").exists()
    assert main([*args[:3], "--out", str(tmp_path / "y"), "--wavelengths", "350,450"]) == 1
    assert "outside 380-780" in capsys.readouterr().err and not (tmp_path / "y").exists()


def test_the_command_names_files_after_the_design_and_refuses_f_number_0(tmp_path, capsys):
    """--name names the pattern and its files, so two designs in one folder and one
    evaluation keep apart (every result was once pattern.toml, and evaluate refused two as
    duplicates); --f-number 0 is refused like the other impossible f-numbers (it once meant
    normal incidence)."""
    from splitcam import patterns
    from splitcam.cli import main

    args = ["optics", "rcwa", str(DESIGNS / "zou2022-16x16.csv"), "--order", "1", "--quiet"]
    args += ["--wavelengths", "450,650", "--out", str(tmp_path / "o")]
    assert main([*args, "--name", "zou one"]) == 0
    assert main([*args, "--name", "zou-two"]) == 0
    files = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert "zou_one.toml" in files and "zou-two.toml" in files and "zou-two-spectra.csv" in files
    assert patterns.get(str(tmp_path / "o" / "zou_one.toml")).name == "zou one"
    from splitcam.recon.registry import build_methods

    labels = [
        m.name
        for m in build_methods(
            ["lmmse"],
            patterns_for_lmmse=[
                str(tmp_path / "o" / f) for f in files if "." in f and f.endswith(".toml")
            ],
        )
    ]
    assert sorted(labels) == ["lmmse-zou one", "lmmse-zou-two"]
    for bad in ("0", "0.4", "-2"):
        out = tmp_path / f"f{bad}"
        assert main([*args[:-1], str(out), "--f-number", bad]) == 1
        assert "f-number must be > 0.5" in capsys.readouterr().err and not out.exists()


def test_layers_of_different_grids_or_thicknesses_are_refused_before_any_solve(tmp_path, capsys):
    """`optics rcwa` of two design files: one line naming both where their grids differ, or
    where the thicknesses given are neither one nor one per layer; nothing written."""
    from splitcam.cli import main

    (tmp_path / "a.csv").write_text("0,1\n1,0\n")
    (tmp_path / "b.csv").write_text("0,1,1\n1,0,0\n1,1,0\n")
    out = tmp_path / "o"
    settings = ["--order", "1", "--quiet", "--out", str(out)]
    files = [str(tmp_path / "a.csv"), str(tmp_path / "b.csv")]
    assert main(["optics", "rcwa", *files, *settings]) == 1
    err = capsys.readouterr().err
    assert "must have one grid" in err and "2x2 cells" in err and "b.csv 3x3" in err
    files = [str(tmp_path / "a.csv")] * 2
    assert main(["optics", "rcwa", *files, "--thickness", "0.2", "0.3", "0.4", *settings]) == 1
    assert "3 thicknesses for a design of 2 layer(s)" in capsys.readouterr().err
    assert not out.exists()


def test_colliding_roles_are_said_with_the_numbers(tmp_path, capsys):
    """A design that sends blue and red into the same pixel (a blank layer sends every colour
    everywhere alike) has no band efficiencies: the command writes its spectra and pattern and
    says so, instead of calling three pixels green."""
    from splitcam.cli import main

    blank = tmp_path / "blank.csv"
    blank.write_text("\n".join(",".join(["0"] * 4) for _ in range(4)) + "\n")
    args = ["optics", "rcwa", str(blank), "--order", "1", "--wavelengths", "450,650", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "o")]) == 0
    captured = capsys.readouterr()
    assert "both peak in quadrant" in captured.err and "450 nm" in captured.err
    assert "band efficiency" not in captured.out
    assert (tmp_path / "o" / "blank.toml").exists()
    with pytest.raises(ValueError, match="both peak"):
        band_efficiencies(np.full((2, 2, 3), 0.25), [450.0, 550.0, 650.0])


def test_band_efficiencies_into_given_pixels_where_oblique_light_sorts_badly():
    """Oblique light can send blue and red to one pixel (the Zou router at a 25-degree chief
    ray): with the pixels the design sorts to at normal incidence given, its efficiencies are
    the shares that still reach them, computed here by hand."""
    lams = [450.0, 550.0, 650.0]
    t = np.zeros((2, 2, 3))
    t[0, 1] = [0.5, 0.1, 0.6]  # blue and red both land mostly in pixel 1
    t[0, 0] = [0.1, 0.2, 0.1]  # the red pixel at normal incidence
    t[1, 0] = [0.1, 0.3, 0.1]
    t[1, 1] = [0.2, 0.3, 0.1]  # the blue pixel at normal incidence
    with pytest.raises(ValueError, match="both peak"):
        band_efficiencies(t, lams)
    eff = band_efficiencies(t, lams, {"blue": 3, "red": 0})
    assert eff["blue"] == pytest.approx(0.2) and eff["red"] == pytest.approx(0.1)
    assert eff["green"] == pytest.approx(0.1 + 0.3)  # pixels 1 and 2 at 550 nm
    assert eff["quadrants"] == {"blue": 3, "red": 0}
    with pytest.raises(ValueError, match="two different pixels"):
        band_efficiencies(t, lams, {"blue": 2, "red": 2})


def test_band_purities_are_the_band_shares_of_what_each_pixel_receives():
    """Purity by hand on the same layout: a perfect sorter is 1 in every band, a layer that
    sends every wavelength alike is each band's share of the wavelengths, and a mixed layer's
    numbers are written out here."""
    lams = [430.0, 470.0, 530.0, 570.0, 630.0, 670.0]
    q = {"blue": 3, "red": 0}
    perfect = np.zeros((2, 2, 6))
    perfect[1, 1, :2] = 1.0
    perfect[0, 0, 4:] = 1.0
    perfect[0, 1, 2:4] = perfect[1, 0, 2:4] = 0.5
    assert band_purities(perfect, lams, q) == pytest.approx({"blue": 1, "green": 1, "red": 1})
    assert band_purities(np.full((2, 2, 6), 0.25), lams, q) == pytest.approx(
        {"blue": 1 / 3, "green": 1 / 3, "red": 1 / 3}
    )
    t = np.zeros((2, 2, 6))
    t[1, 1] = [0.6, 0.5, 0.1, 0.1, 0.05, 0.05]  # blue pixel: 1.1 of 1.4 is blue
    t[0, 0] = [0.1, 0.1, 0.1, 0.1, 0.5, 0.6]  # red pixel: 1.1 of 1.5
    t[0, 1] = [0.1, 0.1, 0.3, 0.3, 0.1, 0.1]  # green pixels: (0.6 + 0.5) of (1.0 + 0.9)
    t[1, 0] = [0.1, 0.1, 0.3, 0.2, 0.1, 0.1]
    assert band_purities(t, lams, q) == pytest.approx(
        {"blue": 1.1 / 1.4, "red": 1.1 / 1.5, "green": 1.1 / 1.9}
    )
    # No wavelength in the red band: no purity there (NaN, as its efficiency), not 0.
    short = band_purities(t[..., :4], lams[:4], q)
    assert np.isnan(short["red"]) and short["blue"] == pytest.approx(1.1 / 1.3)


def test_a_wavelength_where_an_order_grazes_is_solved():
    """At 400 and 500 nm a 2 µm period in vacuum has a diffraction order exactly at grazing (a
    Rayleigh anomaly); the solve divided by its zero normal wavevector and returned NaN."""
    design = RouterDesign(np.eye(4), thickness=0.3, depth=0.5)
    out = quadrant_spectra(design, [400.0, 500.0], order=3, samples=8)
    assert np.all(np.isfinite(out["transmission"]))
    np.testing.assert_allclose(
        out["transmission"].sum(axis=(0, 1)) + out["reflection"], 1.0, atol=1e-6
    )


# --- layers stacked --------------------------------------------------------------------------


def _films(indices, thicknesses, n_sub: float, lam: float) -> float:
    """Transmittance of films stacked on a substrate at normal incidence from vacuum, the first
    film on top: the product of their characteristic matrices."""
    m = np.eye(2, dtype=complex)
    for n_film, thickness in zip(indices, thicknesses, strict=True):
        delta = 2 * math.pi * n_film * thickness / lam
        m = m @ np.array(
            [
                [math.cos(delta), 1j * math.sin(delta) / n_film],
                [1j * n_film * math.sin(delta), math.cos(delta)],
            ]
        )
    b, c = m @ np.array([1.0, n_sub])
    return float(4 * n_sub / abs(b + c) ** 2)


@pytest.mark.parametrize(
    "solver",
    ["torcwa", pytest.param("fmmax-fft", marks=pytest.mark.slow)],  # fmmax: 4 s compiling
)
def test_uniform_layers_stacked_transmit_what_films_stacked_do(solver):
    """Two uniform layers of different densities and thicknesses, a spacer of the background
    between them: the transmittance of the three films (layer, vacuum, layer) on silica."""
    if solver != "torcwa":
        _fmmax()
    lam = 530.0
    grid = np.stack([np.full((4, 4), 1.0), np.full((4, 4), 0.4)])
    design = RouterDesign(grid, thickness=(0.31, 0.22), depth=0.7, spacer=0.15)
    out = quadrant_spectra(design, [lam], order=1, samples=8, solver=solver)
    eps_p = float(MATERIALS["Si3N4"](lam / 1000)) ** 2
    n1, n2 = math.sqrt(eps_p), math.sqrt(1 + 0.4 * (eps_p - 1))
    um = lam / 1000
    expect = _films([n1, 1.0, n2], [0.31, 0.15, 0.22], float(MATERIALS["SiO2"](um)), um)
    assert expect != pytest.approx(_films([n1, n2], [0.31, 0.22], 1.46, um), abs=1e-3)
    np.testing.assert_allclose(out["transmission"][:, :, 0], expect / 4, rtol=1e-6)
    assert out["reflection"][0] == pytest.approx(1 - expect, abs=1e-6)


@pytest.mark.parametrize(
    "solver",
    ["torcwa", pytest.param("fmmax-fft", marks=pytest.mark.slow)],  # fmmax: 20 s
)
def test_a_layer_cut_in_two_touching_halves_is_the_layer(solver):
    """A patterned layer is the same two halves stacked with no spacer: every quadrant and the
    reflection at an angle, to the solver's precision; a spacer between them changes both."""
    if solver != "torcwa":
        _fmmax()
    rng = np.random.default_rng(3)
    grid = (rng.random((6, 6)) > 0.5).astype(float)
    direction = [cone_directions(2.0)[2]]
    settings = {"order": 2, "samples": 8, "directions": direction, "solver": solver}
    whole = quadrant_spectra(RouterDesign(grid, thickness=0.5, depth=1.0), [560.0], **settings)
    halves = RouterDesign(np.stack([grid, grid]), thickness=0.25, depth=1.0)
    cut = quadrant_spectra(halves, [560.0], **settings)
    np.testing.assert_allclose(cut["by_polarisation"], whole["by_polarisation"], atol=1e-9)
    np.testing.assert_allclose(cut["reflection"], whole["reflection"], atol=1e-9)
    apart = RouterDesign(np.stack([grid, grid]), thickness=0.25, depth=1.0, spacer=0.2)
    moved = quadrant_spectra(apart, [560.0], **settings)
    assert np.abs(moved["transmission"] - whole["transmission"]).max() > 1e-3
    total = moved["transmission"].sum() + moved["reflection"][0]
    assert total == pytest.approx(1.0, abs=1e-6)  # light is conserved through both layers


def test_the_gradient_in_either_of_two_layers_is_the_central_difference():
    """Two different patterned layers apart: torcwa's gradient with respect to cells of either
    layer is the central difference."""
    import torch

    from splitcam.physics.fullwave import torcwa_quadrants

    rng = np.random.default_rng(5)
    grid = rng.uniform(0.2, 0.8, (2, 4, 4))
    design = RouterDesign(grid, thickness=(0.3, 0.2), depth=0.8, spacer=0.1)
    x = torch.tensor(grid, requires_grad=True)
    quads, reflected = torcwa_quadrants(design, x, 550.0, 0.1, 0.3, order=2, samples=8)
    (quads[0, 0, 1] - 0.5 * quads[1, 1, 0] + 0.3 * reflected).backward()

    def scalar(v):
        with torch.no_grad():
            q, r = torcwa_quadrants(design, torch.tensor(v), 550.0, 0.1, 0.3, order=2, samples=8)
        return float(q[0, 0, 1] - 0.5 * q[1, 1, 0] + 0.3 * r)

    h = 1e-6
    for cell in [(0, 0, 0), (0, 2, 3), (1, 1, 2), (1, 3, 0)]:
        step = np.zeros_like(grid)
        step[cell] = h
        fd = (scalar(grid + step) - scalar(grid - step)) / (2 * h)
        assert float(x.grad[cell]) == pytest.approx(fd, rel=1e-5, abs=1e-9)
    assert float(x.grad[1].abs().max()) > 1e-4  # the second layer moves the light too


@pytest.mark.slow  # about 4 s: fmmax's solve compiled
def test_two_different_layers_apart_solve_alike_in_both_solvers():
    """fmmax lands near torcwa at the same order for two different patterned layers apart."""
    _fmmax()
    grid = np.random.default_rng(5).uniform(0.2, 0.8, (2, 4, 4))
    design = RouterDesign(grid, thickness=(0.3, 0.2), depth=0.8, spacer=0.1)
    ours = quadrant_spectra(design, [550.0], order=3, samples=8)
    fm = quadrant_spectra(design, [550.0], order=3, samples=8, solver="fmmax-fft")
    np.testing.assert_allclose(fm["transmission"], ours["transmission"], atol=0.03)


@pytest.mark.parametrize(
    ("grid", "settings", "message"),
    [
        (np.ones((2, 4, 4)), {"thickness": (0.3, 0.2, 0.1)}, "3 thicknesses for a design of 2"),
        (np.ones((2, 4, 4)), {"spacer": -0.1}, "spacer must be >= 0"),
        (np.ones((2, 4, 4)), {"thickness": (0.3, 0.0)}, "thickness must be > 0"),
        (np.ones((1, 2, 2, 2)), {}, "3-D stack of layers"),
    ],
)
def test_bad_stacks_are_refused_in_one_line(grid, settings, message):
    with pytest.raises(FullwaveError, match=message):
        RouterDesign(grid, **settings)


def test_a_stack_is_kept_whole_by_its_key():
    """RouterDesign.stack (what compiled solves are kept under) makes the same design again,
    every cell 0; one layer keeps its thickness a number."""
    design = RouterDesign(np.ones((2, 3, 3)), 0.8, (0.3, 0.2), 1.5, 2.4, "vacuum", 1.45, 0.1)
    blank = RouterDesign.blank(design.stack())
    assert blank.stack() == design.stack() and not blank.grid.any()
    assert blank.thicknesses == (0.3, 0.2) and blank.cells == (3, 3) and blank.spacer == 0.1
    one = RouterDesign.blank(RouterDesign(np.ones((3, 3)), thickness=0.6).stack())
    assert one.thickness == 0.6 and one.layers.shape == (1, 3, 3)
    # A sequence of one thickness (the CLI's --thickness) is that number, for any layer count.
    assert RouterDesign(np.ones((3, 3)), thickness=[0.6]).thickness == 0.6
    assert RouterDesign(np.ones((2, 3, 3)), thickness=[0.3]).thicknesses == (0.3, 0.3)


# --- the second solver: fmmax (splitcam[fmmax]) ---------------------------------------------


def _fmmax():
    pytest.importorskip("fmmax")


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["fmmax-fft", "fmmax-jones"])
def test_fmmax_transmits_what_a_thin_film_does(solver):
    _fmmax()
    lam = 530.0
    design = RouterDesign(np.full((4, 4), 1.0), thickness=0.31, depth=0.7)
    out = quadrant_spectra(design, [lam], order=1, samples=8, solver=solver)
    n_film = float(MATERIALS["Si3N4"](lam / 1000))
    expect = _airy(n_film, 0.31, float(MATERIALS["SiO2"](lam / 1000)), lam / 1000)
    np.testing.assert_allclose(out["transmission"][:, :, 0], expect / 4, rtol=1e-6)
    assert out["reflection"][0] == pytest.approx(1 - expect, abs=1e-6)


@pytest.mark.slow  # about 5 s; the fast suite solves with fmmax through the command
def test_fmmax_conserves_light_at_an_angle_and_agrees_with_torcwa():
    """fmmax's FFT formulation conserves light through a patterned layer at oblique incidence,
    and lands near torcwa at the same order (the truncations differ: a circle of about
    ``(2 order + 1)^2`` terms against the square)."""
    _fmmax()
    rng = np.random.default_rng(0)
    design = RouterDesign(rng.random((8, 8)) > 0.5, thickness=0.5, depth=1.0)
    direction = [cone_directions(2.0)[3]]
    ours = quadrant_spectra(design, [610.0], order=4, samples=16, directions=direction)
    out = quadrant_spectra(
        design, [610.0], order=4, samples=16, directions=direction, solver="fmmax-fft"
    )
    assert out["terms"] == pytest.approx(81, abs=4) and ours["terms"] == 81
    assert out["transmission"].sum() + out["reflection"][0] == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(out["transmission"], ours["transmission"], atol=0.03)
    assert out["transmission"].std() > 0.01  # the layer sorts light


@pytest.mark.slow  # about 20 s: fmmax's interior solution compiled layer by layer
def test_fmmax_outer_amplitudes_are_those_of_the_interior_solution():
    """The periodic solve takes the reflected and the arriving amplitudes from the stack's one
    scattering matrix; fmmax's own interior solution (every layer's matrices, then the
    amplitudes inside each layer) gives the same, and nothing travels back up the substrate."""
    _fmmax()
    import jax.numpy as jnp
    from fmmax import fields, fmm, scattering

    from splitcam.physics.fullwave import _FmmaxStack, _periodic_solve, _permittivities

    rng = np.random.default_rng(4)
    design = RouterDesign(rng.random((6, 6)) > 0.5, thickness=0.5, depth=1.2)
    stack = _FmmaxStack.of(design, 45, "JONES_DIRECT")
    n = stack.expansion.num_terms

    def plane_wave(ambient):
        return jnp.zeros((2 * n, 2), complex).at[0, 0].set(1.0).at[n, 1].set(1.0)

    um, eps = jnp.asarray(0.58), jnp.asarray(_permittivities(design, 580.0))
    sol = _periodic_solve(
        stack, jnp.asarray(design.grid), um, eps, jnp.asarray([0.4, -0.2]), plane_wave
    )
    fine = jnp.kron(jnp.asarray(design.grid, float), stack.up).T  # fmmax: [x, y]
    patterned = fmm.eigensolve_isotropic_media(
        wavelength=um,
        in_plane_wavevector=jnp.asarray([0.4, -0.2]),
        primitive_lattice_vectors=stack.lattice,
        permittivity=(eps[1] + (eps[0] - eps[1]) * fine).astype(complex),
        expansion=stack.expansion,
        formulation=fmm.Formulation.JONES_DIRECT,
    )
    inner = scattering.stack_s_matrices_interior(
        [sol["ambient"], patterned, sol["substrate"]],
        [jnp.zeros(()), jnp.asarray(design.thickness), jnp.asarray(design.depth)],
    )
    amplitudes = fields.stack_amplitudes_interior(inner, sol["forward"], sol["zero"])
    arriving = fields.propagate_amplitude(
        amplitudes[2][0], jnp.asarray(design.depth), sol["substrate"]
    )
    np.testing.assert_allclose(sol["reflected"], amplitudes[0][1], atol=1e-12)
    np.testing.assert_allclose(sol["arriving"], arriving, atol=1e-12)
    np.testing.assert_allclose(amplitudes[2][1], 0.0, atol=1e-12)
    assert float(jnp.abs(sol["reflected"]).max()) > 0.01  # the layer reflects: not a 0 = 0


def _finite_difference(f, grid: np.ndarray, cells, h: float = 1e-6) -> np.ndarray:
    out = []
    for i, j in cells:
        step = np.zeros_like(grid)
        step[i, j] = h
        out.append((f(grid + step) - f(grid - step)) / (2 * h))
    return np.asarray(out)


@pytest.mark.slow  # about 40 s: six compilations of fmmax's solve
def test_fmmax_quadrants_are_the_spectra_solve_and_differentiate_through_jax():
    """fmmax_quadrants (PyTorch in and out, JAX inside) is what quadrant_spectra solves with
    fmmax; in the FFT formulation its gradient with respect to the cell densities is the
    central difference; in Jones-direct, whose vector field fmmax holds fixed under
    differentiation, it points the same way (cosine above 0.95), not exactly."""
    _fmmax()
    import torch

    from splitcam.physics.fullwave import fmmax_quadrants

    rng = np.random.default_rng(0)
    grid = rng.uniform(0.2, 0.8, (4, 4))
    design = RouterDesign(grid, thickness=0.4, depth=0.8)
    weights = torch.from_numpy(rng.normal(size=(2, 2, 2)))
    cells = [(0, 0), (0, 1), (1, 2), (2, 0), (3, 1), (3, 3)]
    for solver, formulation in (("fmmax-fft", "FFT"), ("fmmax-jones", "JONES_DIRECT")):
        spectra = quadrant_spectra(
            design, [550.0], samples=4, solver=solver, terms=21, directions=[(0.1, 0.3, 1.0)]
        )
        x = torch.tensor(grid, requires_grad=True)
        quads, reflected = fmmax_quadrants(design, x, 550.0, 0.1, 0.3, 21, 4, formulation)
        np.testing.assert_allclose(
            quads.detach().numpy(), spectra["by_polarisation"][..., 0], atol=1e-12
        )
        assert float(reflected.detach()) == pytest.approx(spectra["reflection"][0], abs=1e-12)
        ((quads * weights).sum() + 0.7 * reflected).backward()

        def scalar(v, formulation=formulation):
            q, r = fmmax_quadrants(design, torch.tensor(v), 550.0, 0.1, 0.3, 21, 4, formulation)
            return float((q * weights).sum() + 0.7 * r)

        fd = _finite_difference(scalar, grid, cells)
        ours = np.asarray([float(x.grad[i, j]) for i, j in cells])
        if formulation == "FFT":
            np.testing.assert_allclose(ours, fd, rtol=1e-5, atol=1e-8)
        else:
            cosine = ours @ fd / np.linalg.norm(ours) / np.linalg.norm(fd)
            assert 0.95 < cosine < 1.0 - 1e-9  # close, and not the exact derivative
    with pytest.raises(FullwaveError, match="density of shape"):
        fmmax_quadrants(design, torch.zeros(3, 3, dtype=torch.float64), 500.0)


def test_solver_settings_are_checked(monkeypatch):
    from splitcam.cli import rcwa

    assert rcwa.SOLVERS == SOLVERS  # the parser's copy of the list
    design = RouterDesign(np.ones((2, 2)))
    with pytest.raises(FullwaveError, match="unknown solver 'meep'; expected one of torcwa"):
        quadrant_spectra(design, [500.0], solver="meep")
    with pytest.raises(FullwaveError, match="terms: a number >= 1, for an fmmax solver"):
        quadrant_spectra(design, [500.0], terms=100)
    monkeypatch.setitem(sys.modules, "fmmax", None)
    with pytest.raises(FullwaveError, match=r"pip install 'splitcam\[fmmax\]'"):
        quadrant_spectra(design, [500.0], solver="fmmax-fft")


def test_the_command_solves_with_fmmax_and_says_so(tmp_path, capsys):
    _fmmax()
    from splitcam import patterns
    from splitcam.cli import main

    out = tmp_path / "zou"
    args = ["optics", "rcwa", str(DESIGNS / "zou2022-16x16.csv"), "--wavelengths", "450,650"]
    fmmax = ["--solver", "fmmax-fft", "--terms", "40", "--quiet"]
    assert main([*args, *fmmax, "--out", str(out)]) == 0
    pattern = patterns.get(str(out / "zou2022-16x16.toml"))
    assert "fmmax-fft, 37 terms" in pattern.provenance
    assert main([*args, "--terms", "40", "--out", str(tmp_path / "x")]) == 1
    assert "for an fmmax solver" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_a_missing_extra_is_said_before_any_work(tmp_path, capsys, monkeypatch):
    """Without the solver's extra the command says so in one line, with the install command,
    before a progress bar or any file (the line once came after a 0 % bar)."""
    import importlib.util

    from splitcam.cli import main

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "torcwa" else real(name, *a)
    )
    out = tmp_path / "o"
    assert main(["optics", "rcwa", str(DESIGNS / "zou2022-16x16.csv"), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert "pip install 'splitcam[fullwave]'" in err and len(err.splitlines()) == 1
    assert "%" not in err and not out.exists()
