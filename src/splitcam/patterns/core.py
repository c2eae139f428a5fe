"""The :class:`Pattern` type: a splitter layout plus its kernels, validated on construction.

A pattern has a period ``(Ph, Pw)``, a ``layout`` of shape ``(Ph, Pw)`` naming the splitter used at
each position of the period, and ``kernels`` of shape ``(S, 3, kh, kw)``: light of colour ``c``
arriving where splitter ``s`` sits puts the fraction ``kernels[s, c, a, b]`` on the pixel offset by
``(a - kh // 2, b - kw // 2)`` (model.md §1). Kernel sums below 1 model absorbed light (a colour
filter); sums above 1 would create light and are refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from numbers import Integral, Real
from pathlib import PurePath
from typing import Any

import numpy as np

COLOURS = ("R", "G", "B")
#: Tolerance on a kernel sum above 1 (floating-point slack of a learned, exported pattern).
SUM_TOLERANCE = 1e-6


class PatternError(ValueError):
    """A pattern (or pattern file) is invalid; the message names the problem."""


def _nested_shape(value: Any, what: str) -> tuple[int, ...]:
    """Shape of a rectangular nested list, or a PatternError naming the ragged level."""
    if isinstance(value, np.ndarray):
        return value.shape
    if not isinstance(value, (list, tuple)):
        return ()
    if len(value) == 0:
        raise PatternError(f"{what} has an empty list")
    shapes = {_nested_shape(v, what) for v in value}
    if len(shapes) != 1:
        sizes = sorted("x".join(map(str, s)) or "scalar" for s in shapes)
        raise PatternError(f"{what} has mismatched sizes: {', '.join(sizes)}")
    return (len(value), *shapes.pop())


def _as_layout(layout: Any) -> np.ndarray:
    shape = _nested_shape(layout, "layout")
    if len(shape) != 2:
        raise PatternError(f"layout must be a 2-D grid of integers, got shape {shape}")
    arr = np.asarray(layout, dtype=object) if not isinstance(layout, np.ndarray) else layout
    flat = arr.reshape(-1).tolist()
    for v in flat:
        is_int = isinstance(v, Integral) and not isinstance(v, bool)
        is_integral_float = (
            isinstance(v, Real) and not isinstance(v, bool) and float(v).is_integer()
        )
        if not (is_int or (isinstance(layout, np.ndarray) and is_integral_float)):
            raise PatternError(f"layout must be a 2-D grid of integers, got the entry {v!r}")
    return np.asarray(flat, dtype=np.int64).reshape(shape)


def _dark_pixel(layout: np.ndarray, kernels: np.ndarray) -> tuple[int, int] | None:
    """The first pixel of the period (row, column) that no splitter sends light of any colour
    to, or None: each splitter at ``q`` sends its kernel's light to ``q + offset``, wrapped
    around the period (the pattern repeats)."""
    ph, pw = layout.shape
    dy, dx = kernel_offsets(*kernels.shape[2:])
    received = np.zeros((ph, pw))
    light = kernels.sum(axis=1)  # (S, kh, kw): all colours together
    for (qi, qj), s in np.ndenumerate(layout):
        np.add.at(received, ((qi + dy) % ph, (qj + dx) % pw), light[s])
    dark = np.argwhere(received <= 0)
    return (int(dark[0][0]), int(dark[0][1])) if dark.size else None


def _as_kernels(kernels: Any) -> np.ndarray:
    shape = _nested_shape(kernels, "kernels")
    if len(shape) != 4:
        raise PatternError(
            f"kernels must have shape (splitters, 3 colours, kh, kw), got shape {shape}"
        )
    try:
        arr = np.asarray(kernels, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise PatternError(f"kernels must be numbers: {exc}") from None
    return arr


@dataclass(frozen=True, eq=False)
class Pattern:
    """A splitter (or colour-filter) pattern.

    Args:
        name: Short name, e.g. ``"D"``.
        layout: Integer grid of shape ``(Ph, Pw)``: the splitter index at each period position.
        kernels: Array of shape ``(S, 3, kh, kw)``, odd ``kh`` and ``kw``, non-negative, each
            ``(s, c)`` kernel summing to at most 1.
        provenance: Where the values come from ("authors' code", "modelled ...", "learned", ...).
        description: One line saying what the pattern is.
        reference: Publication the pattern comes from.

    Raises:
        PatternError: If any of the constraints above is violated; the message names it.
    """

    name: str
    layout: np.ndarray
    kernels: np.ndarray
    provenance: str = "user"
    description: str = ""
    reference: str = ""
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise PatternError("a pattern needs a non-empty name")
        layout = _as_layout(self.layout)
        kernels = _as_kernels(self.kernels)
        n_split, n_col, kh, kw = kernels.shape
        if n_col != 3:
            raise PatternError(f"kernels must have 3 colours (R, G, B) on axis 1, got {n_col}")
        if n_split < 1:
            raise PatternError("kernels must define at least one splitter")
        if kh % 2 == 0 or kw % 2 == 0:
            raise PatternError(
                f"kernel size must be odd in both directions (the centre is the pixel the light "
                f"arrives at), got {kh}x{kw}"
            )
        bad = np.argwhere((layout < 0) | (layout >= n_split))
        if bad.size:
            i, j = (int(v) for v in bad[0])
            raise PatternError(
                f"layout index {int(layout[i, j])} at position ({i}, {j}) is out of range for "
                f"{n_split} splitter{'s' * (n_split != 1)} (valid: 0..{n_split - 1})"
            )
        if not np.all(np.isfinite(kernels)):
            s, c, a, b = (int(v) for v in np.argwhere(~np.isfinite(kernels))[0])
            raise PatternError(
                f"kernel weight of splitter {s}, colour {COLOURS[c]} at ({a}, {b}) is not finite"
            )
        if np.any(kernels < 0):
            s, c, a, b = (int(v) for v in np.argwhere(kernels < 0)[0])
            raise PatternError(
                f"kernel weight of splitter {s}, colour {COLOURS[c]} at ({a}, {b}) is negative "
                f"({kernels[s, c, a, b]:g}); light fractions must be >= 0"
            )
        sums = kernels.sum(axis=(2, 3))
        over = np.argwhere(sums > 1 + SUM_TOLERANCE)
        if over.size:
            s, c = (int(v) for v in over[0])
            raise PatternError(
                f"splitter {s}, colour {COLOURS[c]} sums to {sums[s, c]:.6g} > 1: a splitter "
                f"cannot send on more light than arrives (it would create light)"
            )
        dark = _dark_pixel(layout, kernels)
        if dark is not None:
            i, j = dark
            raise PatternError(
                f"pixel ({i}, {j}) of the period records no light: no splitter sends it any R, G "
                f"or B, so it measures nothing and no reconstruction can use it (the LMMSE "
                f"cannot even be solved)"
            )
        layout.setflags(write=False)
        kernels.setflags(write=False)
        object.__setattr__(self, "layout", layout)
        object.__setattr__(self, "kernels", kernels)

    @property
    def period(self) -> tuple[int, int]:
        """``(Ph, Pw)``, the size of the repeating unit cell."""
        return (int(self.layout.shape[0]), int(self.layout.shape[1]))

    @property
    def num_splitters(self) -> int:
        return int(self.kernels.shape[0])

    @property
    def kernel_size(self) -> tuple[int, int]:
        return (int(self.kernels.shape[2]), int(self.kernels.shape[3]))

    @property
    def absorbs_light(self) -> bool:
        """True for a colour filter: some colour at some used splitter sums below 1."""
        used = np.unique(self.layout)
        return bool(np.any(self.kernels[used].sum(axis=(2, 3)) < 1 - SUM_TOLERANCE))

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form used by pattern files and checkpoints."""
        return {
            "name": self.name,
            "provenance": self.provenance,
            "description": self.description,
            "reference": self.reference,
            "layout": self.layout.tolist(),
            "kernels": [
                {c: self.kernels[s, i].tolist() for i, c in enumerate(COLOURS)}
                for s in range(self.num_splitters)
            ],
            **({"metadata": self.metadata} if self.metadata else {}),
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "pattern") -> Pattern:
        """Build from the plain-data form; kernels as ``[{R:, G:, B:}, ...]`` or a 4-D list."""
        if not isinstance(data, dict):
            raise PatternError(f"{source}: expected a table/object, got {type(data).__name__}")
        missing = [k for k in ("name", "layout", "kernels") if k not in data]
        if missing:
            raise PatternError(f"{source}: missing field(s) {', '.join(missing)}")
        unknown = set(data) - {
            "name",
            "provenance",
            "description",
            "reference",
            "layout",
            "kernels",
            "metadata",
        }
        if unknown:
            raise PatternError(f"{source}: unknown field(s) {', '.join(sorted(unknown))}")
        kernels = data["kernels"]
        if isinstance(kernels, list) and kernels and isinstance(kernels[0], dict):
            rows = []
            for s, k in enumerate(kernels):
                if not isinstance(k, dict) or set(k) != set(COLOURS):
                    got = sorted(k) if isinstance(k, dict) else type(k).__name__
                    raise PatternError(
                        f"{source}: splitter {s} must give exactly the colours R, G, B, got {got}"
                    )
                rows.append([k[c] for c in COLOURS])
            kernels = rows
        try:
            return cls(
                name=str(data["name"]),
                layout=data["layout"],
                kernels=kernels,
                provenance=str(data.get("provenance", "user")),
                description=str(data.get("description", "")),
                reference=str(data.get("reference", "")),
                metadata=dict(data.get("metadata", {})),
            )
        except PatternError as exc:
            raise PatternError(f"{source}: {exc}") from None

    def __repr__(self) -> str:
        kh, kw = self.kernel_size
        return (
            f"Pattern({self.name!r}, period={self.period}, splitters={self.num_splitters}, "
            f"kernel={kh}x{kw}, provenance={self.provenance!r})"
        )

    def equals(self, other: Pattern, atol: float = 0.0) -> bool:
        """Same layout and kernels (to ``atol``)."""
        return (
            self.layout.shape == other.layout.shape
            and bool(np.array_equal(self.layout, other.layout))
            and self.kernels.shape == other.kernels.shape
            and bool(np.allclose(self.kernels, other.kernels, rtol=0, atol=atol))
        )


def kernel_offsets(kh: int, kw: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column offsets ``(a - kh//2, b - kw//2)`` of every tap, each of shape (kh, kw)."""
    dy, dx = np.meshgrid(np.arange(kh) - kh // 2, np.arange(kw) - kw // 2, indexing="ij")
    return dy, dx


def check_pattern(value: Any, what: str = "pattern") -> Pattern:
    """``value`` if it is a :class:`Pattern`; else a TypeError that says how to make one.

    Library functions take patterns, not names: a name or a file is read once, where a user
    hands it over (:func:`splitcam.patterns.get`, the constructors users call, the CLI).

    >>> check_pattern("D", "start")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    TypeError: expected a Pattern for start, got the str 'D': splitcam.patterns.get('D') reads...
    """
    if isinstance(value, Pattern):
        return value
    hint = (
        f": splitcam.patterns.get({str(value)!r}) reads a pattern's name or file"
        if isinstance(value, (str, PurePath))
        else ""
    )
    raise TypeError(
        f"expected a Pattern for {what}, got the {type(value).__name__} {value!r}{hint}"
    )
