"""Learning-rate schedules: linear warm-up, then constant or cosine decay to zero.

The learning rate is a pure function of where the run stands (:func:`learning_rate`), never a
state that is stepped, so a resumed run continues exactly where it stopped: the trainer only has
to restore the step and the training time already spent. A run ends at ``steps`` steps or at its
time limit, whichever comes first; the cosine decays over that same span, so a run limited by
time ends at a learning rate of zero too.
"""

from __future__ import annotations

import math

__all__ = ["SCHEDULES", "learning_rate", "progress", "scaled_lr"]

#: Names accepted by :func:`learning_rate`.
SCHEDULES = ("constant", "cosine")


def progress(
    step: int, steps: int, seconds: float = 0.0, time_limit_s: float | None = None
) -> float:
    """How far the run is, in [0, 1]: the larger of the step and the time fractions.

    Args:
        step: Optimiser steps done.
        steps: Steps the run may take.
        seconds: Training time spent so far (all processes of the run together).
        time_limit_s: The run's time limit in seconds, if any.
    """
    frac = step / steps if steps > 0 else 1.0
    if time_limit_s:
        frac = max(frac, seconds / time_limit_s)
    return min(1.0, max(0.0, frac))


def learning_rate(
    kind: str, peak: float, step: int, warmup_steps: int, run_progress: float
) -> float:
    """The learning rate to use for step ``step`` (counting from 0).

    ``peak * warm-up * decay``: the warm-up rises linearly over the first ``warmup_steps`` steps,
    ``(step + 1) / warmup_steps``, then stays 1; the decay is 1 (``constant``) or
    ``(1 + cos(pi * run_progress)) / 2`` (``cosine``).

    Raises:
        ValueError: An unknown ``kind``.
    """
    if kind not in SCHEDULES:
        raise ValueError(f"unknown schedule {kind!r}; expected one of {', '.join(SCHEDULES)}")
    warm = min(1.0, (step + 1) / warmup_steps) if warmup_steps > 0 else 1.0
    decay = 1.0 if kind == "constant" else 0.5 * (1.0 + math.cos(math.pi * run_progress))
    return peak * warm * decay


def scaled_lr(lr: float, batch: int, new_batch: int) -> float:
    """The peak learning rate for ``new_batch`` of a recipe tuned at ``lr`` and ``batch``: the
    square-root rule, ``lr * sqrt(new_batch / batch)``.

    The rule for Adam (Malladi et al., "On the SDEs and Scaling Rules for Adaptive Gradient
    Algorithms", NeurIPS 2022; Hoffer et al. 2017); the linear rule (Goyal et al. 2017) is
    SGD's. Checked here at batch 64 against batch 8 at equal patches seen on the CPU
    (docs/results/batch/); the warm-up is left in steps, which at a larger batch covers more
    patches.

    >>> round(scaled_lr(1e-3, 8, 64), 6)
    0.002828
    """
    if batch < 1 or new_batch < 1:
        raise ValueError(f"batch sizes must be >= 1, got {batch} and {new_batch}")
    return lr * math.sqrt(new_batch / batch)
