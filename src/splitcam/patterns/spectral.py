"""Spectral patterns: a sensor described wavelength by wavelength, reduced exactly to Eq. 2's RGB
kernels.

A spectral pattern has the layout of a :class:`~splitcam.patterns.core.Pattern` and, in place of
the three colours, a grid of wavelengths: ``kernels[s, l]`` is the ``kh x kw`` kernel of
splitter ``s`` at wavelength ``wavelengths[l]`` (the share of that wavelength's light arriving on
the splitter's pixel that lands on each neighbour; each sums to at most 1). Where only the
period's totals are known (``transmission[i, j, l]``: the share of the light of wavelength ``l``
arriving on the whole period that lands on pixel ``(i, j)``; a full-wave simulation of a
periodic metasurface gives exactly this), :meth:`SpectralPattern.from_transmission` spreads it
by the rule documented there.

**The reduction** (:meth:`SpectralPattern.to_pattern`). Eq. 2 is linear in the light, so a
spectral sensor is an RGB sensor exactly for scenes whose spectra are linear in their linear
sRGB values, ``S(x, l) = sum_c rgb_c(x) E_c(l)``. splitcam takes ``E_c`` from the spectral
upsampling of Mallett & Yuksel (*Spectral Primary Decomposition for Rendering with sRGB
Reflectance*, EGSR 2019; ``colour.recovery`` ships the three basis reflectances, which sum to 1
at every wavelength and reproduce sRGB under D65): ``E_c = B_c * D65``, each scaled to sum to 1 on
the grid, so that one unit of colour ``c`` is what the RGB model calls one unit of light of
colour ``c`` (a bare pixel collects 1 of each; a sensor's kernels then keep summing to
at most 1 per colour). The RGB kernel of splitter ``s`` and colour ``c`` is then

    ``k[s, c] = sum_l kernels[s, l] * E_c(l)``,

and a simulation wavelength by wavelength of such a scene gives the RGB sensor's raw image to
rounding (tests/patterns/test_spectral.py checks 1e-6). For other scenes the reduction is an
approximation: two spectra of one sRGB colour (metamers) can give different raw values. The
size of that error for real reflectances is measured in docs/results/spectral/.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from .core import Pattern, PatternError, _as_layout

__all__ = ["SpectralPattern", "scene_basis"]

#: The wavelengths (nm) the scene basis is defined on (Mallett & Yuksel's tables).
BASIS_RANGE = (380.0, 780.0)


@lru_cache(maxsize=8)
def _basis(wavelengths: tuple[float, ...]) -> np.ndarray:
    import colour
    from colour.recovery import MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019

    grid = np.asarray(wavelengths)
    basis = MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    d65 = colour.SDS_ILLUMINANTS["D65"]
    columns = [
        np.interp(grid, basis.wavelengths, basis.values[:, c])
        * np.interp(grid, d65.wavelengths, d65.values)
        for c in range(3)
    ]
    e = np.stack(columns, axis=1)  # (L, 3)
    return e / e.sum(axis=0, keepdims=True)


def scene_basis(wavelengths: Any) -> np.ndarray:
    """The spectra ``E_c`` of one unit of linear sRGB red, green and blue on ``wavelengths``
    (nm), ``(L, 3)``: Mallett & Yuksel's basis reflectances under D65, each column summing to 1
    (D65's spectral power: the weights are energy per
    wavelength, summing to 1; see the module docstring). See the module docstring.

    Raises:
        PatternError: Wavelengths not increasing, or outside 380-780 nm.
    """
    grid = _check_wavelengths(wavelengths)
    return _basis(tuple(float(v) for v in grid)).copy()


def _check_wavelengths(wavelengths: Any) -> np.ndarray:
    try:
        grid = np.asarray(wavelengths, dtype=np.float64)
    except (TypeError, ValueError):
        raise PatternError(f"wavelengths must be numbers (nm), got {wavelengths!r}") from None
    if grid.ndim != 1 or grid.size < 1 or not np.all(np.isfinite(grid)):
        raise PatternError("wavelengths must be a list of numbers (nm)")
    if np.any(np.diff(grid) <= 0):
        raise PatternError("wavelengths must increase")
    low, high = BASIS_RANGE
    if grid[0] < low or grid[-1] > high:
        raise PatternError(
            f"wavelengths {grid[0]:g}-{grid[-1]:g} nm lie outside {low:g}-{high:g} nm, where "
            "the scene spectra are defined"
        )
    return grid


def _numbers(values: Any, name: str, what: str) -> np.ndarray:
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise PatternError(f"spectral pattern {name!r}: {what} must be numbers") from None


def _light(values: np.ndarray, name: str, what: str) -> None:
    """Refuse shares of light that are not finite or negative."""
    if not np.all(np.isfinite(values)) or values.min() < 0:
        raise PatternError(f"spectral pattern {name!r}: {what} must be finite and >= 0")


def _nearest_copies(q: tuple[int, int], p: tuple[int, int], period: tuple[int, int]) -> list:
    """Offsets from pixel ``q`` to the nearest copies of pixel ``p`` of the repeating period
    (several where they tie, e.g. left and right in a period of 2)."""
    options = []
    for axis in range(2):
        n = period[axis]
        d = (p[axis] - q[axis]) % n
        candidates = [d, d - n]
        best = min(abs(c) for c in candidates)
        options.append(sorted({c for c in candidates if abs(c) == best}))
    return [(dy, dx) for dy in options[0] for dx in options[1]]


@dataclass
class SpectralPattern:
    """A pattern given wavelength by wavelength (see the module docstring).

    Args:
        name: The pattern's name.
        layout: ``(Ph, Pw)`` splitter index of each pixel of the period.
        wavelengths: ``(L,)`` increasing, nm, within 380-780.
        kernels: ``(S, L, kh, kw)``, odd ``kh, kw``, non-negative, each ``(s, l)`` kernel
            summing to at most 1.
        provenance: As for :class:`~splitcam.patterns.core.Pattern`.
        description: As for :class:`~splitcam.patterns.core.Pattern`.
        reference: As for :class:`~splitcam.patterns.core.Pattern`.
        metadata: Anything else to keep with the pattern.

    Raises:
        PatternError: Any of the above violated; a kernel that creates light names its
            splitter and wavelength.
    """

    name: str
    layout: np.ndarray
    wavelengths: np.ndarray
    kernels: np.ndarray
    provenance: str = "user"
    description: str = ""
    reference: str = ""
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.layout = _as_layout(self.layout)
        self.wavelengths = _check_wavelengths(self.wavelengths)
        k = _numbers(self.kernels, self.name, "kernels")
        s, length = int(self.layout.max()) + 1, len(self.wavelengths)
        if k.ndim != 4 or k.shape[:2] != (s, length) or k.shape[2] % 2 == 0 or k.shape[3] % 2 == 0:
            raise PatternError(
                f"spectral pattern {self.name!r}: kernels must have shape (splitters {s}, "
                f"wavelengths {length}, odd kh, odd kw), got {k.shape}"
            )
        _light(k, self.name, "kernels")
        sums = k.sum(axis=(2, 3))
        if sums.max() > 1 + 1e-9:
            si, li = np.unravel_index(int(sums.argmax()), sums.shape)
            raise PatternError(
                f"spectral pattern {self.name!r}: splitter {si} sends on {sums[si, li]:.4g} of "
                f"the light at {self.wavelengths[li]:g} nm (at most 1: it cannot create light)"
            )
        self.kernels = k

    @property
    def period(self) -> tuple[int, int]:
        return (int(self.layout.shape[0]), int(self.layout.shape[1]))

    @classmethod
    def from_transmission(
        cls, name: str, wavelengths: Any, transmission: Any, **info: Any
    ) -> SpectralPattern:
        """A pattern from the period's totals: ``transmission[i, j, l]``, the share of light of
        wavelength ``l`` arriving on the period that lands on pixel ``(i, j)``.

        Totals fix how much light each pixel gets, not where it came from. The rule here: every
        pixel of the period sends the same shares, ``transmission[p, l]`` of its light to pixel
        ``p``, landing on the nearest copy of ``p`` (split evenly where copies tie). Under
        uniform light each pixel then receives exactly its total, and a lossless design loses
        nothing. For a 2x2 router this puts each colour's light within one pixel of where it
        arrived; the kernels are 3x3 for a period of 2 and 5x5 for one of 3 or 4.

        Raises:
            PatternError: Not ``(Ph, Pw, L)``, negative, or pixel shares summing above 1 at a
                wavelength (light created; the message names it).
        """
        t = _numbers(transmission, name, "transmission")
        grid = _check_wavelengths(wavelengths)
        if t.ndim != 3 or t.shape[2] != len(grid):
            raise PatternError(
                f"spectral pattern {name!r}: transmission must have shape (rows, columns, "
                f"{len(grid)} wavelengths), got {t.shape}"
            )
        _light(t, name, "transmission")
        total = t.sum(axis=(0, 1))
        if total.max() > 1 + 1e-9:
            li = int(total.argmax())
            raise PatternError(
                f"spectral pattern {name!r}: the pixels receive {total[li]:.4g} of the light at "
                f"{grid[li]:g} nm (at most 1: a sensor cannot create light)"
            )
        ph, pw = t.shape[:2]
        half = (ph // 2, pw // 2)
        kernels = np.zeros((ph * pw, len(grid), 2 * half[0] + 1, 2 * half[1] + 1))
        for q in np.ndindex(ph, pw):
            s = q[0] * pw + q[1]
            for p in np.ndindex(ph, pw):
                copies = _nearest_copies(q, p, (ph, pw))
                for dy, dx in copies:
                    kernels[s, :, dy + half[0], dx + half[1]] += t[p] / len(copies)
        layout = np.arange(ph * pw).reshape(ph, pw)
        meta = {"transmission": t.tolist(), **info.pop("metadata", {})}
        return cls(name, layout, grid, kernels, metadata=meta, **info)

    @classmethod
    def from_dict(cls, data: Any, source: str = "spectral pattern") -> SpectralPattern:
        """The plain-data form of a pattern file: ``name``, ``wavelengths`` and either
        ``transmission`` (``(Ph, Pw, L)``, :meth:`from_transmission`) or ``layout`` with
        ``kernels`` (``(S, L, kh, kw)``); optional ``provenance``, ``description``,
        ``reference``, ``metadata``."""
        if not isinstance(data, dict):
            raise PatternError(f"{source}: expected a table/object, got {type(data).__name__}")
        info = {k: str(data[k]) for k in ("provenance", "description", "reference") if k in data}
        info["metadata"] = dict(data.get("metadata", {}))
        allowed = {"name", "wavelengths", "transmission", "layout", "kernels", *info}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise PatternError(f"{source}: unknown field(s) {', '.join(unknown)}")
        has_t, has_k = "transmission" in data, "kernels" in data or "layout" in data
        if "name" not in data or has_t == has_k:
            raise PatternError(
                f"{source}: a spectral pattern needs name, wavelengths and either transmission "
                "(rows x columns x wavelengths) or layout and kernels (splitters x wavelengths x "
                "kh x kw)"
            )
        try:
            if has_t:
                return cls.from_transmission(
                    str(data["name"]), data["wavelengths"], data["transmission"], **info
                )
            return cls(
                str(data["name"]), data["layout"], data["wavelengths"], data["kernels"], **info
            )
        except (PatternError, KeyError) as exc:
            raise PatternError(f"{source}: {exc}") from None

    def to_pattern(self) -> Pattern:
        """The RGB :class:`~splitcam.patterns.core.Pattern` of this sensor: exact for scenes
        whose spectra are linear in linear sRGB (the module docstring)."""
        e = scene_basis(self.wavelengths)
        rgb = np.einsum("slhw,lc->schw", self.kernels, e)
        return Pattern(
            name=self.name,
            layout=self.layout,
            kernels=rgb,
            provenance=self.provenance,
            description=self.description
            or f"spectral sensor on {self.wavelengths[0]:g}-{self.wavelengths[-1]:g} nm, reduced "
            "to RGB by splitcam.patterns.spectral",
            reference=self.reference,
            metadata={
                **self.metadata,
                "spectral": {
                    "wavelengths": self.wavelengths.tolist(),
                    "kernels": self.kernels.tolist(),
                },
            },
        )
