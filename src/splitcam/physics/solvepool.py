"""Full-wave solves of one layer spread over worker processes.

The solves of a router's spectra (every wavelength in every direction of a lens's cone: 42 for
six wavelengths behind f/2) are independent of each other given the layer, so they can run in
processes of one thread each: :func:`splitcam.physics.fullwave.quadrant_spectra` takes the ones
its log lacks in order as they come back, and a design step
(:class:`splitcam.design.fullwave.FullwaveDesign`) takes them in two rounds:

1. **forward**: each worker solves its share without keeping any intermediate and sends back
   the quadrant transmissions (``(2, 2, 2)``) and the reflection;
2. **backward**: given the loss's gradient with respect to each solve's outputs (a cotangent),
   each worker solves its share again with the gradient tape on and sends back the
   vector-Jacobian product, a density-shaped array; the parent sums them.

That is the work one process does too (it holds no solve's intermediates between the passes
either, and solves again in the backward), with the same spectra and, to rounding in the sum,
the same gradient (tested). What it saves depends on how much of the machine one process
already uses: torcwa with one thread keeps one core busy, while fmmax's JAX spreads some of
its work over more cores by itself (docs/results/fullwave/README.md gives the measured
steps). Processes are spawned, not forked: JAX is multithreaded, and a fork of it may hang. A
worker that dies ends the work with an error; a design run continues from its last saved step,
and a logged solve run from its log, when started again.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from itertools import repeat
from typing import Any

import numpy as np
import torch

__all__ = ["SolvePool", "pooled_solves"]

#: One solve: ``(setting, density, wavelength nm, polar angle, azimuth)`` → ``((2, 2, 2)``
#: quadrant transmissions, reflection``)``, torch float64, differentiable in ``density``.
Solve = Callable[[Any, torch.Tensor, float, float, float], tuple[torch.Tensor, torch.Tensor]]

_WORKER: dict[str, Any] = {}


def _start_worker(solve: Solve, setting: Any, threads: int) -> None:
    torch.set_num_threads(threads)
    _WORKER.update(solve=solve, setting=setting)


def _forward(
    density: np.ndarray, job: tuple[float, float, float]
) -> tuple[np.ndarray, float, float]:
    start = time.perf_counter()
    with torch.no_grad():
        quads, reflected = _WORKER["solve"](_WORKER["setting"], torch.from_numpy(density), *job)
    return quads.numpy(), float(reflected), time.perf_counter() - start


def _pullback(
    density: np.ndarray, job: tuple[float, float, float], d_quads: np.ndarray, d_reflected: float
) -> np.ndarray:
    d = torch.from_numpy(density).requires_grad_(True)
    quads, reflected = _WORKER["solve"](_WORKER["setting"], d, *job)
    cotangents = [torch.from_numpy(d_quads), torch.tensor(d_reflected, dtype=reflected.dtype)]
    torch.autograd.backward([quads, reflected.reshape(())], cotangents)
    return np.zeros_like(density) if d.grad is None else d.grad.numpy()


class SolvePool:
    """Worker processes that each run ``solve`` for one setting (the stack and the solver's
    terms), one thread each.

    Args:
        solve: A module-level function (it is sent to the workers by name).
        setting: Its first argument, the same for every solve (picklable).
        workers: Processes, >= 2 to be of use.
        threads: Threads per worker.
    """

    def __init__(self, solve: Solve, setting: Any, workers: int, threads: int = 1) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.workers = int(workers)
        self._executor = ProcessPoolExecutor(
            self.workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_start_worker,
            initargs=(solve, setting, threads),
        )

    def solutions(
        self, density: np.ndarray, jobs: Sequence[tuple[float, float, float]]
    ) -> Iterator[tuple[np.ndarray, float, float]]:
        """Each job's ``(quadrants, reflection, seconds of solving)``, in the order of
        ``jobs``, each as soon as it and the ones before it are done."""
        return self._executor.map(_forward, repeat(density), jobs)

    def forward(
        self, density: np.ndarray, jobs: Sequence[tuple[float, float, float]]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Every job's quadrants ``(J, 2, 2, 2)`` and reflection ``(J,)`` (float64)."""
        solved = list(self.solutions(density, jobs))
        quads = torch.from_numpy(np.stack([q for q, _, _ in solved]))
        return quads, torch.tensor([r for _, r, _ in solved], dtype=torch.float64)

    def pullback(
        self,
        density: np.ndarray,
        jobs: Sequence[tuple[float, float, float]],
        d_quads: np.ndarray,
        d_reflected: np.ndarray,
    ) -> np.ndarray:
        """The sum over jobs of each solve's vector-Jacobian product with its cotangent
        (``d_quads[j]``, ``d_reflected[j]``)."""
        grads = self._executor.map(
            _pullback, repeat(density), jobs, list(d_quads), [float(r) for r in d_reflected]
        )
        return np.sum(list(grads), axis=0)

    def close(self) -> None:
        """Stop the workers."""
        self._executor.shutdown(wait=True, cancel_futures=True)


class _Pooled(torch.autograd.Function):
    @staticmethod
    def forward(ctx, density, pool, jobs):  # noqa: ANN001, ANN205 - torch's signature
        ctx.pool, ctx.jobs = pool, jobs
        ctx.save_for_backward(density)
        return pool.forward(density.detach().numpy(), jobs)

    @staticmethod
    def backward(ctx, d_quads, d_reflected):  # noqa: ANN001, ANN205
        (density,) = ctx.saved_tensors
        grad = ctx.pool.pullback(
            density.detach().numpy(), ctx.jobs, d_quads.numpy(), d_reflected.numpy()
        )
        return torch.from_numpy(grad).to(density), None, None


def pooled_solves(
    pool: SolvePool, density: torch.Tensor, jobs: Sequence[tuple[float, float, float]]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Every job ``(wavelength, polar angle, azimuth)`` solved by ``pool``: ``(J, 2, 2, 2)``
    quadrant transmissions and ``(J,)`` reflections, differentiable in ``density`` (float64)."""
    if not (density.requires_grad and torch.is_grad_enabled()):
        return pool.forward(density.detach().numpy(), list(jobs))
    return _Pooled.apply(density, pool, list(jobs))
