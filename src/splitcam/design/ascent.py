"""The one optimisation loop of pattern design: Adam ascent on an objective in dB (or any
figure of merit), with the history, the wall time and an optional progress bar.

Both designers (:func:`~splitcam.design.kernels.design_pattern` on kernel logits and
:func:`~splitcam.design.metasurface.design_metasurface` on a height map) are this loop over their
own parameters and objective.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterable, Iterator, Sequence

import torch

__all__ = ["ascend", "check_sigmas", "psnr_of"]


def psnr_of(mse: torch.Tensor) -> torch.Tensor:
    """``-10 log10(mse)``: the PSNR (dB) of an MSE in ``[0, 1]`` units, differentiable."""
    return -10.0 * torch.log10(mse)


def check_sigmas(sigmas: Iterable[float] | torch.Tensor) -> list[float]:
    """The noise levels as floats, each finite and >= 0 (8-bit units).

    Raises:
        ValueError: Not numbers, empty, or a level that is negative or not finite.
    """
    try:
        values = [float(s) for s in sigmas]
    except (TypeError, ValueError):
        raise ValueError(f"expected sigmas as numbers (8-bit units), got {sigmas!r}") from None
    if not values or any(not (math.isfinite(s) and s >= 0) for s in values):
        raise ValueError(f"expected one or more finite sigmas >= 0 (8-bit units), got {values}")
    return values


@contextlib.contextmanager
def intra_op_threads(threads: int | None) -> Iterator[None]:
    """Run with ``threads`` intra-op threads (``None``: leave as is), restored afterwards."""
    before = torch.get_num_threads()
    if threads is not None and threads != before:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)


def ascend(
    parameters: Sequence[torch.Tensor],
    value_of: Callable[[int], torch.Tensor],
    *,
    steps: int,
    lr: float,
    threads: int | None = None,
    progress: str | None = None,
    unit: str = "dB",
) -> tuple[list[float], float]:
    """Maximise ``value_of(step)`` over ``parameters`` with Adam for ``steps`` steps.

    Args:
        parameters: The tensors to optimise (``requires_grad``).
        value_of: The objective at a step (a scalar tensor, higher is better).
        steps: Adam steps.
        lr: Adam learning rate.
        threads: Intra-op threads during the loop (restored afterwards; ``None`` leaves them).
        progress: Description of a tqdm progress bar (``None``: no bar).
        unit: Label of the objective in the progress bar.

    Returns:
        The objective at every step (before that step's update) and the wall time in seconds.
    """
    bar = None
    if progress is not None:
        from tqdm.auto import tqdm

        bar = tqdm(total=steps, desc=progress, unit="step")
    history: list[float] = []
    began = time.perf_counter()
    with intra_op_threads(threads):
        optimizer = torch.optim.Adam(list(parameters), lr=lr)
        for step in range(steps):
            value = value_of(step)
            optimizer.zero_grad(set_to_none=True)
            (-value).backward()
            optimizer.step()
            history.append(value.item())
            if bar is not None:
                bar.set_postfix({unit: f"{history[-1]:.3f}"}, refresh=False)
                bar.update(1)
    if bar is not None:
        bar.close()
    return history, time.perf_counter() - began
