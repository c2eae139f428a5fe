"""Kernels computed from the fields (splitcam.physics.bloch): against the periodic solves of the
lens's plane waves (an independent computation: another lattice of solves, no spot, no
supercell), light conservation, the folding of the supercell into kernels, the cache, refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from splitcam.physics.fullwave import FullwaveError, RouterDesign, quadrant_spectra

pytest.importorskip("fmmax")
from splitcam.physics.bloch import _fold, pixel_kernels, quadrant_sums  # noqa: E402

SMALL = {"terms": 21, "cells": 2, "samples": 4, "positions": 2}


def _design() -> RouterDesign:
    rng = np.random.default_rng(3)
    grid = (rng.random((4, 4)) > 0.5).astype(float)
    return RouterDesign(grid, thickness=0.25, depth=1.0)


def _free() -> RouterDesign:
    return RouterDesign(
        np.zeros((2, 2)), thickness=0.1, depth=0.2, pillar="vacuum", substrate="vacuum"
    )


def _pupil(lam: float, f_number: float, cells: int, period: float = 2.0) -> list:
    """The plane waves of the Bloch grid inside the lens's pupil, as (theta, phi, weight),
    written out here: wavevectors k + 2 pi (a, b) / P with k on the M x M grid of the zone
    (fmmax's convention for odd and even M: the grid includes 0), |k| <= k0 / (2N)."""
    k0 = 2 * math.pi / (lam / 1000.0)
    step = 2 * math.pi / (cells * period)
    offsets = [(i - (cells - 1) // 2) * step for i in range(cells)]
    out = []
    for ky in offsets:
        for kx in offsets:
            for a in range(-8, 9):
                for b in range(-8, 9):
                    wx, wy = kx + 2 * math.pi * a / period, ky + 2 * math.pi * b / period
                    if math.hypot(wx, wy) <= k0 / (2 * f_number) + 1e-12:
                        out.append((math.asin(math.hypot(wx, wy) / k0), math.atan2(wy, wx), 1.0))
    return out


@pytest.mark.slow
def test_kernels_add_up_to_the_periodic_solves_of_the_lens_plane_waves():
    """Under uniform light (spots everywhere, intensities added) the kernels must give each pixel
    what the periodic solves give for the pupil's plane waves, each carrying the same power:
    the cross terms between plane waves average out over the spot positions. They differ by
    the truncation (a plane wave of the Bloch grid is an order of its wavevector's solve, whose
    Fourier terms are centred elsewhere: the spots' own shares agree to 0.005 here, 0.001 for the
    Zou router at 97 terms) and by what an intensity kernel cannot hold (the fitted kernels:
    0.008 here, 0.006 for the Zou router at 650 nm)."""
    design = _design()
    result = pixel_kernels(design, [600.0], f_number=2.0, **SMALL)
    directions = _pupil(600.0, 2.0, SMALL["cells"])
    assert len(directions) == 9
    solved = quadrant_spectra(
        design,
        [600.0],
        solver="fmmax-jones",
        terms=SMALL["terms"],
        samples=4,
        directions=directions,
    )
    periodic = solved["transmission"]
    np.testing.assert_allclose(quadrant_sums(result["kernels"]), periodic, atol=0.015)
    assert 0 < result["misfit"][0] < 0.2
    # Not trivially so: the pixels receive different shares.
    assert np.ptp(periodic) > 0.1
    # Shares of light: none negative, none above 1, about as much light as was transmitted.
    k = result["kernels"][:, 0]
    assert k.min() >= 0 and k.sum(axis=(-2, -1)).max() <= 1 + 1e-9
    assert k.sum(axis=(-2, -1)).mean() == pytest.approx(periodic.sum(), abs=0.03)


@pytest.mark.slow
def test_free_space_keeps_the_light_on_its_pixel():
    """Without a router the kernels must undo the lens's own blur (an f/2 spot, about 1.3 µm
    across at 550 nm, spills over a 1 µm pixel) and leave each pixel's light on it."""
    result = pixel_kernels(_free(), [550.0], f_number=2.0, **SMALL)
    kernels = result["kernels"][:, 0]
    half = kernels.shape[-1] // 2
    np.testing.assert_allclose(kernels[:, half, half], 1.0, atol=0.01)
    assert kernels.sum() == pytest.approx(4.0, abs=0.01)
    assert result["misfit"][0] < 0.01 and result["reflection"][0] == pytest.approx(0, abs=1e-9)


@pytest.mark.slow  # about 20 s: two Bloch solves compiled
def test_a_layer_cut_in_two_touching_halves_has_the_layer_s_kernels():
    """Layers stacked reach the Bloch solve: the layer as two touching halves gives its kernels
    and reflection (the same stack of scattering matrices), and a spacer between the halves
    moves them."""
    whole = _design()
    halves = RouterDesign(np.stack([whole.grid, whole.grid]), thickness=0.125, depth=1.0)
    apart = RouterDesign(np.stack([whole.grid, whole.grid]), 1.0, 0.125, 1.0, spacer=0.3)
    ours = [pixel_kernels(d, [600.0], f_number=2.0, **SMALL) for d in (whole, halves, apart)]
    np.testing.assert_allclose(ours[1]["kernels"], ours[0]["kernels"], atol=1e-9)
    np.testing.assert_allclose(ours[1]["reflection"], ours[0]["reflection"], atol=1e-9)
    assert np.abs(ours[2]["kernels"] - ours[0]["kernels"]).max() > 1e-3


def test_fold_puts_each_supercell_pixel_at_its_offset_and_splits_the_far_one():
    cells = 2  # a 4 x 4 supercell, offsets -2 .. 2
    shares = np.arange(16.0).reshape(4, 4)
    kernel = _fold(shares, 1, 2, cells)
    assert kernel.sum() == pytest.approx(shares.sum())
    # Written out: pixel (y, x) at offset (y - 1, x - 2) wrapped into -2 .. 1; offset -2 is
    # also +2, each getting half.
    naive = np.zeros((5, 5))
    for y in range(4):
        for x in range(4):
            dy, dx = (y - 1 + 2) % 4 - 2, (x - 2 + 2) % 4 - 2
            ys = [dy] if dy != -2 else [-2, 2]
            xs = [dx] if dx != -2 else [-2, 2]
            for a in ys:
                for b in xs:
                    naive[a + 2, b + 2] += shares[y, x] / (len(ys) * len(xs))
    np.testing.assert_array_equal(kernel, naive)
    assert kernel[2, 2] == shares[1, 2]


@pytest.mark.slow
def test_a_cache_continues_without_solving_again(tmp_path):
    design = _free()
    cache = tmp_path / "solves.jsonl"
    first = pixel_kernels(design, [500.0], cache=cache, **SMALL)
    again = pixel_kernels(design, [500.0], cache=cache, **SMALL)
    assert again["cost"]["reused"] == again["cost"]["solves"] == 4
    np.testing.assert_allclose(again["kernels"], first["kernels"], rtol=1e-12)
    # the numbers kept beside each solve come back from the log with it
    np.testing.assert_allclose(again["misfit"], first["misfit"], rtol=1e-12)
    assert again["terms"] == first["terms"]
    other = pixel_kernels(design, [500.0], cache=cache, **{**SMALL, "positions": 1})
    assert other["cost"]["reused"] == 0  # another setting is solved, not reused


@pytest.mark.parametrize(
    "bad, says",
    [
        ({"cells": 1}, "cells"),
        ({"positions": 0}, "positions"),
        ({"f_number": 0.4}, "f-number"),
        ({"chief_ray": math.radians(80)}, "grazing"),
        ({"formulation": "POL"}, "formulation"),
    ],
)
def test_bad_settings_are_refused_before_any_solve(bad, says):
    with pytest.raises(FullwaveError, match=says):
        pixel_kernels(_design(), [550.0], **{**SMALL, **bad})


@pytest.mark.slow
def test_the_command_writes_both_patterns_and_refuses_bad_settings(tmp_path, capsys):
    """`splitcam optics rcwa-kernels`: the computed pattern (and its 5 x 5 cut where larger),
    the nearest-copy pattern on the same totals, every file a pattern the other commands read;
    bad settings are one line and write nothing."""
    from splitcam import patterns
    from splitcam.cli import main

    design = tmp_path / "d.csv"
    design.write_text("1,0\n0,1\n")
    out = tmp_path / "o"
    args = ["optics", "rcwa-kernels", str(design), "--out", str(out), "--quiet"]
    small = ["--terms", "21", "--samples", "4", "--positions", "1", "--wavelengths", "500,600"]
    assert main([*args, *small, "--cells", "3", "--thickness", "0.3", "--depth", "1"]) == 0
    said = capsys.readouterr().out
    assert "misfit" in said and "18 Bloch solves" in said
    computed = patterns.get(str(out / "d-kernels.json"))
    cut = patterns.get(str(out / "d-kernels-5x5.json"))
    rule = patterns.get(str(out / "d-nearest.toml"))
    assert computed.kernels.shape[-1] == 7 and cut.kernels.shape[-1] == 5
    assert rule.kernels.shape[-1] == 3
    # The two rules spread the same totals: equal light per colour under uniform light.
    np.testing.assert_allclose(
        computed.kernels.sum(axis=(-2, -1)).mean(axis=0),
        rule.kernels.sum(axis=(-2, -1)).mean(axis=0),
        atol=1e-4,
    )
    bad = tmp_path / "bad"
    assert main(["optics", "rcwa-kernels", str(design), "--out", str(bad), "--cells", "1"]) == 1
    assert "cells must be" in capsys.readouterr().err and not bad.exists()
