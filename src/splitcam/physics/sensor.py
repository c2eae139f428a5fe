"""The differentiable image-formation model of a splitter sensor (paper Eq. 1, Eq. 2, adjoint).

The maths lives in pure functions (:func:`splitter_forward`, :func:`pixel_gather`,
:func:`splitter_adjoint`, :func:`pixel_kernels`); :class:`SplitterSensor` is the ``nn.Module``
shell that holds a pattern, and :class:`LearnableSplitterSensor` adds the softmax-parameterised
kernels of the joint optimisation (paper Eq. 5).

Why not the paper's literal algorithm (one masked full-size image and one transposed convolution
per splitter)? It touches ``S`` full-size images and runs ``S`` single-output transposed
convolutions, most of whose multiplications are by the zeros of the mask. Because the layout is
periodic, every sensor pixel of phase ``(i', j')`` collects light through the same taps from the
same phases of its neighbours, so Eq. 1 is one *strided* convolution: a ``conv2d`` from the 3
colours to ``Ph * Pw`` output phases with stride ``(Ph, Pw)`` and a kernel of size
``(Ph + kh - 1, Pw + kw - 1)``, followed by a depth-to-space rearrangement of the phases. The image
is read once, in place, by one optimised library call; the adjoint is the matching
``conv_transpose2d``. The strided kernel is gathered from the splitter kernels by an index table,
so gradients reach the kernels through plain indexing.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_image
from ..patterns import Pattern, PatternError, check_pattern, get
from .periodic import period_shuffle, period_unshuffle, phase_conv

__all__ = [
    "LearnableSplitterSensor",
    "SwitchingSensor",
    "SplitterSensor",
    "pattern_pixel_kernels",
    "pixel_gather",
    "pixel_kernels",
    "splitter_adjoint",
    "splitter_forward",
]


Layout = torch.Tensor | np.ndarray | tuple[tuple[int, ...], ...]

#: Kernels within this of the pattern a sensor was built with count as that pattern in
#: :meth:`SplitterSensor.to_pattern`: the float32 rounding of weights of at most 1 is below it.
HELD_ATOL = 1e-7


def _tensor(
    array: np.ndarray, dtype: torch.dtype, device: torch.device | None = None
) -> torch.Tensor:
    """A pattern's array as a new tensor; ``np.array`` copies it first, so any view (a flipped
    or strided one included) converts."""
    return torch.tensor(np.array(array), dtype=dtype, device=device)


def _layout_key(layout: Layout) -> tuple[tuple[int, ...], ...]:
    """The layout as a hashable tuple (the key of the index-table caches)."""
    if isinstance(layout, tuple):
        return layout
    arr = layout.detach().cpu().numpy() if isinstance(layout, torch.Tensor) else layout
    return tuple(tuple(int(v) for v in row) for row in np.asarray(arr))


@functools.lru_cache(maxsize=64)
def _strided_index(
    layout: tuple[tuple[int, ...], ...], num_splitters: int, kh: int, kw: int
) -> torch.Tensor:
    """Index table that gathers the strided kernel from the flattened splitter kernels.

    The strided kernel ``K`` has shape ``(Ph * Pw, 3, Ph + kh - 1, Pw + kw - 1)``. Output channel
    ``i' * Pw + j'`` is the sensor phase; tap ``(u, v)`` reads the scene pixel at offset
    ``(u - kh//2, v - kw//2)`` from the top-left pixel of the sensor pixel's period block. That
    pixel has phase ``((u - kh//2) mod Ph, (v - kw//2) mod Pw)``, so its splitter is fixed, and
    it reaches phase ``(i', j')`` through splitter tap ``a = i' - u + 2 * (kh//2)`` (likewise
    ``b``). Entries no tap maps to point at one extra zero slot.
    """
    lay = np.asarray(layout, dtype=np.int64)
    ph, pw = lay.shape
    rh, rw = kh // 2, kw // 2
    index = np.full((ph * pw, 3, ph + kh - 1, pw + kw - 1), num_splitters * 3 * kh * kw)
    for i2 in range(ph):
        for j2 in range(pw):
            for u in range(ph + kh - 1):
                a = i2 - u + 2 * rh
                if not 0 <= a < kh:
                    continue
                for v in range(pw + kw - 1):
                    b = j2 - v + 2 * rw
                    if not 0 <= b < kw:
                        continue
                    s = lay[(u - rh) % ph, (v - rw) % pw]
                    for c in range(3):
                        index[i2 * pw + j2, c, u, v] = ((s * 3 + c) * kh + a) * kw + b
    return torch.from_numpy(index)


def _strided_kernel(weights: torch.Tensor, layout: Layout) -> torch.Tensor:
    s, _, kh, kw = weights.shape
    index = _strided_index(_layout_key(layout), s, kh, kw)
    flat = torch.cat([weights.reshape(-1), weights.new_zeros(1)])
    return flat[index.to(weights.device)]


def _period(layout: Layout) -> tuple[int, int]:
    if isinstance(layout, tuple):
        return (len(layout), len(layout[0]))
    return (int(layout.shape[0]), int(layout.shape[1]))


def splitter_forward(rgb: torch.Tensor, weights: torch.Tensor, layout: Layout) -> torch.Tensor:
    r"""Raw image of a splitter sensor, paper Eq. 1 (noise-free).

    .. math:: g = \sum_{s} (f \downarrow_s) \star w_s

    Light of colour ``c`` arriving at ``(y, x)`` (splitter ``s = L[y mod Ph, x mod Pw]``) puts
    ``w[s, c, a, b]`` of itself on pixel ``(y + a - kh//2, x + b - kw//2)``; light leaving the
    sensor is lost. Linear in ``rgb`` and in ``weights``; differentiable in both.

    Args:
        rgb: Scene, linear values (8-bit / 255 in the paper's protocol).
        weights: Splitter kernels.
        layout: Integer grid of splitter indices.

    Shape:
        - rgb: ``(N, 3, H, W)``, any ``H, W >= 1``.
        - weights: ``(S, 3, kh, kw)``, odd ``kh, kw``.
        - layout: ``(Ph, Pw)``.
        - output: ``(N, 1, H, W)``.
    """
    check_image(rgb, 3, "an RGB image")
    ph, pw = _period(layout)
    kh, kw = weights.shape[-2:]
    h, w = rgb.shape[-2:]
    kernel = _strided_kernel(weights.to(rgb.dtype), layout)
    hp, wp = -(-h // ph) * ph, -(-w // pw) * pw
    if (hp, wp) == (h, w):
        raw = F.conv2d(rgb, kernel, stride=(ph, pw), padding=(kh // 2, kw // 2))
    else:
        # Zero rows/columns up to whole periods: they carry no light, and what lands on them
        # is cropped away, exactly like light that leaves the sensor.
        pad = (kw // 2, kw // 2 + wp - w, kh // 2, kh // 2 + hp - h)
        raw = F.conv2d(F.pad(rgb, pad), kernel, stride=(ph, pw))
    return period_shuffle(raw, (ph, pw), (h, w))


def splitter_adjoint(raw: torch.Tensor, weights: torch.Tensor, layout: Layout) -> torch.Tensor:
    r"""Exact adjoint of :func:`splitter_forward` in the image.

    .. math:: (A^T g)[c, y, x] = \sum_{a,b} w[s(y,x), c, a, b]\, g[y + a - kh//2, x + b - kw//2]

    with ``g`` zero outside the sensor.

    Shape:
        - raw: ``(N, 1, H, W)``.
        - output: ``(N, 3, H, W)``.
    """
    check_image(raw, 1, "a raw image")
    ph, pw = _period(layout)
    kh, kw = weights.shape[-2:]
    kernel = _strided_kernel(weights.to(raw.dtype), layout)
    rgb = F.conv_transpose2d(
        period_unshuffle(raw, (ph, pw)), kernel, stride=(ph, pw), padding=(kh // 2, kw // 2)
    )
    return rgb[:, :, : raw.shape[-2], : raw.shape[-1]]


@functools.lru_cache(maxsize=64)
def _pixel_kernel_index(
    layout: tuple[tuple[int, ...], ...], num_splitters: int, kh: int, kw: int
) -> torch.Tensor:
    lay = np.asarray(layout, dtype=np.int64)
    ph, pw = lay.shape
    rh, rw = kh // 2, kw // 2
    index = np.empty((ph, pw, 3, kh, kw), dtype=np.int64)
    for i in range(ph):
        for j in range(pw):
            for c in range(3):
                for a in range(kh):
                    for b in range(kw):
                        # Source pixel at offset (a - rh, b - rw) from the sensor pixel; the
                        # splitter there sends light back by tap (rh - dy, rw - dx).
                        dy, dx = a - rh, b - rw
                        s = lay[(i + dy) % ph, (j + dx) % pw]
                        index[i, j, c, a, b] = ((s * 3 + c) * kh + (rh - dy)) * kw + (rw - dx)
    return torch.from_numpy(index)


def pixel_kernels(weights: torch.Tensor, layout: Layout) -> torch.Tensor:
    """Per-pixel gather kernels ``k_p`` of paper Eq. 2, derived from the splitter kernels.

    ``k[i, j, c, a, b]`` is the fraction of colour ``c`` at scene pixel
    ``(y + a - kh//2, x + b - kw//2)`` that a sensor pixel ``(y, x)`` of phase ``(i, j)`` collects:
    what each pixel sees. ``k.sum((-1, -2))`` is the pixel's spectral response to a flat scene.

    Shape:
        - weights: ``(S, 3, kh, kw)``; layout: ``(Ph, Pw)``.
        - output: ``(Ph, Pw, 3, kh, kw)``.
    """
    s, _, kh, kw = weights.shape
    index = _pixel_kernel_index(_layout_key(layout), s, kh, kw).to(weights.device)
    return weights.reshape(-1)[index]


def pattern_pixel_kernels(pattern: Pattern) -> torch.Tensor:
    """:func:`pixel_kernels` of a :class:`Pattern`, in float64.

    Shape:
        - output: ``(Ph, Pw, 3, kh, kw)``.
    """
    pattern = check_pattern(pattern)
    weights = torch.from_numpy(np.array(pattern.kernels, dtype=np.float64))
    return pixel_kernels(weights, pattern.layout)


def pixel_gather(rgb: torch.Tensor, weights: torch.Tensor, layout: Layout) -> torch.Tensor:
    r"""Raw image by paper Eq. 2: each pixel correlates the scene with its own kernel.

    .. math:: g = \sum_{p} ((f * k_p) \downarrow_p)

    A separate code path from :func:`splitter_forward` (gather instead of scatter): convolve the
    scene with every phase's kernel, then keep, at each pixel, the response of its own phase.

    Shape:
        - rgb: ``(N, 3, H, W)``; output ``(N, 1, H, W)``.
    """
    check_image(rgb, 3, "an RGB image")
    k = pixel_kernels(weights.to(rgb.dtype), layout)
    ph, pw, c, kh, kw = k.shape
    return phase_conv(rgb, k.reshape(ph * pw, 1, c, kh, kw), (ph, pw))


class SplitterSensor(nn.Module):
    """A sensor behind a fixed splitter (or filter) pattern: ``sensor(rgb)`` is Eq. 1.

    The kernels and layout are buffers, so ``.to(device)``, ``state_dict()`` and saving work;
    computations follow the input's device and dtype. What the sensor reports
    (:meth:`to_pattern`, its ``repr``, :attr:`period`) is read from those buffers, so a sensor
    that loaded the state dict of another pattern of the same shapes reports that pattern's
    layout and kernels (see :meth:`to_pattern` for its name).

    Args:
        pattern: A :class:`~splitcam.patterns.Pattern` or a registered name / pattern file path.

    Shape:
        - forward / gather input: ``(N, 3, H, W)``; output ``(N, 1, H, W)``.
        - adjoint input: ``(N, 1, H, W)``; output ``(N, 3, H, W)``.

    >>> import torch
    >>> bayer = SplitterSensor("bayer")
    >>> bayer
    SplitterSensor(pattern='bayer', period=(2, 2))
    >>> red = torch.zeros(1, 3, 2, 2)
    >>> red[:, 0] = 1.0
    >>> bayer(red)[0, 0].tolist()  # RGGB filters: only the red pixel records red light
    [[1.0, 0.0], [0.0, 0.0]]
    >>> raw = SplitterSensor("A")(torch.ones(1, 3, 8, 8, dtype=torch.float64))
    >>> raw[0, 0, 4:6, 4:6].tolist()  # white light, routed: R and B pixels gather 4 units
    [[4.0, 2.0], [2.0, 4.0]]
    >>> float(raw[0, 0, 4:6, 4:6].sum())  # nothing lost: 4 pixels x 3 colours
    12.0
    >>> SplitterSensor("A").adjoint(raw).shape
    torch.Size([1, 3, 8, 8])
    """

    layout: torch.Tensor

    def __init__(self, pattern: Pattern | str) -> None:
        super().__init__()
        pattern = get(pattern)  # a constructor users call: names and files read here
        self._meta = pattern
        self.register_buffer("layout", _tensor(pattern.layout, torch.long))
        # The layout as a tuple, read once: converting the buffer on every call would copy it
        # to the host (a device sync on GPUs). Refreshed if a state dict replaces the buffer.
        self._layout = _layout_key(pattern.layout)
        self.register_load_state_dict_post_hook(
            lambda module, _keys: setattr(module, "_layout", _layout_key(module.layout))
        )
        self._init_kernels(pattern)

    def _init_kernels(self, pattern: Pattern) -> None:
        self.register_buffer("kernels", _tensor(pattern.kernels, torch.float64))

    @property
    def period(self) -> tuple[int, int]:
        return _period(self._layout)

    def weights(self) -> torch.Tensor:
        """The splitter kernels ``(S, 3, kh, kw)`` currently in use."""
        return self.kernels

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        return splitter_forward(rgb, self.weights(), self._layout)

    def gather(self, rgb: torch.Tensor) -> torch.Tensor:
        """Same raw image by the pixel (gather) form, Eq. 2."""
        return pixel_gather(rgb, self.weights(), self._layout)

    def adjoint(self, raw: torch.Tensor) -> torch.Tensor:
        """``A^T raw``, the exact adjoint of :meth:`forward`."""
        return splitter_adjoint(raw, self.weights(), self._layout)

    def pixel_kernels(self) -> torch.Tensor:
        """What each pixel phase sees, ``(Ph, Pw, 3, kh, kw)`` (see :func:`pixel_kernels`)."""
        return pixel_kernels(self.weights(), self._layout)

    def _held(self) -> tuple[np.ndarray, np.ndarray]:
        """The layout and kernels (float64) of the buffers, on the host."""
        layout = self.layout.detach().cpu().numpy()
        return layout, self.kernels.detach().to("cpu", torch.float64).numpy()

    def _holds_constructor_pattern(self) -> bool:
        """Whether the buffers hold the constructor's pattern (kernels to float32 precision)."""
        layout, kernels = self._held()
        built = self._meta
        return (
            layout.shape == built.layout.shape
            and bool(np.array_equal(layout, built.layout))
            and kernels.shape == built.kernels.shape
            and bool(np.allclose(kernels, built.kernels, rtol=0, atol=HELD_ATOL))
        )

    def _held_name(self) -> str:
        """The name :meth:`to_pattern` gives (without building the pattern)."""
        if self._holds_constructor_pattern():
            return self._meta.name
        return f"{self._meta.name}-loaded"

    def to_pattern(self, name: str | None = None) -> Pattern:
        """The pattern of the layout and kernels this sensor holds (renamed to ``name`` if given).

        While the buffers hold the pattern the sensor was built with (kernels equal within
        :data:`HELD_ATOL`, so a sensor cast to float32 and back still does), that pattern is
        returned, with its name, provenance and description. Otherwise (a state dict of another
        pattern was loaded, or the buffers were written) the result is a pattern of the buffers'
        layout and kernels named ``"<built-with name>-loaded"``, provenance ``"loaded"``; a state
        dict holds tensors only, so the loaded pattern's own name is not known here.

        Raises:
            PatternError: The buffers hold kernels that are no valid pattern (negative, or
                summing to more than 1).
        """
        if self._holds_constructor_pattern():
            held = self._meta
        else:
            layout, kernels = self._held()
            held = Pattern(
                name=f"{self._meta.name}-loaded",
                layout=layout,
                kernels=kernels,
                provenance="loaded",
                description=f"kernels loaded into a sensor built for pattern {self._meta.name}",
                metadata={"built_for": self._meta.name},
            )
        return held if name is None else dataclasses.replace(held, name=name)

    def extra_repr(self) -> str:
        return f"pattern={self._held_name()!r}, period={self.period}"


class LearnableSplitterSensor(SplitterSensor):
    """A splitter sensor whose kernels are learned: ``w = softmax(z)`` over the taps (Eq. 5).

    Each ``(s, c)`` kernel is a softmax over its ``kh * kw`` taps, so it is non-negative and sums
    to 1 by construction: a learned splitter can neither create nor absorb light. The layout and
    kernel size stay those of the starting pattern.

    Args:
        pattern: Starting pattern (name, path or Pattern). Colour filters (kernel sums below 1,
            such as ``bayer``) are refused: a softmax cannot represent absorbed light.
        init: ``"support"`` (the authors' choice: ``z = support_logit`` where the pattern is
            non-zero, 0 elsewhere), ``"exact"`` (``z = log(max(w, eps))``, so ``softmax(z)``
            reproduces the pattern up to ``eps``) or ``"random"`` (``z ~ N(0, 1)``, the paper's
            "Optimized-R" ablation).
        generator: Seeded generator for ``"random"``.
        support_logit: The logit on the support for ``"support"`` (5 in the paper).
        eps: Floor for ``"exact"``.
    """

    INITS = ("support", "exact", "random")

    def __init__(
        self,
        pattern: Pattern | str,
        init: str = "support",
        *,
        generator: torch.Generator | None = None,
        support_logit: float = 5.0,
        eps: float = 1e-6,
    ) -> None:
        self._init = init
        self._generator = generator
        self._support_logit = support_logit
        self._eps = eps
        super().__init__(pattern)

    def _init_kernels(self, pattern: Pattern) -> None:
        if self._init not in self.INITS:
            raise ValueError(
                f"expected init to be one of {', '.join(self.INITS)}, got {self._init!r}"
            )
        if pattern.absorbs_light:
            raise PatternError(
                f"pattern {pattern.name!r} absorbs light (some kernels sum to less than 1, as in "
                f"a colour filter), but learned kernels are a softmax that always sums to 1 "
                f"(light conserved); start from a splitter pattern such as A or D instead"
            )
        w = _tensor(pattern.kernels, torch.float64)
        if self._init == "support":
            z = torch.where(w > 0, self._support_logit, 0.0)
        elif self._init == "exact":
            z = torch.log(w.clamp_min(self._eps))
        else:
            z = torch.randn(w.shape, generator=self._generator, dtype=torch.float64)
        self.logits = nn.Parameter(z.float())

    def weights(self) -> torch.Tensor:
        z = self.logits
        return torch.softmax(z.reshape(*z.shape[:2], -1), dim=-1).reshape(z.shape)

    def to_pattern(self, name: str | None = None) -> Pattern:
        """Export the learned kernels (softmax in float64) as a fixed :class:`Pattern`.

        Layout and kernels are the module's (the ``layout`` buffer and ``softmax(logits)``, so
        after a ``load_state_dict`` those of the loaded state); the name (default
        ``"<start>-learned"``), description and metadata name the starting pattern and
        initialisation the sensor was built with.
        """
        z = self.logits.detach().double().cpu()
        w = torch.softmax(z.reshape(*z.shape[:2], -1), dim=-1).reshape(z.shape)
        base = self._meta
        return Pattern(
            name=name or f"{base.name}-learned",
            layout=self.layout.detach().cpu().numpy(),
            kernels=w.numpy(),
            provenance="learned",
            description=f"learned from pattern {base.name} ({self._init} initialisation)",
            reference="Liu & Lam, joint optimisation of splitter pattern and reconstruction",
            metadata={"start": base.name, "init": self._init},
        )

    def extra_repr(self) -> str:
        return f"start={self._meta.name!r}, init={self._init!r}, period={self.period}"


class SwitchingSensor(SplitterSensor):
    """A fixed-pattern sensor whose pattern is replaced between training steps.

    What training one network over many patterns needs (:class:`~splitcam.patterns.random.
    PatternMix`): :meth:`set_pattern` swaps the layout and kernels, whatever their period and
    kernel size. Neither is saved in a ``state_dict`` (the pattern of a step is recomputed from
    the step, not restored), so checkpoints of such a run hold only the network, and loading a
    state dict leaves the pattern as it was: :meth:`to_pattern` is the pattern last set.

    Args:
        pattern: The first pattern.
    """

    def __init__(self, pattern: Pattern | str) -> None:
        super().__init__(pattern)
        self.set_pattern(self._meta)

    def set_pattern(self, pattern: Pattern) -> None:
        """Use ``pattern`` from now on (buffers stay on the sensor's device)."""
        pattern = check_pattern(pattern)
        device = self.kernels.device
        self._meta = pattern
        self._layout = _layout_key(pattern.layout)
        layout = _tensor(pattern.layout, torch.long, device=device)
        kernels = _tensor(pattern.kernels, torch.float64, device=device)
        self.register_buffer("layout", layout, persistent=False)
        self.register_buffer("kernels", kernels, persistent=False)
