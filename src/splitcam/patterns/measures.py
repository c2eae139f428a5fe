"""Design-principle measures of a pattern (paper section 3.1, model.md §2).

The paper's three principles — avoid the sub-pixel (pooling) structure, split colours to a region
as small as possible, split the incident light fully — become numbers that can be read for any
pattern, including learned ones:

- ``efficiency``: mean kernel sum over the layout, per colour (1 = lossless, 1/3 for Bayer G/2...);
  ``white``, their mean: the share of white light collected.
- ``split_fraction``: share of the incident (white) light that leaves the pixel it arrived at.
- ``spread``: the largest distance (in pixels) any light travels; ``mean_travel``: the
  light-weighted mean distance travelled.
- ``purity``: the mean over the period's pixels of the largest colour's share of what the pixel
  records under white light: 1 when every pixel records one colour (ideal filters, A), 1/3 for a
  bare (W) pixel; leaky filters and routers with crosstalk lie between.
- ``pooling_unit``: how many sites send every colour to exactly the same pixels (the sub-pixel
  structure: the unit pools its light); 1 means no pooling.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .core import Pattern, kernel_offsets

#: Weights below this count as "no light" when finding supports.
SUPPORT_EPS = 1e-6


@dataclass(frozen=True)
class PatternMeasures:
    name: str
    period: tuple[int, int]
    efficiency: tuple[float, float, float]
    split_fraction: float
    spread: float
    mean_travel: float
    pooling_unit: int
    purity: float = 1.0

    @property
    def pooling(self) -> bool:
        return self.pooling_unit > 1

    @property
    def white(self) -> float:
        """Share of white light the sensor collects (the mean of the three efficiencies): 1 for
        a lossless router, 2/3 for an ideal RGBW array, 1/3 for Bayer and Quad Bayer."""
        return sum(self.efficiency) / 3

    def row(self) -> dict[str, str]:
        """Formatted cells for a table."""
        return {
            "pattern": self.name,
            "period": f"{self.period[0]}x{self.period[1]}",
            "efficiency R/G/B": "/".join(f"{e:.2f}" for e in self.efficiency),
            "white": f"{self.white:.3f}",
            "purity": f"{self.purity:.2f}",
            "split": f"{self.split_fraction:.2f}",
            "spread (px)": f"{self.spread:.2f}",
            "mean travel (px)": f"{self.mean_travel:.2f}",
            "pooling": f"yes, {self.pooling_unit}-pixel unit" if self.pooling else "no",
        }


def _targets(pattern: Pattern, i: int, j: int, c: int, oy: int, ox: int) -> frozenset:
    """Sensor pixels reached by colour ``c`` from position ``(i, j)`` of the period (oy, ox)."""
    ph, pw = pattern.period
    k = pattern.kernels[pattern.layout[i, j], c]
    dy, dx = kernel_offsets(*k.shape)
    y0, x0 = oy * ph + i, ox * pw + j
    on = k > SUPPORT_EPS
    return frozenset((y0 + int(a), x0 + int(b)) for a, b in zip(dy[on], dx[on], strict=True))


def _pooling_unit(pattern: Pattern) -> int:
    """Largest number of sites that send every colour to exactly the same pixels.

    Such sites form a unit that treats its light as a whole (the paper's sub-pixel structure):
    the sensor cannot tell where in the unit the light arrived. The criterion is over all three
    colours together: sharing one colour's target alone is not pooling (pattern E's plain pixel
    and its splitter both put red on the same pixel, yet the paper counts E among the patterns
    without the sub-pixel structure).
    """
    ph, pw = pattern.period
    best = 1
    for i in range(ph):
        for j in range(pw):
            mine = [_targets(pattern, i, j, c, 0, 0) for c in range(3)]
            if not any(mine):
                continue
            same = sum(
                all(_targets(pattern, i2, j2, c, oy, ox) == mine[c] for c in range(3))
                for oy in (-1, 0, 1)
                for ox in (-1, 0, 1)
                for i2 in range(ph)
                for j2 in range(pw)
            )
            best = max(best, same)
    return best


def measure(pattern: Pattern) -> PatternMeasures:
    """Compute the design-principle measures of ``pattern``.

    >>> from splitcam import patterns
    >>> a = patterns.measure(patterns.get("A"))
    >>> a.efficiency, a.white  # a lossless router collects all of every colour
    ((1.0, 1.0, 1.0), 1.0)
    >>> round(a.split_fraction, 4), a.pooling  # two thirds of the light change pixel
    (0.6667, False)
    >>> patterns.measure(patterns.get("bayer")).efficiency  # colour filters absorb the rest
    (0.25, 0.5, 0.25)
    """
    ph, pw = pattern.period
    k = pattern.kernels[pattern.layout.reshape(-1)]  # (P, 3, kh, kw), one per period position
    kh, kw = pattern.kernel_size
    dy, dx = kernel_offsets(kh, kw)
    dist = np.hypot(dy, dx)
    incident = k.shape[0] * 3
    centre = k[:, :, kh // 2, kw // 2]
    moved = k.sum(axis=(2, 3)) - centre
    reached = dist[(k > SUPPORT_EPS).any(axis=(0, 1))]
    unit = _pooling_unit(pattern)
    total = float(k.sum())
    return PatternMeasures(
        name=pattern.name,
        period=pattern.period,
        efficiency=tuple(float(e) for e in k.sum(axis=(2, 3)).mean(axis=0)),
        split_fraction=float(moved.sum() / incident),
        spread=float(reached.max()) if reached.size else 0.0,
        mean_travel=float((k * dist).sum() / total) if total > 0 else 0.0,
        pooling_unit=unit,
        purity=_purity(pattern),
    )


def _purity(pattern: Pattern) -> float:
    response = pixel_response(pattern)
    total = response.sum(axis=2)
    lit = total > 0
    return float((response.max(axis=2)[lit] / total[lit]).mean()) if lit.any() else 0.0


def pixel_response(pattern: Pattern) -> np.ndarray:
    """``(Ph, Pw, 3)``: what each pixel of the unit cell records of a white scene, per colour."""
    ph, pw = pattern.period
    kh, kw = pattern.kernel_size
    response = np.zeros((ph, pw, 3))
    for i in range(ph):
        for j in range(pw):
            for a in range(kh):
                for b in range(kw):
                    # Light reaching (i, j) through tap (a, b) left from (i - dy, j - dx).
                    s = pattern.layout[(i - a + kh // 2) % ph, (j - b + kw // 2) % pw]
                    response[i, j] += pattern.kernels[s, :, a, b]
    return response
