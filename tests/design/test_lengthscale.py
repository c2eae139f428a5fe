"""A binary layer made to keep a minimum feature (splitcam.design.lengthscale), measured by
imageruler (the length-scale measure of inverse design, an independent implementation) and by
construction: specks and slits narrower than the brush go, features that fit it stay, the layer
wraps around its edges."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from splitcam.design.lengthscale import (
    LengthScaleError,
    brush,
    keeps_minimum_feature,
    with_minimum_feature,
)


def _disc(shape, centre, diameter):
    rows, cols = np.indices(shape)
    dy = (rows - centre[0] + shape[0] / 2) % shape[0] - shape[0] / 2  # periodic distance
    dx = (cols - centre[1] + shape[1] / 2) % shape[1] - shape[1] / 2
    return dy**2 + dx**2 < (diameter / 2) ** 2


def _thresholded_noise(seed: int, shape=(64, 64), blur=2.5) -> np.ndarray:
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    return ndimage.gaussian_filter(rng.random(shape), blur, mode="wrap") > 0.5


def test_the_brush_is_the_disc_of_its_diameter():
    assert brush(1).tolist() == [[True]]
    assert brush(3).all()  # a 3-cell disc's corners are inside its circle (1.41 < 1.5)
    b = brush(8)
    assert b.shape == (8, 8) and b[3:5].all() and not b[0, 0] and b[0, 3]
    assert np.array_equal(b, b.T) and np.array_equal(b, b[::-1])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("diameter", [4, 8])
def test_a_thresholded_layer_is_made_to_keep_the_feature_as_imageruler_measures_it(seed, diameter):
    imageruler = pytest.importorskip("imageruler")
    layer = _thresholded_noise(seed, blur=0.65 * diameter)
    solid, void = imageruler.minimum_length_scale(layer, periodic=(True, True))
    assert min(solid, void) < diameter  # the raw threshold breaks the rule
    fixed = with_minimum_feature(layer, diameter)
    assert keeps_minimum_feature(fixed, diameter)
    solid, void = imageruler.minimum_length_scale(fixed, periodic=(True, True))
    assert solid >= diameter and void >= diameter
    assert (fixed != layer).mean() < 0.2  # a repair, not a new layer


def test_specks_and_slits_go_and_what_fits_the_brush_stays_across_the_edges():
    shape = (48, 48)
    big = _disc(shape, (0, 0), 14) | _disc(shape, (24, 30), 12)  # one wraps the corners
    speck = _disc(shape, (24, 8), 3)
    slit = np.zeros(shape, bool)
    slit[24, 26:35] = True  # a one-cell cut through the second disc
    layer = (big | speck) & ~slit
    fixed = with_minimum_feature(layer, 8)
    assert np.array_equal(fixed, big)
    assert np.array_equal(with_minimum_feature(big, 8), big)  # a layer that keeps it: as it was
    assert keeps_minimum_feature(big, 8) and not keeps_minimum_feature(layer, 8)


def test_two_pillars_a_slit_apart_are_kept_apart_or_joined_wide_never_by_a_neck():
    """Closing fills the slit between two pillars near their closest point, and the opening
    would cut that neck again: the alternation must settle (a neck is opened to the brush)."""
    imageruler = pytest.importorskip("imageruler")
    shape = (40, 60)
    layer = _disc(shape, (20, 17), 18) | _disc(shape, (20, 43), 18)  # 8 cells, then a 1-cell gap
    layer[:, 29:31] &= False
    layer |= _disc(shape, (20, 30), 4) & ~layer  # a bridge narrower than the brush
    fixed = with_minimum_feature(layer, 6)
    assert min(imageruler.minimum_length_scale(fixed, periodic=(True, True))) >= 6


def test_bad_layers_are_refused_in_one_line():
    with pytest.raises(LengthScaleError, match="2-D"):
        with_minimum_feature(np.zeros((2, 4, 4)), 3)
    with pytest.raises(LengthScaleError, match="does not fit"):
        with_minimum_feature(np.zeros((6, 6)), 8)
    with pytest.raises(LengthScaleError, match="at least 1 cell"):
        brush(0)
    assert np.array_equal(with_minimum_feature(np.eye(5), 1), np.eye(5, dtype=bool))


def test_the_designs_binary_layer_keeps_its_feature_and_the_loss_sees_that_layer():
    """FullwaveDesign.binary is the thresholded densities made to keep the filter's radius as a
    feature; the binary steps' forward pass is that same layer."""
    pytest.importorskip("torcwa")
    from splitcam.design.fullwave import FullwaveDesign
    from splitcam.physics.fullwave import RouterDesign

    design = FullwaveDesign(RouterDesign(np.eye(48)), radius=6.0)
    theta = torch.from_numpy(np.random.default_rng(3).normal(0, 2, (48, 48)))
    layer = design.binary(theta, beta=8.0)
    assert design.feature_cells == 6 and keeps_minimum_feature(layer, 6)
    raw = (design.densities(theta, 8.0) >= 0.5).numpy()
    assert not keeps_minimum_feature(raw, 6)  # the threshold alone would not
    forward = design.binarised(theta.clone().requires_grad_(True), 8.0)
    assert np.array_equal(forward.detach().numpy(), layer)


def test_the_measured_length_scale_is_the_narrowest_feature_solid_and_void():
    from splitcam.design.lengthscale import minimum_length_scale

    shape = (48, 48)
    discs = _disc(shape, (0, 0), 14) | _disc(shape, (24, 30), 11)  # one wraps the corners
    solid, void = minimum_length_scale(discs)
    assert solid == 11 and void > 11  # the smaller disc; the gaps between them are wide
    slit = discs.copy()
    slit[:, 40:43] = True  # a wall 3 cells wide, across the period
    assert minimum_length_scale(slit)[0] == 3
    cut = discs.copy()
    cut[24, :] = False  # a one-cell slit across the period and through the smaller disc
    assert minimum_length_scale(cut)[1] == 1
    uniform = np.zeros((20, 30), bool)
    assert minimum_length_scale(uniform) == (20, 20)
    assert minimum_length_scale(discs, limit=5) == (5, 5)
    with pytest.raises(LengthScaleError, match="2-D grid"):
        minimum_length_scale(np.zeros(5, bool))


@pytest.mark.parametrize("seed", [0, 3])
def test_the_measured_length_scale_is_at_most_imagerulers_and_kept_by_the_repair(seed):
    """imageruler lets the brush miss single cells along an interface, so it measures at
    least ours; a layer made to keep d cells measures at least d by both."""
    imageruler = pytest.importorskip("imageruler")
    from splitcam.design.lengthscale import minimum_length_scale

    layer = _thresholded_noise(seed, blur=4.0)
    for x in (layer, with_minimum_feature(layer, 6)):
        ours = minimum_length_scale(x)
        theirs = imageruler.minimum_length_scale(x, periodic=(True, True))
        assert ours[0] <= theirs[0] and ours[1] <= theirs[1]
        assert keeps_minimum_feature(x, min(ours))
    assert min(minimum_length_scale(with_minimum_feature(layer, 6))) >= 6
