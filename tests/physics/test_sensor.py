"""The image-formation model against the paper's literal algorithm, hand-checked scenes, input
validation, the learnable sensor's parameterisation and the switching sensor.

The operator checks that every sensor class shares (adjointness, gradcheck, state-dict round
trip, dtype and device moves, functional form against module) are in
``test_sensor_battery.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from naive_reference import loop_splitter_forward, naive_splitter_forward

from splitcam import patterns
from splitcam.patterns import PatternError
from splitcam.physics.sensor import (
    LearnableSplitterSensor,
    SplitterSensor,
    SwitchingSensor,
    pixel_gather,
    pixel_kernels,
    splitter_forward,
)

NAMES = patterns.names()


SIZES = [(7, 5), (1, 1), (2, 3), (8, 12), (9, 10)]


def _kernels(name: str, dtype=torch.float64) -> tuple[torch.Tensor, np.ndarray]:
    p = patterns.get(name)
    return torch.tensor(p.kernels, dtype=dtype), p.layout


def _gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("size", SIZES)
def test_eq1_equals_naive_reference_and_eq2(name, size):
    w, layout = _kernels(name)
    f = torch.rand(2, 3, *size, generator=_gen(), dtype=torch.float64)
    fast = splitter_forward(f, w, layout)
    assert fast.shape == (2, 1, *size)
    torch.testing.assert_close(fast, naive_splitter_forward(f, w, layout), rtol=0, atol=1e-6)
    torch.testing.assert_close(pixel_gather(f, w, layout), fast, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["A", "C", "D"])
def test_eq1_equals_pixel_loop(name):
    w, layout = _kernels(name)
    f = torch.rand(1, 3, 6, 7, generator=_gen(1), dtype=torch.float64)
    expected = loop_splitter_forward(f, w, layout.tolist())
    torch.testing.assert_close(splitter_forward(f, w, layout), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_light_conservation(name):
    """With no light near the border, the raw total is the light times the efficiency."""
    p = patterns.get(name)
    w, layout = _kernels(name)
    f = torch.zeros(1, 3, 16, 18, dtype=torch.float64)
    f[:, :, 3:-3, 3:-3] = torch.rand(1, 3, 10, 12, generator=_gen(6), dtype=torch.float64)
    raw = splitter_forward(f, w, layout)
    # Efficiency of every pixel: the kernel sum of its splitter, per colour (independent of Eq. 1).
    sums = p.kernels.sum(axis=(2, 3))  # (S, 3)
    ph, pw = p.period
    site = np.array([[p.layout[y % ph, x % pw] for x in range(18)] for y in range(16)])
    eff = torch.tensor(sums[site].transpose(2, 0, 1))  # (3, H, W)
    expected = (f[0] * eff).sum()
    torch.testing.assert_close(raw.sum(), expected, rtol=1e-12, atol=0)
    if not p.absorbs_light:
        torch.testing.assert_close(raw.sum(), f.sum(), rtol=1e-12, atol=0)


@pytest.mark.parametrize("name", NAMES)
def test_shift_by_one_period_shifts_raw(name):
    w, layout = _kernels(name)
    ph, pw = layout.shape
    f = torch.zeros(1, 3, 14, 15, dtype=torch.float64)
    f[:, :, 3:8, 3:9] = torch.rand(1, 3, 5, 6, generator=_gen(7), dtype=torch.float64)
    shifted = torch.roll(f, shifts=(ph, pw), dims=(2, 3))
    expected = torch.roll(splitter_forward(f, w, layout), shifts=(ph, pw), dims=(2, 3))
    torch.testing.assert_close(splitter_forward(shifted, w, layout), expected, rtol=0, atol=1e-12)


def test_golden_pattern_a_white_scene():
    """Hand-checked: a white scene gives 4 at interior R and B pixels, less at the border."""
    raw = SplitterSensor("A")(torch.ones(1, 3, 4, 4, dtype=torch.float64))[0, 0]
    assert raw[2, 2].item() == pytest.approx(4.0)  # R site: 1 + 4 * 0.5 + 4 * 0.25
    assert raw[1, 1].item() == pytest.approx(4.0)  # B site, likewise
    assert raw[0, 0].item() == pytest.approx(2.25)  # corner R: 1 + 0.5 + 0.5 + 0.25
    assert raw[0, 1].item() == pytest.approx(1.75)  # edge G: 1 + 3 * 0.25 (one neighbour outside)
    assert raw[1, 2].item() == pytest.approx(2.0)  # interior G: 1 + 4 * 0.25
    single = torch.zeros(1, 3, 4, 4, dtype=torch.float64)
    single[0, 0, 1, 1] = 1.0  # red light on the B site goes to its four diagonal R pixels
    expected = torch.zeros(4, 4, dtype=torch.float64)
    expected[0, 0] = expected[0, 2] = expected[2, 0] = expected[2, 2] = 0.25
    torch.testing.assert_close(SplitterSensor("A")(single)[0, 0], expected)


def test_golden_pattern_d_colour_scene():
    """Hand-checked: uniform (R, G, B) = (0.2, 0.4, 0.8) on a 2x4 sensor behind pattern D."""
    f = torch.tensor([0.2, 0.4, 0.8], dtype=torch.float64).view(1, 3, 1, 1).expand(1, 3, 2, 4)
    expected = torch.tensor(
        [
            [1.5, 1.2, 1.6, 1.2],  # W+R: 1.4 + red halves from the deflectors; W-R: G + B
            [0.6, 2.2, 0.6, 1.8],
        ],  # W-B: R + G; W+B: 1.4 + blue halves (one lost at the edge)
        dtype=torch.float64,
    )
    torch.testing.assert_close(SplitterSensor("D")(f)[0, 0], expected)


def test_bayer_is_the_rggb_mosaic():
    f = torch.rand(1, 3, 6, 8, generator=_gen(10), dtype=torch.float64)
    raw = SplitterSensor("bayer")(f)[0, 0]
    mosaic = torch.empty(6, 8, dtype=torch.float64)
    mosaic[0::2, 0::2] = f[0, 0, 0::2, 0::2]
    mosaic[0::2, 1::2] = f[0, 1, 0::2, 1::2]
    mosaic[1::2, 0::2] = f[0, 1, 1::2, 0::2]
    mosaic[1::2, 1::2] = f[0, 2, 1::2, 1::2]
    assert torch.equal(raw, mosaic)


def test_pixel_kernels_describe_what_each_pixel_sees():
    """Pattern D: the W+R pixel sees all its own light plus half the red of each neighbour."""
    k = SplitterSensor("D").pixel_kernels()
    assert k.shape == (2, 2, 3, 1, 3)
    torch.testing.assert_close(
        k[0, 0].double(),
        torch.tensor([[[0.5, 1, 0.5]], [[0, 1, 0]], [[0, 1, 0]]], dtype=torch.float64),
    )
    w, layout = _kernels("A")
    # Per colour, the light collected by the four phases of a period equals the light sent.
    total = pixel_kernels(w, layout).sum(dim=(0, 1, 3, 4))
    torch.testing.assert_close(total, torch.full((3,), 4.0, dtype=torch.float64))


@pytest.mark.parametrize(
    "bad, message",
    [
        (
            torch.rand(2, 4, 8, 8),
            r"expected an RGB image of shape \(N, 3, H, W\), got \(2, 4, 8, 8\)",
        ),
        (torch.rand(3, 8, 8), r"expected an RGB image of shape \(N, 3, H, W\), got \(3, 8, 8\)"),
        (torch.rand(1, 3, 0, 8), r"expected an RGB image with N, H, W >= 1"),
    ],
)
def test_bad_image_shape(bad, message):
    with pytest.raises(ValueError, match=message):
        SplitterSensor("A")(bad)


def test_bad_image_dtype_and_type():
    with pytest.raises(TypeError, match="expected an RGB image with a floating dtype.*torch.int64"):
        SplitterSensor("A")(torch.ones(1, 3, 4, 4, dtype=torch.int64))
    with pytest.raises(TypeError, match="expected an RGB image as a torch.Tensor, got ndarray"):
        SplitterSensor("A")(np.ones((1, 3, 4, 4)))
    with pytest.raises(ValueError, match=r"expected a raw image of shape \(N, 1, H, W\), got"):
        SplitterSensor("A").adjoint(torch.ones(1, 3, 4, 4))


def test_learned_kernels_are_valid_and_support_init_matches_the_authors():
    sensor = LearnableSplitterSensor("D", init="support")
    w = sensor.weights().detach()
    assert torch.all(w >= 0)
    torch.testing.assert_close(w.sum(dim=(2, 3)), torch.ones(4, 3))
    support = torch.tensor(patterns.get("D").kernels) > 0
    expected = torch.where(support, 5.0, 0.0).float()
    assert torch.equal(sensor.logits.detach(), expected)
    random = LearnableSplitterSensor("A", init="random", generator=_gen(14)).weights().detach()
    assert torch.all(random > 0)
    torch.testing.assert_close(random.sum(dim=(2, 3)), torch.ones(4, 3))


def test_exact_init_reproduces_the_pattern():
    sensor = LearnableSplitterSensor("A", init="exact")
    torch.testing.assert_close(
        sensor.weights().double(), torch.tensor(patterns.get("A").kernels), rtol=0, atol=1e-4
    )


def test_gradient_reaches_the_logits():
    sensor = LearnableSplitterSensor("A")
    f = torch.rand(2, 3, 8, 8, generator=_gen(15))
    (sensor(f) ** 2).sum().backward()
    assert sensor.logits.grad is not None and sensor.logits.grad.abs().sum() > 0


@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_learned_pattern_exports_and_reloads(tmp_path, suffix):
    sensor = LearnableSplitterSensor("A", init="random", generator=_gen(16))
    path = patterns.save(sensor.to_pattern("mine"), tmp_path / f"mine{suffix}")
    fixed = SplitterSensor(patterns.get(str(path)))
    assert fixed.to_pattern().provenance == "learned"
    f = torch.rand(2, 3, 9, 8, generator=_gen(17), dtype=torch.float64)
    torch.testing.assert_close(fixed(f), sensor.double()(f), rtol=0, atol=1e-6)


def test_learning_a_filter_is_refused():
    with pytest.raises(PatternError, match="'bayer' absorbs light.*softmax.*sums to 1"):
        LearnableSplitterSensor("bayer")
    with pytest.raises(ValueError, match="expected init to be one of support, exact, random"):
        LearnableSplitterSensor("A", init="zeros")


def _universal_scene(n: int = 2, h: int = 37, w: int = 43, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, h + 4, w + 4, generator=g)
    return torch.nn.functional.avg_pool2d(x, 5, stride=1)


def test_switching_sensor_changes_pattern_without_saving_it() -> None:
    sensor = SwitchingSensor("D")
    rgb = _universal_scene()
    for name in ("A", "E", "bayer"):
        sensor.set_pattern(patterns.get(name))
        torch.testing.assert_close(sensor(rgb), SplitterSensor(name)(rgb))
        assert sensor.period == patterns.get(name).period
    assert sensor.state_dict() == {}
