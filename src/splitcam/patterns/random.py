"""Random valid patterns, to train one network over many patterns (model.md §16).

:func:`random_pattern` draws a pattern from one of three families, each a kind of sensor a
designer brings:

- ``filter``: a colour filter array. 1x1 kernels; every position of the period gets a colour
  class (R, G, B, a complementary C/M/Y or panchromatic W) whose in-band transmission is drawn in
  ``[0.5, 1]`` and whose out-of-band leakage in ``[0, 0.15]`` (loss and crosstalk of real dyes).
- ``router``: a structured colour router such as A, B, D or E. Each position of the period owns a
  colour set (one colour, or W); every splitter sends each colour ``c`` to the pixels within its
  kernel's reach that own ``c``, equally or with random weights, at an efficiency ``eta`` in
  ``[0.4, 1]``, and spreads a crosstalk fraction ``chi`` over the other taps (``eta + chi <= 1``;
  the rest is lost).
- ``scatter``: unstructured kernels: each ``(splitter, colour)`` kernel is a sparse random
  distribution over the taps (Dirichlet with a small concentration), times an efficiency in
  ``[0.4, 1]``; like an unoptimised metasurface.

Periods are drawn from 1x1 to ``max_period`` per axis, kernel sides from 1 to ``max_kernel``
(odd; 1 for filters), the layout either one splitter per position or a random assignment of
fewer splitters. Every draw is a valid :class:`~splitcam.patterns.Pattern` (non-negative, each
kernel summing to at most 1) in which every colour reaches the sensor: at least
``MIN_COLOUR_SHARE`` of a flat scene's light of each colour lands on some pixel. Draws are a pure
function of the ``numpy`` generator, so a seed reproduces them.
"""

from __future__ import annotations

import numpy as np

from ..checks import check_count
from .core import Pattern

__all__ = ["FAMILIES", "MIN_COLOUR_SHARE", "PatternMix", "random_pattern"]

#: Smallest mean fraction (over the period's positions) of each colour a draw must collect.
MIN_COLOUR_SHARE = 0.1

# Colour sets a position (filter or router target) can own: R, G, B, then C, M, Y, then W.
_SETS = np.array(
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 1], [1, 0, 1], [1, 1, 0], [1, 1, 1]], dtype=np.float64
)
# Draw weights of the sets: primaries most often, as in most sensors.
_SET_WEIGHTS = np.array([3, 3, 3, 1, 1, 1, 2], dtype=np.float64) / 14.0


def _owners(rng: np.random.Generator, period: tuple[int, int]) -> np.ndarray:
    """Colour sets ``(Ph, Pw, 3)`` of the positions, every colour owned by at least one."""
    while True:
        sets = _SETS[rng.choice(len(_SETS), size=period, p=_SET_WEIGHTS)]
        if sets.reshape(-1, 3).max(0).min() > 0:
            return sets


def _layout(rng: np.random.Generator, period: tuple[int, int]) -> tuple[np.ndarray, int]:
    """A layout: one splitter per position (half the draws), else a random assignment."""
    ph, pw = period
    n = ph * pw
    if n == 1 or rng.random() < 0.5:
        return np.arange(n).reshape(ph, pw), n
    s = int(rng.integers(1, n + 1))
    layout = rng.integers(0, s, size=(ph, pw))
    used = np.unique(layout)  # renumber so every splitter is used
    return np.searchsorted(used, layout), len(used)


def _filter(
    rng: np.random.Generator, period: tuple[int, int], kh: int, kw: int
) -> tuple[np.ndarray, np.ndarray]:
    del kh, kw  # filters have 1x1 kernels
    ph, pw = period
    sets = _owners(rng, period).reshape(-1, 3)
    band = rng.uniform(0.5, 1.0, size=sets.shape)
    leak = rng.uniform(0.0, 0.15, size=sets.shape)
    kernels = np.where(sets > 0, band, leak)[:, :, None, None]
    return np.arange(ph * pw).reshape(ph, pw), kernels


def _router(
    rng: np.random.Generator, period: tuple[int, int], kh: int, kw: int
) -> tuple[np.ndarray, np.ndarray]:
    ph, pw = period
    owners = _owners(rng, period)
    layout, s = _layout(rng, period)
    kernels = np.zeros((s, 3, kh, kw))
    dy, dx = np.meshgrid(np.arange(kh) - kh // 2, np.arange(kw) - kw // 2, indexing="ij")
    dist = np.hypot(dy, dx)
    for k in range(s):
        # The splitter's position: the first place of the period that uses it.
        i, j = (int(v) for v in np.argwhere(layout == k)[0])
        for c in range(3):
            # Target taps: pixels within reach that own colour c.
            owns = owners[(i + dy) % ph, (j + dx) % pw, c] > 0
            if not owns.any():  # no owner within reach: the light stays
                owns = dist == 0
            if rng.random() < 0.7:  # nearest owners, equal shares (like A, D, E)
                near = owns & (dist == dist[owns].min())
                target = near / near.sum()
            else:  # every owner within reach, random shares
                w = owns * rng.gamma(1.0, size=owns.shape)
                target = w / w.sum()
            eta = rng.uniform(0.4, 1.0)
            chi = rng.uniform(0.0, min(0.35, 1.0 - eta)) if (~owns).any() else 0.0
            spread = ~owns / max((~owns).sum(), 1)
            kernels[k, c] = eta * target + chi * spread
    return layout, kernels


def _scatter(
    rng: np.random.Generator, period: tuple[int, int], kh: int, kw: int
) -> tuple[np.ndarray, np.ndarray]:
    layout, s = _layout(rng, period)
    taps = kh * kw
    raw = rng.dirichlet(np.full(taps, 0.3), size=(s, 3))
    eta = rng.uniform(0.4, 1.0, size=(s, 3, 1))
    return layout, (raw * eta).reshape(s, 3, kh, kw)


#: The families :func:`random_pattern` draws from: name → draw ``(rng, period, kh, kw) →
#: (layout, kernels)``.
FAMILIES = {"filter": _filter, "router": _router, "scatter": _scatter}


def random_pattern(
    rng: np.random.Generator,
    *,
    max_period: int = 4,
    max_kernel: int = 5,
    families: tuple[str, ...] = tuple(FAMILIES),
    name: str = "random",
) -> Pattern:
    """One random valid pattern (see the module docstring for the families).

    Args:
        rng: The generator; the draw is a pure function of its state.
        max_period: Largest period side (each axis drawn from 1 to it).
        max_kernel: Largest kernel side (odd sides from 1 to it, each axis on its own).
        families: The families to draw from, equally likely.
        name: The pattern's name.

    Raises:
        ValueError: ``max_period < 1``, ``max_kernel`` not an odd number >= 1, or an unknown family.
    """
    check_count(max_period, "max_period", 1)
    if max_kernel < 1 or max_kernel % 2 == 0:
        raise ValueError(f"max_kernel must be an odd number >= 1, got {max_kernel}")
    unknown = sorted(set(families) - set(FAMILIES))
    if unknown or not families:
        raise ValueError(f"unknown families {unknown}; valid: {', '.join(FAMILIES)}")
    sides = np.arange(1, max_kernel + 1, 2)
    while True:
        family = families[int(rng.integers(len(families)))]
        period = (int(rng.integers(1, max_period + 1)), int(rng.integers(1, max_period + 1)))
        kh, kw = (int(v) for v in rng.choice(sides, size=2))
        layout, kernels = FAMILIES[family](rng, period, kh, kw)
        # Each kernel at most 1 despite rounding; every colour reaches the sensor.
        kernels = kernels / np.maximum(kernels.sum((2, 3), keepdims=True), 1.0)
        share = kernels[layout].sum((-1, -2)).reshape(-1, 3).mean(0)
        if share.min() >= MIN_COLOUR_SHARE:
            return Pattern(
                name=name,
                layout=layout,
                kernels=kernels,
                provenance="random",
                description=f"random {family} pattern, period {period[0]}x{period[1]}",
            )


class PatternMix:
    """Which pattern a training step uses: random draws mixed with named patterns.

    The pattern of step ``t`` is a pure function of ``(seed, t)``, so a resumed run (or another
    rank of a distributed one) draws the same patterns without any saved state.

    Args:
        named: Patterns mixed in (library names, files or :class:`Pattern`).
        named_fraction: Probability that a step uses one of ``named`` (equally likely) instead of
            a random draw.
        seed: Seed of the draws.
        max_period: Limit of the random draws (:func:`random_pattern`).
        max_kernel: Limit of the random draws (:func:`random_pattern`).
    """

    def __init__(
        self,
        named: list[Pattern] | tuple[Pattern, ...] = (),
        named_fraction: float = 0.3,
        seed: int = 0,
        *,
        max_period: int = 4,
        max_kernel: int = 5,
    ) -> None:
        if not 0.0 <= named_fraction <= 1.0:
            raise ValueError(f"named_fraction must be in [0, 1], got {named_fraction}")
        if named_fraction > 0 and not named:
            raise ValueError("named_fraction > 0 needs at least one named pattern")
        self.named = list(named)
        self.named_fraction = float(named_fraction)
        self.seed = int(seed)
        self.max_period = max_period
        self.max_kernel = max_kernel

    def pattern(self, step: int) -> Pattern:
        rng = np.random.default_rng([self.seed, int(step)])
        if self.named and rng.random() < self.named_fraction:
            return self.named[int(rng.integers(len(self.named)))]
        return random_pattern(rng, max_period=self.max_period, max_kernel=self.max_kernel)
