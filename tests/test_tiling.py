"""The one tiling mechanism (splitcam.recon.tiling.tiled) and the methods that use it."""

from __future__ import annotations

import pytest
import torch

from splitcam.physics.periodic import phase_conv, phase_map
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.demosaic import ClassicalDemosaic
from splitcam.recon.tiling import tiled


def _periodic_filter(period: tuple[int, int], radius: int, seed: int = 0):
    """A random local, periodic reconstruction: per-phase (2r+1)^2 filters plus bias."""
    g = torch.Generator().manual_seed(seed)
    p = period[0] * period[1]
    k = 2 * radius + 1
    weights = torch.randn(p, 3, 1, k, k, generator=g, dtype=torch.float64)
    bias = torch.randn(p, 3, generator=g, dtype=torch.float64)

    def fn(raw: torch.Tensor) -> torch.Tensor:
        phase = phase_map(*raw.shape[-2:], period, raw.device)
        return phase_conv(raw, weights, period) + bias[phase].permute(2, 0, 1).unsqueeze(0)

    return fn


@pytest.mark.parametrize(
    ("period", "radius", "size"),
    [((2, 2), 2, (53, 47)), ((3, 2), 3, (61, 40)), ((4, 4), 1, (45, 70)), ((1, 3), 4, (37, 66))],
)
def test_tiled_equals_the_whole_image(period, radius, size) -> None:
    fn = _periodic_filter(period, radius)
    raw = torch.rand(2, 1, *size, dtype=torch.float64)
    whole = fn(raw)
    out = tiled(fn, raw, period, radius, tile=20)
    torch.testing.assert_close(out, whole, rtol=0, atol=1e-12)


def test_too_little_overlap_is_refused_and_would_be_wrong() -> None:
    period, radius = (2, 2), 3
    fn = _periodic_filter(period, radius)
    raw = torch.rand(1, 1, 50, 50, dtype=torch.float64)
    with pytest.raises(ValueError, match="overlap must be an integer >= the receptive radius 3"):
        tiled(fn, raw, period, radius, tile=20, overlap=2)
    # Declared with a radius one short, the tiles would be wrong: the check matters.
    short = tiled(fn, raw, period, radius - 1, tile=20, overlap=2)
    assert not torch.allclose(short, fn(raw))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tile": 0}, "tile must be a positive integer"),
        ({"tile": 2.5}, "tile must be a positive integer"),
        ({"tile": 4}, "too small"),
    ],
)
def test_bad_tiles_are_refused(kwargs, message) -> None:
    fn = _periodic_filter((2, 2), 2)
    with pytest.raises(ValueError, match=message):
        tiled(fn, torch.rand(1, 1, 30, 30), (2, 2), 2, **kwargs)


def test_bad_period_and_radius_are_refused() -> None:
    fn = _periodic_filter((2, 2), 1)
    raw = torch.rand(1, 1, 30, 30)
    with pytest.raises(ValueError, match="period must be two positive integers"):
        tiled(fn, raw, (0, 2), 1, tile=10)
    with pytest.raises(ValueError, match="radius must be an integer >= 0"):
        tiled(fn, raw, (2, 2), -1, tile=10)


def test_lmmse_in_tiles_equals_its_filters_applied_by_hand(monkeypatch) -> None:
    from splitcam.recon import lmmse as lmmse_module

    lmmse = closed_form_lmmse("D")
    rgb = torch.rand(1, 3, 70, 90, dtype=torch.float64)
    raw = SplitterSensor("D").double()(rgb)
    weights, bias = lmmse.statistics.filters(5.0)
    expected = phase_conv(raw, weights.unsqueeze(2), (2, 2))
    expected = expected + bias[phase_map(70, 90, (2, 2), raw.device)].permute(2, 0, 1)[None]
    monkeypatch.setattr(lmmse_module, "DEFAULT_TILE", 24)
    torch.testing.assert_close(lmmse.reconstruct(raw, 5.0), expected, rtol=0, atol=1e-12)


def _mosaic(size: tuple[int, int], seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(1, 1, *size, generator=g, dtype=torch.float64)


@pytest.mark.parametrize("method", ClassicalDemosaic.METHODS)
def test_demosaic_radius_is_exact_both_ways(method) -> None:
    """Tiles overlapping by the documented radius reproduce the whole image exactly; one pixel
    less does not; and one changed mosaic pixel changes nothing farther than the radius."""
    demosaic = ClassicalDemosaic(method, tile=None)
    radius = demosaic.radius
    raw = _mosaic((64, 72), 1)
    whole = demosaic.demosaic(raw)
    tile = 24 + 2 * radius
    out = tiled(demosaic.demosaic, raw, (2, 2), radius, tile=tile, overlap=radius)
    torch.testing.assert_close(out, whole, rtol=0, atol=0)
    if radius > 1:
        short = tiled(demosaic.demosaic, raw, (2, 2), radius - 1, tile=tile, overlap=radius - 1)
        assert not torch.equal(short, whole)
    # Reach: poke one pixel of each phase of the period in the middle, see how far the output
    # changes (it differs between phases: menon2007 reaches 6, 4, 7 and 6 pixels).
    reach = 0
    for dy in (0, 1):
        for dx in (0, 1):
            y, x = 32 + dy, 36 + dx
            poked = raw.clone()
            poked[0, 0, y, x] += 0.5
            diff = (demosaic.demosaic(poked) - whole).abs().amax(1)[0]
            ys, xs = torch.nonzero(diff > 0, as_tuple=True)
            reach = max(reach, int(torch.maximum((ys - y).abs(), (xs - x).abs()).max()))
    assert reach <= radius
    assert method == "bilinear" or reach >= radius - 1  # the radius is not loose either
