"""The one tiling mechanism (splitcam.recon.tiling) and the methods that use it."""

from __future__ import annotations

import pytest
import torch

from splitcam import patterns
from splitcam.physics.periodic import phase_conv, phase_map
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.networks import (
    PackedReconNet,
    ReconNet,
)
from splitcam.recon.tiling import reconstruct, tile_spans, tiled


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

    lmmse = closed_form_lmmse(patterns.get("D"))
    rgb = torch.rand(1, 3, 70, 90, dtype=torch.float64)
    raw = SplitterSensor("D").double()(rgb)
    weights, bias = lmmse.statistics.filters(5.0)
    expected = phase_conv(raw, weights.unsqueeze(2), (2, 2))
    expected = expected + bias[phase_map(70, 90, (2, 2), raw.device)].permute(2, 0, 1)[None]
    monkeypatch.setattr(lmmse_module, "DEFAULT_TILE", 24)
    torch.testing.assert_close(lmmse.reconstruct(raw, 5.0), expected, rtol=0, atol=1e-12)


ARCHS = [ReconNet, PackedReconNet]


def _small(cls, period, features=8, blocks=2, seed=0, dtype=torch.float32):
    torch.manual_seed(seed)
    return cls(period, features=features, blocks=blocks).to(dtype)


@pytest.mark.parametrize(
    ("cls", "period", "tile", "size"),
    [
        (ReconNet, (2, 2), 21, (45, 38)),
        (ReconNet, (1, 3), 23, (50, 41)),
        (PackedReconNet, (2, 2), 29, (61, 47)),
        (PackedReconNet, (1, 3), 41, (62, 95)),
    ],
)
def test_tiled_equals_untiled(cls, period, tile, size):
    blocks = 2 if cls is ReconNet else 1
    net = _small(cls, period, blocks=blocks)
    torch.manual_seed(2)
    raw = torch.rand(2, 1, *size)
    with torch.no_grad():
        full = net(raw)
    tiled = reconstruct(net, raw, tile=tile)
    assert tiled.shape == full.shape
    assert tiled.dtype == full.dtype
    assert (tiled - full).abs().max() < 1e-5
    # A larger, non-default overlap is also exact.
    wider = reconstruct(net, raw, tile=tile + 10, overlap=net.receptive_radius + 1)
    assert (wider - full).abs().max() < 1e-5


@pytest.mark.parametrize("cls", ARCHS)
def test_tile_larger_than_image_and_none(cls):
    net = _small(cls, (2, 2), features=4, blocks=1)
    raw = torch.rand(1, 1, 9, 11)
    with torch.no_grad():
        full = net(raw)
    assert torch.equal(reconstruct(net, raw, tile=64), full)
    assert torch.equal(reconstruct(net, raw, tile=None), full)


def test_reconstruct_runs_without_autograd_and_progress(capsys):
    net = _small(ReconNet, (2, 2), features=4, blocks=1)
    raw = torch.rand(1, 1, 30, 30, requires_grad=True)
    out = reconstruct(net, raw, tile=20, progress=True)
    assert not out.requires_grad
    assert out.shape == (1, 3, 30, 30)


def test_reconstruct_bad_arguments():
    net = _small(ReconNet, (2, 2), features=4, blocks=1)  # receptive radius 5
    raw = torch.rand(1, 1, 40, 40)
    with pytest.raises(ValueError, match="receptive radius 5"):
        reconstruct(net, raw, tile=16, overlap=4)
    with pytest.raises(ValueError, match="too small"):
        reconstruct(net, raw, tile=12)
    with pytest.raises(ValueError, match="tile must be"):
        reconstruct(net, raw, tile=0)
    with pytest.raises(ValueError, match=r"expected \(N, 1, H, W\)"):
        reconstruct(net, torch.rand(1, 3, 8, 8), tile=16)
    with pytest.raises(TypeError, match="period"):
        reconstruct(torch.nn.Identity(), raw, tile=16)


@pytest.mark.parametrize("period", [1, 2, 3])
@pytest.mark.parametrize("overlap", [0, 3, 8])
@pytest.mark.parametrize("tile", [19, 24, 40])
def test_tile_spans_properties(period, overlap, tile):
    for size in range(1, 130):
        if size > tile and (tile - 2 * overlap) // period * period < period:
            with pytest.raises(ValueError):
                tile_spans(size, tile, overlap, period)
            continue
        spans = tile_spans(size, tile, overlap, period)
        assert spans[0].keep_start == 0 and spans[-1].keep_stop == size
        for prev, nxt in zip(spans, spans[1:], strict=False):
            assert prev.keep_stop == nxt.keep_start
        for s in spans:
            assert s.start % period == 0
            assert 0 <= s.start <= s.keep_start < s.keep_stop <= s.stop <= size
            assert s.stop - s.start <= tile
            if s.start > 0:
                assert s.keep_start - s.start >= overlap
            if s.stop < size:
                assert s.stop - s.keep_stop >= overlap


def test_channels_last_leaves_the_network_as_it_was() -> None:
    """Reconstruction in channels-last memory used to convert the network's weights in place; a
    network that is also training (validation reconstructs with it) then stepped on in another
    layout, and a resumed run differed from an uninterrupted one by ~1e-8. The weights now come
    back in their own layout and storage, and the result equals the contiguous one."""
    from splitcam.physics.sensor import pattern_pixel_kernels
    from splitcam.recon.networks import build_network
    from splitcam.recon.tiling import reconstruct

    torch.manual_seed(0)
    net = build_network({"arch": "physics", "period": [2, 2], "features": 8, "blocks": 1}).eval()
    storage = {n: p.data_ptr() for n, p in net.named_parameters()}
    raw = torch.rand(1, 1, 20, 22, generator=torch.Generator().manual_seed(1))
    physics = {"sigma": 5.0, "kernels": pattern_pixel_kernels(patterns.get("D"))}
    plain = reconstruct(net, raw, tile=None, **physics)
    fast = reconstruct(net, raw, tile=None, channels_last=True, **physics)
    torch.testing.assert_close(fast, plain, rtol=0, atol=1e-6)
    assert all(p.is_contiguous() for p in net.parameters())
    assert {n: p.data_ptr() for n, p in net.named_parameters()} == storage
