"""Test-time self-ensembles: a reconstruction averaged over the image's flips and transpositions
that the sensor itself is symmetric under, or, for a network of any pattern, over all eight.

A flip or a transposition ``g`` of the scene is a fair second look at a raw image only when the
sensor commutes with it, ``sensor(g(x)) = g(sensor(x))``: then ``g(raw)`` is exactly the raw
image a camera with the same pattern records of the scene ``g(x)``, and ``g⁻¹(method(g(raw)))``
is a second estimate of ``x`` with the same noise statistics. Whether it commutes depends on the
pattern's kernels and on where the image ends within the period (flipping a 2x2 Bayer image of
even width turns RGGB into GRBG; of odd width it stays RGGB), so :func:`symmetries` tests each of
the eight transforms on a small probe image of the same size modulo the period, by simulating
both sides (no case analysis to get wrong). :class:`SelfEnsemble` averages the method over those
transforms; with only the identity it is the method itself.

The usual test-time augmentation of image restoration flips the input regardless; for a
colour-routing sensor that would feed the network raw images no sensor of its pattern produces,
so only the exact symmetries are used here. A network told each pixel's kernels (``universal``,
model.md §16) is not bound to one pattern: ``g(raw)`` is exactly the raw image that the
flipped pattern :func:`transformed` records of ``g(x)``, so it can take all eight looks, each
told the pattern it sees (``every_look``; measured, it pays only where the network knows the
flipped patterns as well as the pattern itself).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..patterns import Pattern
from ..physics.sensor import SplitterSensor
from .base import NetworkReconstructor, Reconstructor, method_domain

__all__ = ["TRANSFORMS", "SelfEnsemble", "Transform", "symmetries", "transformed", "with_flips"]


@dataclass(frozen=True)
class Transform:
    """Transpose (rows and columns swapped) first, then flips of the last two axes."""

    transpose: bool = False
    flip_rows: bool = False
    flip_cols: bool = False

    def apply(self, x: torch.Tensor) -> torch.Tensor:
        """``g(x)`` on the last two axes of ``(..., H, W)``."""
        if self.transpose:
            x = x.transpose(-2, -1)
        dims = [d for d, on in ((-2, self.flip_rows), (-1, self.flip_cols)) if on]
        return x.flip(dims) if dims else x

    def invert(self, x: torch.Tensor) -> torch.Tensor:
        """``g⁻¹(x)``: the flips undone, then the transposition."""
        dims = [d for d, on in ((-2, self.flip_rows), (-1, self.flip_cols)) if on]
        if dims:
            x = x.flip(dims)
        return x.transpose(-2, -1) if self.transpose else x

    @property
    def label(self) -> str:
        parts = [
            n
            for n, on in (("T", self.transpose), ("V", self.flip_rows), ("H", self.flip_cols))
            if on
        ]
        return "".join(parts) or "id"


#: The eight symmetries of a rectangle's pixel grid (the dihedral group of the square), the
#: identity first.
TRANSFORMS = tuple(
    Transform(t, r, c) for t in (False, True) for r in (False, True) for c in (False, True)
)


def symmetries(pattern: Pattern, height: int, width: int) -> list[Transform]:
    """The transforms ``g`` of :data:`TRANSFORMS` that the sensor of ``pattern`` commutes with on
    images of ``height`` x ``width``: ``sensor(g(x)) = g(sensor(x))`` for every scene ``x``.

    Tested by simulating both sides on a random probe image whose sides equal ``height`` and
    ``width`` modulo the period (which is all that decides it: the phase of every pixel, and
    the zero padding at the borders, which every flip and transposition preserves), large enough
    that borders and interior are both there. The identity is always among them.

    >>> from splitcam.patterns import get
    >>> " ".join(g.label for g in symmetries(get("bayer"), 512, 768))  # RGGB: its diagonal
    'id T'
    >>> " ".join(g.label for g in symmetries(get("bayer"), 321, 481))  # odd sides: all
    'id H V VH T TH TV TVH'
    """
    ph, pw = pattern.period
    key = (pattern.period, tuple(pattern.kernel_size), height % ph, width % pw)
    kernels = torch.tensor(np.array(pattern.kernels), dtype=torch.float64)
    cached = _CACHE.get(key)
    if cached is not None and torch.equal(cached[0], kernels):
        return list(cached[1])
    kh, kw = pattern.kernel_size
    h = ph * (2 * kh + 4) + height % ph
    w = pw * (2 * kw + 4) + width % pw
    sensor = SplitterSensor(pattern).double()
    x = torch.rand(1, 3, h, w, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    found = []
    with torch.no_grad():
        base = sensor(x)
        for g in TRANSFORMS:
            lhs, rhs = sensor(g.apply(x)), g.apply(base)
            if lhs.shape == rhs.shape and torch.allclose(lhs, rhs, rtol=0, atol=1e-12):
                found.append(g)
    _CACHE[key] = (kernels, tuple(found))
    return found


_CACHE: dict[tuple, tuple[torch.Tensor, tuple[Transform, ...]]] = {}


def transformed(pattern: Pattern, g: Transform, height: int, width: int) -> Pattern:
    """The pattern whose sensor records ``g(x)`` as ``g`` of what ``pattern``'s sensor records
    of ``x``, on images of ``height`` x ``width``: ``sensor'(g(x)) = g(sensor(x))``.

    Each step moves the layout and the kernel taps alike. A transposition swaps the layout's
    axes and each kernel's; a flip of the rows reverses each kernel's rows and maps period row
    ``r`` to ``(H - 1 - r) mod Ph``, which depends on where the image ends within the period
    (``H`` the height at that step); the columns likewise. The result records what ``pattern``
    records (the same pixel kernels) exactly when ``g`` is among :func:`symmetries`.
    """
    if g == TRANSFORMS[0]:
        return pattern
    layout = np.array(pattern.layout)
    kernels = np.array(pattern.kernels)
    h, w = height, width
    if g.transpose:
        layout, kernels, h, w = layout.T, kernels.transpose(0, 1, 3, 2), w, h
    ph, pw = layout.shape
    if g.flip_rows:
        layout, kernels = layout[(h - 1 - np.arange(ph)) % ph], kernels[:, :, ::-1]
    if g.flip_cols:
        layout, kernels = layout[:, (w - 1 - np.arange(pw)) % pw], kernels[:, :, :, ::-1]
    return Pattern(
        name=f"{pattern.name}@{g.label}",
        layout=np.ascontiguousarray(layout),
        kernels=np.ascontiguousarray(kernels),
        provenance=pattern.provenance,
        description=f"{pattern.name} under the transform {g.label} of a {height}x{width} image",
        reference=pattern.reference,
    )


class SelfEnsemble:
    """``method`` averaged over the exact symmetries of its sensor (:func:`symmetries`) for the
    size of each raw image: ``mean_g g⁻¹(method(g(raw)))``. Costs one reconstruction per
    symmetry (1 to 8; 2 for Bayer, A and B on even sides); named ``<method>+flips``.

    With ``every_look``, a method that reconstructs any pattern it is told (``any_pattern``
    and ``for_pattern``, as a network of any pattern has) is averaged over all eight
    transforms, each look told its pattern: ``mean_g g⁻¹(method_{P_g}(g(raw)))`` with ``P_g``
    from :func:`transformed` (8 reconstructions). Off by default: a look is only as good as
    the network is on its pattern, and a transposed or flipped pattern it was not trained on
    costs more than the look gains (docs/results/flips/: the universal network on E loses
    1.4 dB with all eight looks, and gains on A and Bayer only as much as their exact
    symmetries give).

    The noise of ``g(raw)`` is the same noise, moved: the estimates are not independent, and
    the ensemble gains less than averaging independent looks would.
    """

    def __init__(self, method: Reconstructor, *, every_look: bool = False) -> None:
        self.method = method
        self.every_look = bool(every_look) and bool(getattr(method, "any_pattern", False))
        suffix = "all-flips" if self.every_look else "flips"
        self.name = f"{method.name}+{suffix}"
        self.pattern = method.pattern
        self.domain = method_domain(method)
        self.fingerprint = f"{getattr(method, 'fingerprint', '')}+{suffix}"
        # The retargeted methods by where the image ends within the period (all that
        # transformed() depends on): built once, not for every image of a test set.
        self._retargeted: dict[tuple[int, int], list[tuple[Transform, Reconstructor]]] = {}

    def looks(self, height: int, width: int) -> list[tuple[Transform, Reconstructor]]:
        """Each transform of an image of ``height`` x ``width`` with the method that
        reconstructs its raw image: the exact symmetries with the method itself, or, with
        ``every_look``, all eight with the method for the transformed pattern."""
        if not self.every_look:
            return [(g, self.method) for g in symmetries(self.pattern, height, width)]
        ph, pw = self.pattern.period
        key = (height % ph, width % pw)
        if key not in self._retargeted:
            retarget = self.method.for_pattern  # type: ignore[attr-defined]
            self._retargeted[key] = [
                (g, retarget(transformed(self.pattern, g, height, width)) if i else self.method)
                for i, g in enumerate(TRANSFORMS)
            ]
        return self._retargeted[key]

    def reconstruct(self, raw: torch.Tensor, sigma) -> torch.Tensor:
        """The averaged estimate ``(N, 3, H, W)`` of a raw image ``(N, 1, H, W)``."""
        looks = self.looks(*raw.shape[-2:])
        total = None
        for g, method in looks:
            out = g.invert(method.reconstruct(g.apply(raw), sigma)).float()
            total = out if total is None else total + out
        assert total is not None  # the identity is always there
        return total / len(looks)


def with_flips(methods: list, flips: str | None) -> list:
    """The networks among ``methods`` as :class:`SelfEnsemble` s when ``flips`` is ``exact``
    (their sensors' exact symmetries) or ``all`` (every look for a network of any pattern);
    other methods, and every method when ``flips`` is empty, unchanged."""
    if not flips:
        return methods
    if flips not in ("exact", "all"):
        raise ValueError(f"unknown flips {flips!r}; expected exact or all")
    every = flips == "all"
    return [
        SelfEnsemble(m, every_look=every) if isinstance(m, NetworkReconstructor) else m
        for m in methods
    ]
