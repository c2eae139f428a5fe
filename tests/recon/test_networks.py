"""The reconstruction networks (splitcam.recon.networks): the plain and packed networks, the
physics-informed network (LMMSE estimate plus a learned correction) and the universal network
for any pattern."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.patterns.random import random_pattern
from splitcam.physics.noise import Exposure, GaussianNoise
from splitcam.physics.sensor import (
    LearnableSplitterSensor,
    SplitterSensor,
    pattern_pixel_kernels,
)
from splitcam.physics.system import ImagingSystem
from splitcam.recon.base import NetworkReconstructor
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.networks import (
    PackedReconNet,
    PeriodicSampling,
    PhysicsReconNet,
    ReconNet,
    UniversalReconNet,
    build_network,
)

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


def _scene(n: int = 2, size: int = 40, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, size + 4, size + 4, generator=g)
    return torch.nn.functional.avg_pool2d(x, 5, stride=1)


@pytest.mark.parametrize("name", ["D", "C"])
def test_untrained_network_outputs_the_lmmse_estimate(name: str) -> None:
    rgb = _scene()
    raw = SplitterSensor(name)(rgb) + 0.02 * torch.randn(2, 1, 40, 40)
    sensor = SplitterSensor(name)
    net = PhysicsReconNet(sensor.period, features=8, blocks=1)
    out = net(raw, 5.0, pattern_pixel_kernels(patterns.get(name)))
    expected = closed_form_lmmse(patterns.get(name)).reconstruct(raw, 5.0)
    torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-5)
    # Through the reconstruction interface likewise.
    method = NetworkReconstructor(net, sensor.to_pattern(name), "net", tile=48, precision="fp32")
    torch.testing.assert_close(method.reconstruct(raw, 5.0), expected, rtol=1e-5, atol=1e-5)


def test_tiles_equal_the_whole_image_after_training_changes_the_weights() -> None:
    torch.manual_seed(0)
    net = PhysicsReconNet((2, 2), features=6, blocks=1)
    for p in net.parameters():
        p.data.normal_(0, 0.1)
    raw = SplitterSensor("D")(_scene(1, 60))
    kernels = pattern_pixel_kernels(patterns.get("D"))
    with torch.no_grad():
        whole = net(raw, 10.0, kernels)
    method = NetworkReconstructor(
        net, SplitterSensor("D").to_pattern("D"), "net", tile=40, precision="fp32"
    )
    torch.testing.assert_close(method.reconstruct(raw, 10.0), whole, rtol=1e-5, atol=1e-5)


def test_gradients_reach_the_learned_kernels_through_the_estimate() -> None:
    sensor = LearnableSplitterSensor("D", init="support")
    net = PhysicsReconNet(sensor.period, features=4, blocks=1)
    system = ImagingSystem(sensor, net)
    noise = GaussianNoise((0.0, 20.0), seed=1)
    rgb = _scene(2, 24)
    loss = ((system(rgb, noise) - rgb) ** 2).mean()
    loss.backward()
    # The trunk's tail is zero at the start, so this gradient flows only through the LMMSE.
    assert sensor.logits.grad is not None
    assert float(sensor.logits.grad.abs().sum()) > 0


def test_per_image_sigmas_equal_one_call_per_image() -> None:
    net = PhysicsReconNet((2, 2), features=4, blocks=1)
    for p in net.parameters():
        p.data.normal_(0, 0.1)
    raw = SplitterSensor("D")(_scene(2, 24))
    k = pattern_pixel_kernels(patterns.get("D"))
    sig = torch.tensor([3.0, 17.0])
    with torch.no_grad():
        both = net(raw, sig, k)
        one = torch.cat([net(raw[i : i + 1], float(sig[i]), k) for i in range(2)])
    torch.testing.assert_close(both, one, rtol=1e-5, atol=1e-5)


def test_config_round_trip_and_clear_errors() -> None:
    net = PhysicsReconNet((1, 3), features=4, blocks=2, radius=3)
    again = build_network(net.config())
    assert isinstance(again, PhysicsReconNet) and again.radius == 3
    again.load_state_dict(net.state_dict())
    with pytest.raises(ValueError, match="noise level"):
        net(torch.zeros(1, 1, 9, 9))
    with pytest.raises(ValueError, match="period"):
        net(torch.zeros(1, 1, 9, 9), 0.0, pattern_pixel_kernels(patterns.get("D")))
    with pytest.raises(ValueError, match="unknown network config"):
        build_network({"arch": "packed", "period": [2, 2], "radius": 3})


def _universal_scene(n: int = 2, h: int = 37, w: int = 43, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, h + 4, w + 4, generator=g)
    return torch.nn.functional.avg_pool2d(x, 5, stride=1)


def _trained_like(net: torch.nn.Module, seed: int = 0) -> torch.nn.Module:
    """Random weights everywhere (the zero-initialised tail included), as after training."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(0.05 * torch.randn(p.shape, generator=g))
    return net


@pytest.mark.parametrize("seed", range(4))
def test_untrained_universal_network_is_the_lmmse_of_any_pattern(seed: int) -> None:
    pattern = random_pattern(np.random.default_rng(100 + seed))
    raw = SplitterSensor(pattern)(_universal_scene(seed=seed)) + 0.02 * torch.randn(2, 1, 37, 43)
    net = UniversalReconNet(features=8, blocks=1)
    out = net(raw, 5.0, pattern_pixel_kernels(pattern))
    # The tiled LMMSE reconstructor applies the closed-form filters on its own code path.
    expected = closed_form_lmmse(pattern).reconstruct(raw, 5.0)
    torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-5)


def test_same_output_for_an_equivalent_layout() -> None:
    """Pattern D written with a 4x4 period (its 2x2 period repeated) is the same sensor."""
    d = patterns.get("D")
    d4 = patterns.Pattern("D4", np.tile(d.layout, (2, 2)), d.kernels)
    rgb = _universal_scene(h=38, w=41)
    raw = SplitterSensor(d)(rgb)
    torch.testing.assert_close(raw, SplitterSensor(d4)(rgb))
    net = _trained_like(UniversalReconNet(features=8, blocks=1)).eval()
    out = net(raw, 10.0, pattern_pixel_kernels(d))
    out4 = net(raw, 10.0, pattern_pixel_kernels(d4))
    torch.testing.assert_close(out, out4, rtol=1e-4, atol=1e-5)


def test_with_a_physics_trunk_it_computes_the_physics_network() -> None:
    """Started from a 2x2 physics network (the extra inputs weighted 0) it is that network."""
    physics = _trained_like(PhysicsReconNet((2, 2), features=8, blocks=1), seed=1).eval()
    universal = UniversalReconNet(features=8, blocks=1).eval()
    universal.load_physics_trunk(physics.state_dict())
    raw = SplitterSensor("A")(_universal_scene(h=36, w=40))
    k = pattern_pixel_kernels(patterns.get("A"))
    torch.testing.assert_close(universal(raw, 7.0, k), physics(raw, 7.0, k), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="2x2-period physics"):
        UniversalReconNet(features=8, blocks=1).load_physics_trunk(
            PhysicsReconNet((1, 3), features=8, blocks=1).state_dict()
        )


@pytest.mark.parametrize("size", [(33, 35), (64, 61), (2, 3)])
def test_tiles_equal_the_whole_image_for_any_period_and_size(size: tuple[int, int]) -> None:
    pattern = random_pattern(np.random.default_rng(5), max_period=4)
    while pattern.period[1] % 2 == 0:  # a period the 2x2 cells do not divide
        pattern = random_pattern(np.random.default_rng(int(pattern.kernels.sum() * 1e6)))
    net = _trained_like(UniversalReconNet(features=6, blocks=1)).eval()
    raw = SplitterSensor(pattern)(_universal_scene(1, *size))
    whole = NetworkReconstructor(net, pattern, "u", tile=None, precision="fp32")
    tiled = NetworkReconstructor(net, pattern, "u", tile=net.receptive_radius * 2 + 12)
    tiled.precision = "fp32"
    expected = whole.reconstruct(raw, 3.0)
    assert expected.shape == (1, 3, *size)
    torch.testing.assert_close(tiled.reconstruct(raw, 3.0), expected, rtol=1e-4, atol=1e-5)


def test_photon_noise_levels_are_accepted() -> None:
    pattern = patterns.get("E")
    raw = SplitterSensor(pattern)(_universal_scene())
    net = UniversalReconNet(features=8, blocks=1)
    exposures = [Exposure(30.0, read_noise=2.0), Exposure(300.0, read_noise=2.0)]
    out = net(raw, exposures, pattern_pixel_kernels(pattern))
    expected = torch.cat(
        [closed_form_lmmse(pattern).reconstruct(raw[i : i + 1], e) for i, e in enumerate(exposures)]
    )
    torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-5)


def test_gradients_reach_the_kernels() -> None:
    """Through the LMMSE estimate, the residual and the kernel encoder."""
    pattern = patterns.get("A")
    net = _trained_like(UniversalReconNet(features=8, blocks=1))
    rgb = _universal_scene()
    kernels = pattern_pixel_kernels(pattern).clone().requires_grad_(True)
    raw = SplitterSensor(pattern)(rgb)
    loss = (net(raw, 4.0, kernels) - rgb).square().mean()
    loss.backward()
    assert kernels.grad is not None and kernels.grad.abs().sum() > 0
    # And the encoder's path on its own.
    k2 = pattern_pixel_kernels(pattern).clone().requires_grad_(True)
    net.kernel_features(k2).sum().backward()
    assert k2.grad.abs().sum() > 0


def test_bad_kernels_are_refused() -> None:
    net = UniversalReconNet(features=4, blocks=0)
    raw = torch.rand(1, 1, 8, 8)
    with pytest.raises(ValueError, match="up to 5x5"):
        net(raw, 0.0, torch.rand(2, 2, 3, 7, 7) / 50)
    with pytest.raises(ValueError, match="noise level"):
        net(raw)


def test_universal_config_round_trip() -> None:
    net = UniversalReconNet(features=8, blocks=2, embed=4)
    again = build_network(net.config())
    assert again.config() == net.config()
    assert isinstance(again, UniversalReconNet)
    with pytest.raises(ValueError, match="unknown network config"):
        build_network({**net.config(), "colours": 4})
