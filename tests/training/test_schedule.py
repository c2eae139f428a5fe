"""Learning-rate schedules (splitcam.training.schedule)."""

from __future__ import annotations

import math

import pytest

from splitcam.training.schedule import learning_rate, progress


def test_warmup_then_cosine_at_chosen_steps() -> None:
    steps, peak, warm = 1000, 5e-4, 100
    lr = [learning_rate("cosine", peak, s, warm, progress(s, steps)) for s in range(steps)]
    assert lr[0] == pytest.approx(peak / 100)
    assert lr[49] == pytest.approx(peak * 0.5 * 0.5 * (1 + math.cos(math.pi * 0.049)))
    assert lr[99] == pytest.approx(peak * 0.5 * (1 + math.cos(math.pi * 0.099)))
    assert lr[500] == pytest.approx(peak * 0.5)  # half way: cos(pi/2) = 0
    assert lr[999] < peak * 1e-4
    assert max(lr) <= peak
    assert all(a < b for a, b in zip(lr[:99], lr[1:100], strict=True))  # rising warm-up
    assert all(a >= b for a, b in zip(lr[100:], lr[101:], strict=False))  # then decaying


def test_constant_and_no_warmup() -> None:
    assert learning_rate("constant", 1e-4, 0, 0, 0.7) == 1e-4
    assert learning_rate("constant", 1e-4, 9, 10, 0.7) == pytest.approx(1e-4)
    assert learning_rate("constant", 1e-4, 4, 10, 0.0) == pytest.approx(0.5e-4)
    with pytest.raises(ValueError, match="unknown schedule"):
        learning_rate("linear", 1e-4, 0, 0, 0.0)


def test_time_limit_drives_the_decay_when_it_comes_first() -> None:
    assert progress(10, 1000, seconds=30.0, time_limit_s=60.0) == pytest.approx(0.5)
    assert progress(900, 1000, seconds=30.0, time_limit_s=60.0) == pytest.approx(0.9)
    assert progress(10, 1000, seconds=120.0, time_limit_s=60.0) == 1.0
    assert progress(10, 1000) == pytest.approx(0.01)
