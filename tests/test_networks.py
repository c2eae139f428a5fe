"""Tests for splitcam.recon.networks and splitcam.recon.tiling (small, CPU)."""

from __future__ import annotations

import json

import pytest
import torch
import torch.nn.functional as F

from splitcam.physics.periodic import period_shuffle, period_unshuffle
from splitcam.recon.networks import (
    PackedReconNet,
    PeriodicSampling,
    ReconNet,
    build_network,
)
from splitcam.recon.tiling import reconstruct, tile_spans

PERIODS = [(2, 2), (1, 3), (3, 2)]
ARCHS = [ReconNet, PackedReconNet]


def _small(cls, period, features=8, blocks=2, seed=0, dtype=torch.float32):
    torch.manual_seed(seed)
    return cls(period, features=features, blocks=blocks).to(dtype)


def _expected_params(cin: int, cout: int, features: int, blocks: int) -> int:
    def conv(i: int, o: int) -> int:
        return 9 * i * o + o

    return (
        conv(cin, features)
        + blocks * 2 * conv(features, features)
        + conv(features, features)
        + conv(features, cout)
    )


def _count(net: torch.nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())


# --- parameter counts -------------------------------------------------------------------------


def test_paper_default_parameter_count():
    assert _count(ReconNet((2, 2))) == 779_587


@pytest.mark.parametrize("period", [(1, 1), (1, 3), (3, 2), (4, 4)])
def test_parameter_count_formula(period):
    p = period[0] * period[1]
    assert _count(ReconNet(period, features=16, blocks=3)) == _expected_params(p, 3, 16, 3)
    assert _count(PackedReconNet(period, features=16, blocks=3)) == _expected_params(
        p, 3 * p, 16, 3
    )


def test_parameter_count_formula_matches_default():
    assert _expected_params(4, 3, 64, 10) == 779_587


# --- sampling layer ---------------------------------------------------------------------------


@pytest.mark.parametrize("period", PERIODS)
@pytest.mark.parametrize("size", [(7, 5), (1, 1), (4, 6)])
def test_sampling_matches_naive_loop(period, size):
    ph, pw = period
    h, w = size
    raw = torch.rand(2, 1, h, w, dtype=torch.float64) + 0.5
    expected = torch.zeros(2, ph * pw, h, w, dtype=torch.float64)
    for y in range(h):
        for x in range(w):
            expected[:, (y % ph) * pw + (x % pw), y, x] = raw[:, 0, y, x]
    got = PeriodicSampling(period)(raw)
    assert got.dtype == torch.float64
    assert torch.equal(got, expected)


# --- shapes, dtypes, input validation ---------------------------------------------------------


@pytest.mark.parametrize("cls", ARCHS)
@pytest.mark.parametrize("period", PERIODS)
@pytest.mark.parametrize("size", [(7, 5), (1, 1), (2, 9)])
def test_forward_shape(cls, period, size):
    net = _small(cls, period, features=4, blocks=1)
    out = net(torch.rand(2, 1, *size))
    assert out.shape == (2, 3, *size)
    assert out.dtype == torch.float32


@pytest.mark.parametrize("cls", ARCHS)
def test_float64(cls):
    net = _small(cls, (2, 2), dtype=torch.float64)
    out = net(torch.rand(1, 1, 5, 7, dtype=torch.float64))
    assert out.dtype == torch.float64
    assert out.shape == (1, 3, 5, 7)


@pytest.mark.parametrize("cls", ARCHS)
@pytest.mark.parametrize(
    ("bad", "error", "message"),
    [
        (torch.rand(2, 3, 8, 8), ValueError, "expected (N, 1, H, W), got (2, 3, 8, 8)"),
        (torch.rand(1, 8, 8), ValueError, "expected (N, 1, H, W), got (1, 8, 8)"),
        (torch.rand(1, 1, 0, 8), ValueError, "H, W >= 1"),
        (torch.ones(1, 1, 4, 4, dtype=torch.int64), TypeError, "floating-point"),
        ([[1.0]], TypeError, "torch.Tensor"),
    ],
)
def test_bad_input(cls, bad, error, message):
    net = _small(cls, (2, 2), features=4, blocks=1)
    with pytest.raises(error) as info:
        net(bad)
    assert message in str(info.value)


@pytest.mark.parametrize("cls", ARCHS)
@pytest.mark.parametrize(
    "kwargs",
    [
        {"period": (0, 2)},
        {"period": (2,)},
        {"period": (2.0, 2)},
        {"period": (2, 2), "features": 0},
        {"period": (2, 2), "blocks": -1},
        {"period": (2, 2), "blocks": True},
    ],
)
def test_bad_constructor_arguments(cls, kwargs):
    with pytest.raises(ValueError):
        cls(**kwargs)


# --- receptive radius -------------------------------------------------------------------------


def _influence(net, size, pixel):
    """|net(raw with one pixel changed) - net(raw)|, max over batch and colour, in float64."""
    torch.manual_seed(1)
    raw = torch.rand(1, 1, *size, dtype=torch.float64)
    bumped = raw.clone()
    bumped[0, 0, pixel[0], pixel[1]] += 5.0
    with torch.no_grad():
        return (net(bumped) - net(raw)).abs().amax(dim=(0, 1))


def _chebyshev(size, pixel):
    ys = torch.arange(size[0])[:, None]
    xs = torch.arange(size[1])[None, :]
    return torch.maximum((ys - pixel[0]).abs(), (xs - pixel[1]).abs())


def test_receptive_radius_from_architecture():
    assert ReconNet((2, 2)).receptive_radius == 23
    assert ReconNet((2, 2), blocks=3).receptive_radius == 9
    assert ReconNet((3, 1), blocks=0).receptive_radius == 3
    assert PackedReconNet((2, 2)).receptive_radius == 24 * 2 - 1
    assert PackedReconNet((1, 3), blocks=2).receptive_radius == 8 * 3 - 1
    assert PackedReconNet((1, 1), blocks=2).receptive_radius == 7


@pytest.mark.parametrize("period", PERIODS)
@pytest.mark.parametrize("pixel", [(15, 15), (16, 17)])
def test_receptive_radius_paper_is_exact(period, pixel):
    net = _small(ReconNet, period, dtype=torch.float64)
    radius = net.receptive_radius
    assert radius == 7
    size = (32, 33)
    diff = _influence(net, size, pixel)
    dist = _chebyshev(size, pixel)
    assert diff[dist > radius].max() < 1e-12
    # Every pixel of the (2r+1)^2 square changes, up to and including its border.
    assert diff[dist <= radius].min() > 1e-9


@pytest.mark.parametrize("period", [(2, 2), (1, 3), (3, 2)])
def test_receptive_radius_packed_bounds_and_is_attained(period):
    net = _small(PackedReconNet, period, blocks=1, dtype=torch.float64)
    radius = net.receptive_radius
    size = (48, 49)
    reached = 0
    ph, pw = period
    # Cell corners and a pixel in the middle of a cell: the reach depends on the offset in it.
    for pixel in [(4 * ph, 4 * pw), (5 * ph - 1, 5 * pw - 1), (4 * ph + ph // 2, 4 * pw + pw // 2)]:
        pixel = (pixel[0] + 12, pixel[1] + 12)
        diff = _influence(net, size, pixel)
        dist = _chebyshev(size, pixel)
        assert diff[dist > radius].max() < 1e-12
        reached = max(reached, int(dist[diff > 1e-9].max()))
    assert reached == radius


# --- tiled inference --------------------------------------------------------------------------


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


# --- configs ----------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", ARCHS)
@pytest.mark.parametrize("period", [(2, 2), (1, 3)])
def test_config_round_trip(cls, period):
    net = _small(cls, period, features=6, blocks=2)
    config = json.loads(json.dumps(net.config()))
    assert config == {
        "arch": "paper" if cls is ReconNet else "packed",
        "period": list(period),
        "features": 6,
        "blocks": 2,
    }
    rebuilt = build_network(config)
    assert type(rebuilt) is cls
    assert rebuilt.period == period
    rebuilt.load_state_dict(net.state_dict())
    raw = torch.rand(1, 1, 7, 10)
    with torch.no_grad():
        assert torch.equal(rebuilt(raw), net(raw))


def test_build_network_defaults():
    net = build_network({"arch": "paper", "period": [2, 2]})
    assert _count(net) == 779_587


@pytest.mark.parametrize(
    ("config", "message"),
    [
        ({"arch": "unet", "period": [2, 2]}, "unknown network arch 'unet'"),
        ({"period": [2, 2]}, "unknown network arch None"),
        ({"arch": ["paper"], "period": [2, 2]}, "unknown network arch"),
        ({"arch": "paper"}, "period"),
        ({"arch": "paper", "period": [2, 2], "width": 3}, "unknown network config field"),
        ({"arch": "packed", "period": [2, 0]}, "period must be"),
        ({"arch": "paper", "period": [2, 2], "features": "64"}, "features must be"),
        ({"arch": "paper", "period": [2, 2], "blocks": 1.5}, "blocks must be"),
        ("paper", "must be a mapping"),
    ],
)
def test_build_network_errors(config, message):
    with pytest.raises(ValueError) as info:
        build_network(config)
    assert message in str(info.value)


# --- pixel (un)shuffle with rectangular periods -----------------------------------------------


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
