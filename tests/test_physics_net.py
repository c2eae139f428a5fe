"""The physics-informed network (arch "physics"): LMMSE estimate plus a learned correction."""

from __future__ import annotations

import pytest
import torch

from splitcam.physics.noise import GaussianNoise
from splitcam.physics.sensor import LearnableSplitterSensor, SplitterSensor, pattern_pixel_kernels
from splitcam.physics.system import ImagingSystem
from splitcam.recon.base import NetworkReconstructor
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.networks import PhysicsReconNet, build_network


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
    out = net(raw, 5.0, pattern_pixel_kernels(name))
    expected = closed_form_lmmse(name).reconstruct(raw, 5.0)
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
    kernels = pattern_pixel_kernels("D")
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
    k = pattern_pixel_kernels("D")
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
        net(torch.zeros(1, 1, 9, 9), 0.0, pattern_pixel_kernels("D"))
    with pytest.raises(ValueError, match="unknown network config"):
        build_network({"arch": "packed", "period": [2, 2], "radius": 3})


def test_precision_switch(monkeypatch: pytest.MonkeyPatch) -> None:
    from splitcam.recon import base

    assert base.fast_precision("fp32", "cpu") is False
    assert base.fast_precision("bf16", "cpu") is True
    monkeypatch.setattr(base, "_cpu_has_native_bf16", lambda: True)
    assert base.fast_precision("auto", "cpu") is True
    monkeypatch.setattr(base, "_cpu_has_native_bf16", lambda: False)
    assert base.fast_precision("auto", "cpu") is False
    with pytest.raises(ValueError, match="unknown precision"):
        base.fast_precision("fp16", "cpu")


def test_batched_estimate_equals_per_image_estimates_and_their_gradients() -> None:
    """One solve and one grouped convolution for a batch of noise levels give the values and the
    kernel gradients of one call per image (float64)."""
    from splitcam.recon.closed_form import lmmse_estimate, shipped_image_statistics

    stats = shipped_image_statistics()
    raw = SplitterSensor("D")(_scene(3, 20).double())
    sig = torch.tensor([0.0, 7.0, 25.0], dtype=torch.float64)
    target = torch.rand(
        3, 3, 20, 20, generator=torch.Generator().manual_seed(5), dtype=torch.float64
    )
    grads, values = [], []
    for batched in (True, False):
        k = pattern_pixel_kernels("D").clone().requires_grad_(True)
        if batched:
            out = lmmse_estimate(raw, k, sig, stats)
        else:
            out = torch.cat(
                [lmmse_estimate(raw[i : i + 1], k, float(sig[i]), stats) for i in range(3)]
            )
        (out * target).sum().backward()
        values.append(out.detach())
        grads.append(k.grad)
    torch.testing.assert_close(values[0], values[1], rtol=0, atol=1e-12)
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-10, atol=1e-10)
