"""Filter arrays from measured camera sensitivities (splitcam.patterns.measured)."""

from __future__ import annotations

import numpy as np
import pytest

from splitcam import patterns
from splitcam.patterns.measured import camera_filters
from splitcam.patterns.spectral import scene_basis


@pytest.mark.parametrize("camera", ["d5100", "sdmerrill"])
def test_measured_arrays_are_their_cameras_filters(camera):
    grid, filters = camera_filters(camera)
    assert grid[0] >= 400 and grid[-1] <= 700 and np.allclose(np.diff(grid), 10)
    np.testing.assert_allclose(filters.max(axis=0), 1.0)
    bayer = patterns.get(f"bayer-{camera}")
    rgbw = patterns.get(f"rgbw-{camera}")
    e = scene_basis(grid)
    # The red pixel (0, 0) of RGGB: its filter times each colour's unit spectrum, summed.
    np.testing.assert_allclose(bayer.kernels[bayer.layout[0, 0], :, 0, 0], filters[:, 0] @ e)
    # The W pixels of RGBW are bare: all light of every colour.
    w = rgbw.layout[0, 0]
    np.testing.assert_allclose(rgbw.kernels[w, :, 0, 0], 1.0)
    # Each D5100 filter passes its own colour best; the Foveon's top ("blue") layer records
    # more green than blue, as its broad published curve says.
    best = [
        bayer.kernels[bayer.layout[i, j], :, 0, 0].argmax() for i, j in [(0, 0), (0, 1), (1, 1)]
    ]
    assert best == ([0, 1, 2] if camera == "d5100" else [0, 1, 1])
    # Real filters leak: less pure than the ideal array, which they share the layout with.
    ideal = patterns.measure(patterns.get("bayer"))
    real = patterns.measure(bayer)
    assert real.purity < ideal.purity == 1.0
    assert np.array_equal(bayer.layout == bayer.layout[0, 1], patterns.get("bayer").layout % 3 != 0)


def test_the_foveon_curves_leak_more_than_the_bayer_filters():
    d5100 = patterns.measure(patterns.get("bayer-d5100"))
    merrill = patterns.measure(patterns.get("bayer-sdmerrill"))
    assert merrill.purity < d5100.purity
    assert merrill.white > d5100.white
