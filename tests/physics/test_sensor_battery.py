"""One battery of operator checks, run on every sensor class the package has.

Each sensor (fixed on every library pattern, learnable, switching, metasurface-backed) is checked
against a computation that does not go through it: the paper's literal Eq. 1
(:mod:`naive_reference`) with kernels computed here from the pattern or the module's parameters
(a softmax, a sigmoid and the optics), autograd's vector-Jacobian product, finite differences, and
the pattern whose state it loaded. The checks:

- float64 adjointness ``<A x, y> == <x, A^T y>`` and ``A^T`` equal to the VJP of Eq. 1;
- ``gradcheck`` in float64 in the input and in the tensor the kernels come from;
- ``state_dict`` round trip into a sensor built for another pattern: same outputs, and
  ``to_pattern()`` / ``repr`` report the loaded kernels and layout;
- ``.double()``, ``.float()``, ``.to("cpu")`` and, where there is one, a CUDA device;
- the functional forms (:func:`splitter_forward`, :func:`pixel_gather`, :func:`splitter_adjoint`,
  :func:`pixel_kernels`, :func:`simulate`) equal the module's methods."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from naive_reference import naive_splitter_forward
from torch.func import functional_call

from splitcam import patterns
from splitcam.patterns import Pattern
from splitcam.physics import simulate
from splitcam.physics.optics import MetasurfaceSensor, Optics, kernels_of, pattern_of
from splitcam.physics.sensor import (
    LearnableSplitterSensor,
    SplitterSensor,
    SwitchingSensor,
    pixel_gather,
    pixel_kernels,
    splitter_adjoint,
    splitter_forward,
)

SIZES = [(7, 5), (1, 1), (8, 12)]


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _derived(pattern: Pattern) -> Pattern:
    """Another pattern of the same shapes: layout rolled by a column, splitters and taps
    permuted (sums, hence validity and light conservation, unchanged)."""
    layout = np.roll(pattern.layout, 1, axis=1)
    if np.array_equal(layout, pattern.layout):
        layout = np.roll(pattern.layout, 1, axis=0)
    kernels = np.roll(pattern.kernels, 1, axis=0)[:, :, ::-1, ::-1]
    return Pattern(f"{pattern.name}-other", layout, np.ascontiguousarray(kernels))


def _softmax_taps(z: torch.Tensor) -> torch.Tensor:
    """Eq. 5 computed here: each (splitter, colour) kernel a softmax over its taps."""
    e = torch.exp(z.double() - z.double().amax(dim=(2, 3), keepdim=True))
    return e / e.sum(dim=(2, 3), keepdim=True)


class Fixed:
    """:class:`SplitterSensor` on a library pattern; the round trip loads it into a sensor
    built for ``other``."""

    param = "kernels"
    #: How closely ``to_pattern()`` matches :meth:`expected`.
    atol = 0.0

    def __init__(self, name: str, other: Pattern | None = None) -> None:
        self.pattern = patterns.get(name)
        self.other = other if other is not None else _derived(self.pattern)
        self.id = f"fixed-{name}"

    def make(self, which: int = 0) -> SplitterSensor:
        return SplitterSensor(self.pattern if which == 0 else self.other)

    def expected(self, sensor) -> Pattern:
        return self.pattern


class Learnable(Fixed):
    """:class:`LearnableSplitterSensor` from random logits; the other is built for ``other``."""

    param = "logits"
    atol = 1e-12

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.id = f"learnable-{name}"

    def make(self, which: int = 0) -> SplitterSensor:
        start = self.pattern if which == 0 else self.other
        return LearnableSplitterSensor(start, init="random", generator=_gen(20 + which))

    def expected(self, sensor) -> Pattern:
        return Pattern("x", self.pattern.layout, _softmax_taps(sensor.logits.detach()).numpy())


class Switching(Fixed):
    """:class:`SwitchingSensor` built for pattern D, then switched to ``name``."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.id = f"switching-{name}"

    def make(self, which: int = 0) -> SplitterSensor:
        sensor = SwitchingSensor("D")
        sensor.set_pattern(self.pattern if which == 0 else self.other)
        return sensor


#: Small optics (3 wavelengths, 4 samples per pixel): the kernels in milliseconds.
SMALL_OPTICS = Optics(
    pitch=0.5, samples=4, distance=1.0, wavelengths=[450.0, 550.0, 650.0], guard=1
)


class Metasurface:
    """:class:`MetasurfaceSensor` on a random height map; the other has another height map."""

    param = "height_logits"
    #: The sensor takes the sigmoid of its float32 logits in float32.
    atol = 1e-6

    def __init__(self, period: tuple[int, int]) -> None:
        self.period = period
        self.id = f"metasurface-{period[0]}x{period[1]}"

    def make(self, which: int = 0) -> SplitterSensor:
        q, top = SMALL_OPTICS.samples, SMALL_OPTICS.max_height
        shape = (self.period[0] * q, self.period[1] * q)
        unit = torch.rand(shape, generator=_gen(30 + which), dtype=torch.float64)
        height = (0.1 + 0.8 * unit) * top  # inside (0, h_max): the sigmoid's range
        return MetasurfaceSensor(height, self.period, SMALL_OPTICS)

    def height(self, sensor) -> torch.Tensor:
        z = sensor.height_logits.detach().double()
        return SMALL_OPTICS.max_height / (1 + torch.exp(-z))

    def weights(self, sensor) -> torch.Tensor:
        return kernels_of(self.height(sensor), self.period, SMALL_OPTICS)

    def expected(self, sensor) -> Pattern:
        return pattern_of(self.height(sensor), self.period, SMALL_OPTICS)


def _weights(case, sensor) -> torch.Tensor:
    """The kernels ``sensor`` should apply, float64, computed without the sensor's methods."""
    if isinstance(case, Metasurface):
        return case.weights(sensor)
    if isinstance(case, Learnable):
        return _softmax_taps(sensor.logits.detach())
    return torch.tensor(case.pattern.kernels, dtype=torch.float64)


def _layout(case) -> np.ndarray:
    if isinstance(case, Metasurface):
        return np.arange(case.period[0] * case.period[1]).reshape(case.period)
    return case.pattern.layout


CASES = [
    *(Fixed(name) for name in patterns.names() if name not in ("A", "rgbw")),
    Fixed("A", patterns.get("B")),
    Fixed("rgbw", patterns.get("quad")),
    Learnable("A"),
    Learnable("C"),
    Learnable("D"),
    Switching("C"),
    Switching("rgbw"),
    Metasurface((2, 2)),
    Metasurface((1, 3)),
]


IDS = [case.id for case in CASES]


battery = pytest.mark.parametrize("case", CASES, ids=IDS)


def test_the_battery_covers_every_sensor_class_and_library_pattern():
    kinds = {type(case.make()) for case in CASES}
    assert kinds == {SplitterSensor, LearnableSplitterSensor, SwitchingSensor, MetasurfaceSensor}
    fixed = {case.pattern.name for case in CASES if type(case) is Fixed}
    assert fixed == set(patterns.names())
    periods = {case.make().period for case in CASES}
    assert {(1, 3), (2, 2), (4, 4)} <= periods


@battery
def test_forward_is_eq1_and_adjoint_is_its_transpose_float64(case):
    sensor = case.make().double()
    w, layout = _weights(case, sensor), _layout(case)
    for k, size in enumerate(SIZES):
        x = torch.rand(2, 3, *size, generator=_gen(k), dtype=torch.float64, requires_grad=True)
        y = torch.randn(2, 1, *size, generator=_gen(10 + k), dtype=torch.float64)
        reference = naive_splitter_forward(x, w, layout)
        ax = sensor(x)
        torch.testing.assert_close(ax, reference, rtol=0, atol=1e-12)
        aty = sensor.adjoint(y)
        lhs, rhs = float((ax * y).sum().detach()), float((x * aty).sum().detach())
        assert abs(lhs - rhs) <= 1e-12 * max(abs(lhs), abs(rhs), 1.0)
        (vjp,) = torch.autograd.grad(reference, x, y)
        torch.testing.assert_close(aty, vjp, rtol=0, atol=1e-12)


class _Method(torch.nn.Module):
    """``sensor.<method>`` as a module's forward, so that :func:`functional_call` can swap the
    tensor the kernels come from for one that requires a gradient."""

    def __init__(self, sensor: torch.nn.Module, method: str) -> None:
        super().__init__()
        self.sensor, self.method = sensor, method

    def forward(self, inp: torch.Tensor) -> torch.Tensor:
        return getattr(self.sensor, self.method)(inp)


@battery
def test_gradcheck_in_the_input_and_the_kernels(case):
    sensor = case.make().double()
    ph, pw = sensor.period
    x = torch.rand(1, 3, ph + 3, pw + 2, generator=_gen(1), dtype=torch.float64)
    y = torch.rand(1, 1, ph + 3, pw + 2, generator=_gen(2), dtype=torch.float64)
    source = {**dict(sensor.named_buffers()), **dict(sensor.named_parameters())}[case.param]
    t = source.detach().clone().requires_grad_(True)
    for method, inp in (("forward", x), ("gather", x), ("adjoint", y)):
        module = _Method(sensor, method)

        def call(a, b, module=module):
            return functional_call(module, {f"sensor.{case.param}": b}, (a,))

        # fast_mode: the Jacobian along random directions, as strict and much faster.
        inp = inp.clone().requires_grad_(True)
        assert torch.autograd.gradcheck(call, (inp, t), fast_mode=True), method


@battery
def test_state_dict_round_trip_into_a_sensor_of_another_pattern(case):
    """The loaded sensor computes and reports what it loaded, not what it was built with."""
    src, dst = case.make(0), case.make(1)
    before = dst.to_pattern()
    assert not before.equals(case.expected(src))
    x = torch.rand(2, 3, 9, 8, generator=_gen(3), dtype=torch.float64)
    state = src.state_dict()
    dst.load_state_dict(state)
    if isinstance(case, Switching):
        # A switching sensor saves no pattern: loading keeps its own; set_pattern switches.
        assert len(state) == 0
        assert dst.to_pattern().equals(case.other)
        dst.set_pattern(case.pattern)
    torch.testing.assert_close(dst(x), src(x), rtol=0, atol=0)
    torch.testing.assert_close(dst.gather(x), src(x), rtol=0, atol=1e-12)
    held = dst.to_pattern()
    assert held.equals(case.expected(src), atol=case.atol)
    assert held.period == dst.period == case.expected(src).period
    assert dst.to_pattern("mine").name == "mine"
    assert dst.to_pattern("mine").equals(held)
    if type(case) is Fixed:
        assert held.name == f"{case.other.name}-loaded" and held.provenance == "loaded"
        assert f"pattern='{case.other.name}-loaded'" in repr(dst)
        # loading the state of its own pattern back: the built-with pattern again, by name
        dst.load_state_dict(case.make(1).state_dict())
        assert dst.to_pattern().name == case.other.name
        assert dst.to_pattern().equals(case.other)
        assert f"pattern='{case.other.name}'" in repr(dst)
    if isinstance(case, Switching):
        assert held.name == case.pattern.name
        assert f"pattern='{case.pattern.name}'" in repr(dst)


@pytest.mark.parametrize("name", ["A", "rgbw", "C"])
def test_a_fixed_sensor_reports_its_pattern_by_name(name):
    sensor = SplitterSensor(name)
    assert sensor.to_pattern().name == name
    assert sensor.to_pattern().equals(patterns.get(name))
    assert sensor.to_pattern().provenance == patterns.get(name).provenance
    assert sensor.to_pattern("mine").name == "mine"
    assert repr(sensor) == f"SplitterSensor(pattern='{name}', period={patterns.get(name).period})"
    with torch.no_grad():
        sensor.kernels.mul_(0.5)
    assert sensor.to_pattern().name == f"{name}-loaded"
    np.testing.assert_array_equal(sensor.to_pattern().kernels, patterns.get(name).kernels * 0.5)


@battery
def test_dtype_and_device_moves(case):
    sensor = case.make()
    expected = case.expected(sensor)
    x = torch.rand(3, 3, 11, 13, generator=_gen(4), dtype=torch.float64)
    reference = naive_splitter_forward(x, _weights(case, sensor), _layout(case))
    assert sensor.to("cpu") is sensor
    for dtype in (torch.float32, torch.float64):
        raw = sensor(x.to(dtype))
        assert raw.dtype == dtype and raw.shape == (3, 1, 11, 13)
        assert sensor.adjoint(raw).dtype == dtype and sensor.gather(x.to(dtype)).dtype == dtype
        torch.testing.assert_close(raw[1:2], sensor(x[1:2].to(dtype)))
    double = sensor.double()
    assert all(t.dtype == torch.float64 for t in double.parameters())
    assert double.weights().dtype == torch.float64
    torch.testing.assert_close(double(x), reference, rtol=0, atol=1e-12)
    # a float32 round trip rounds the kernels but still holds the same pattern
    sensor.float().double()
    assert sensor.to_pattern().equals(expected, atol=1e-6)
    if type(case) is Fixed:
        assert sensor.to_pattern().name == case.pattern.name


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
@battery
def test_cuda_move(case):
    sensor = case.make().double()
    x = torch.rand(2, 3, 9, 10, generator=_gen(5), dtype=torch.float64)
    y = torch.randn(2, 1, 9, 10, generator=_gen(6), dtype=torch.float64)
    cpu = (sensor(x), sensor.gather(x), sensor.adjoint(y), sensor.to_pattern())
    sensor.to("cuda")
    gpu = (sensor(x.cuda()), sensor.gather(x.cuda()), sensor.adjoint(y.cuda()))
    for a, b in zip(cpu[:3], gpu, strict=True):
        assert b.device.type == "cuda"
        torch.testing.assert_close(b.cpu(), a, rtol=0, atol=1e-10)
    assert sensor.to_pattern().equals(cpu[3], atol=1e-9)
    assert sensor.to_pattern().name == cpu[3].name


@battery
def test_functional_forms_equal_the_module(case):
    sensor = case.make().double()
    w = sensor.weights()
    x = torch.rand(2, 3, 10, 9, generator=_gen(7), dtype=torch.float64)
    y = torch.randn(2, 1, 10, 9, generator=_gen(8), dtype=torch.float64)
    for layout in (sensor.layout, _layout(case)):
        assert torch.equal(splitter_forward(x, w, layout), sensor(x))
        assert torch.equal(pixel_gather(x, w, layout), sensor.gather(x))
        assert torch.equal(splitter_adjoint(y, w, layout), sensor.adjoint(y))
        assert torch.equal(pixel_kernels(w, layout), sensor.pixel_kernels())
    # simulate, in strips of one period (overlapping by the kernels' reach), noise-free
    strip = sensor.period[0]
    raw = simulate(sensor, x.float(), "scene", 0.0, strip=strip)
    with torch.no_grad():
        torch.testing.assert_close(raw, sensor(x.float().double()).float(), rtol=0, atol=0)
