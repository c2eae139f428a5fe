"""Period shuffles (splitcam.physics.periodic): round trips, partial cells, sizes refused."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from splitcam.physics.periodic import period_shuffle, period_unshuffle


@pytest.mark.parametrize("period", [(1, 1), (2, 2), (3, 3), (1, 3), (3, 2), (2, 5)])
def test_period_unshuffle_round_trip(period):
    ph, pw = period
    x = torch.rand(2, 3, 4 * ph, 5 * pw)
    packed = period_unshuffle(x, period)
    assert packed.shape == (2, 3 * ph * pw, 4, 5)
    assert torch.equal(period_shuffle(packed, period), x)
    # Channel c * Ph * Pw + i * Pw + j of cell (u, v) is pixel (u * Ph + i, v * Pw + j).
    for c in range(3):
        for i in range(ph):
            for j in range(pw):
                assert torch.equal(packed[:, c * ph * pw + i * pw + j], x[:, c, i::ph, j::pw])


@pytest.mark.parametrize("factor", [1, 2, 3])
def test_period_unshuffle_matches_torch_for_square(factor):
    x = torch.rand(1, 2, 6 * factor, 3 * factor)
    assert torch.equal(period_unshuffle(x, (factor, factor)), F.pixel_unshuffle(x, factor))
    y = torch.rand(1, 2 * factor * factor, 3, 4)
    assert torch.equal(period_shuffle(y, (factor, factor)), F.pixel_shuffle(y, factor))


@pytest.mark.parametrize("period", [(2, 2), (1, 3), (2, 3)])
def test_period_unshuffle_pads_partial_cells_and_shuffle_crops_them(period):
    x = torch.rand(2, 3, 5, 7)
    packed = period_unshuffle(x, period)
    ph, pw = period
    assert packed.shape == (2, 3 * ph * pw, -(-5 // ph), -(-7 // pw))
    padded = F.pad(x, (0, -7 % pw, 0, -5 % ph))
    assert torch.equal(period_shuffle(packed, period), padded)  # zeros where the pad was
    assert torch.equal(period_shuffle(packed, period, (5, 7)), x)


def test_period_shuffle_rejects_bad_sizes():
    with pytest.raises(ValueError, match="for the period"):
        period_shuffle(torch.rand(1, 5, 3, 3), (2, 2))
