"""Random valid patterns (splitcam.patterns.random): valid, seeded, bounded."""

from __future__ import annotations

import numpy as np
import pytest

from splitcam import patterns
from splitcam.patterns.random import FAMILIES, MIN_COLOUR_SHARE, PatternMix, random_pattern


def test_random_patterns_are_valid_over_many_draws() -> None:
    rng = np.random.default_rng(0)
    families, periods, sizes = set(), set(), set()
    for _ in range(600):
        p = random_pattern(rng)
        # Re-validating through the constructor checks non-negativity and sums <= 1 again.
        patterns.Pattern(p.name, p.layout, p.kernels)
        k = p.kernels
        assert (k >= 0).all() and (k.sum((2, 3)) <= 1 + 1e-9).all()
        assert set(np.unique(p.layout)) == set(range(p.num_splitters))  # every splitter used
        # Every colour reaches the sensor: of a flat scene, each colour's mean collected share.
        share = k[p.layout].sum((-1, -2)).reshape(-1, 3).mean(0)
        assert share.min() >= MIN_COLOUR_SHARE
        assert 1 <= min(p.period) and max(p.period) <= 4
        assert max(p.kernel_size) <= 5
        families.add(p.description.split()[1])
        periods.add(p.period)
        sizes.add(p.kernel_size)
    assert families == set(FAMILIES)
    assert (4, 4) in periods and (1, 1) in periods and (1, 3) in periods
    assert (5, 5) in sizes and (1, 1) in sizes


def test_random_patterns_are_a_function_of_the_seed() -> None:
    a = random_pattern(np.random.default_rng(7))
    b = random_pattern(np.random.default_rng(7))
    assert a.equals(b)
    mix = PatternMix([patterns.get("D")], 0.5, seed=3)
    assert all(mix.pattern(t).equals(mix.pattern(t)) for t in range(20))
    named = sum(mix.pattern(t).name == "D" for t in range(400))
    assert 150 < named < 250  # half the steps, within about 5 standard deviations


def test_random_pattern_rejects_bad_limits() -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="max_kernel"):
        random_pattern(rng, max_kernel=4)
    with pytest.raises(ValueError, match="families"):
        random_pattern(rng, families=("lens",))
    with pytest.raises(ValueError, match="named pattern"):
        PatternMix([], 0.5)
