"""The design-principle measures (splitcam.patterns.measures) against hand computation."""

from __future__ import annotations

import numpy as np
import pytest

from splitcam import patterns


def test_measures_match_hand_computation():
    m = {n: patterns.measure(patterns.get(n)) for n in patterns.names()}
    # D: the red deflector moves all its red (1 of 12 colour-sites of light), the blue one its
    # blue: 2/12 of the incident light leaves its pixel.
    assert m["D"].split_fraction == pytest.approx(2 / 12)
    assert m["D"].spread == pytest.approx(1.0)
    # A: only R at R sites, G at G sites and B at B sites stay: 4 of 12 stay.
    assert m["A"].split_fraction == pytest.approx(8 / 12)
    assert m["A"].spread == pytest.approx(np.sqrt(2))
    # E: 2 of 9 colour-sites of light move (R and B of the splitter pixel).
    assert m["E"].split_fraction == pytest.approx(2 / 9)
    assert m["C"].spread == pytest.approx(2.0)
    assert m["bayer"].efficiency == pytest.approx((0.25, 0.5, 0.25))
    assert m["A"].efficiency == pytest.approx((1.0, 1.0, 1.0))
    assert [n for n in m if m[n].pooling] == ["B", "C"]
    assert m["B"].pooling_unit == 4 and m["C"].pooling_unit == 3
    # A's mean distance travelled, per period: R moves 1 unit by 1 px from each of the two G
    # sites and 1 unit by sqrt2 from the B site; G moves 1 unit by 1 px from the R and B sites;
    # B like R; divided by the 12 units of light.
    travel = (2 * (2 + np.sqrt(2)) + 2) / 12
    assert m["A"].mean_travel == pytest.approx(travel)


def test_low_light_filter_arrays_collect_their_share_of_white_light():
    """model.md §14: RGBW collects 2/3 of white light (twice Bayer), Quad Bayer 1/3; counted
    independently here from the layouts' pixel types."""
    import numpy as np

    rgbw, quad, bayer = (patterns.get(n) for n in ("rgbw", "quad", "bayer"))
    assert rgbw.period == quad.period == (4, 4)
    # Half of RGBW's pixels pass all three colours, the other half one.
    passes = rgbw.kernels[rgbw.layout].sum(axis=(-1, -2)).sum(-1)  # colours passed per pixel
    assert (passes == 3).sum() == 8 and (passes == 1).sum() == 8
    assert patterns.measure(rgbw).white == pytest.approx(2 / 3)
    assert patterns.measure(quad).white == pytest.approx(1 / 3)
    assert patterns.measure(bayer).white == pytest.approx(1 / 3)
    assert patterns.measure(patterns.get("A")).white == pytest.approx(1.0)
    # Quad Bayer is Bayer with every pixel doubled in both directions.
    colour = quad.kernels[quad.layout][..., 0, 0].argmax(-1)
    bayer_colour = bayer.kernels[bayer.layout][..., 0, 0].argmax(-1)
    assert np.array_equal(colour, np.kron(bayer_colour, np.ones((2, 2), dtype=int)))
