"""A full-wave design step in one process against the same step shared by worker processes.

    OMP_NUM_THREADS=1 python benchmarks/bench_design_workers.py [--workers 2] [--terms 97]

One step of ``splitcam optics rcwa-design`` (the loss and its gradient: every wavelength in
every direction of an f/2 cone solved, then solved again for its pullback) on the leaderboard
design's layer, fmmax Jones-direct, behind silicon and an IR cut, first with every solve in this
process (``FullwaveDesign(workers=1)``, one thread), then with the solves shared by ``W``
worker processes of one thread each (``workers=W``, :mod:`splitcam.design.solvepool`). Each
side is warmed up by one step first (fmmax's compilation, the workers' start, reported
apart). Prints seconds per step, the ratio, and the largest differences of the loss and the
gradient between the two. Run it on an otherwise idle machine with at least ``W`` cores.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from common import machine

from splitcam.design.fullwave import FullwaveDesign
from splitcam.physics.fullwave import RouterDesign, cone_directions, read_design
from splitcam.physics.stack import stack_of

DESIGN = Path(__file__).resolve().parents[1] / "experiments/fullwave/designs/best-240325.csv"


def _step(design: FullwaveDesign) -> tuple[float, float, np.ndarray]:
    theta = design.start().clone().requires_grad_(True)
    t0 = time.perf_counter()
    loss, _ = design.objective(theta, beta=32.0)
    loss.backward()
    return time.perf_counter() - t0, float(loss.detach()), theta.grad.numpy().copy()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--terms", type=int, default=97)
    parser.add_argument("--wavelengths", type=float, nargs="+", default=[467.0, 533.0, 633.0])
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    geometry = RouterDesign(read_design(DESIGN), thickness=0.699, depth=2.8)
    kw = dict(
        wavelengths=args.wavelengths,
        photons=30.0,
        directions=cone_directions(2.0),
        samples=16,
        radius=1.0,
        solver="fmmax-jones",
        terms=args.terms,
        optics=stack_of("silicon,ir-cut"),
    )
    solves = len(args.wavelengths) * len(kw["directions"])
    print(f"machine: {machine()}")
    print(
        f"leaderboard layer {geometry.grid.shape}, fmmax Jones-direct, {args.terms} terms, "
        f"{solves} solves a step (f/2), each solved twice (forward, pullback)"
    )
    seconds, results = {}, {}
    for workers in (1, args.workers):
        with FullwaveDesign(geometry, **kw, workers=workers) as design:
            first, *_ = _step(design)
            runs = [_step(design) for _ in range(args.repeat)]
        seconds[workers] = float(np.median([r[0] for r in runs]))
        results[workers] = runs[-1][1:]
        print(
            f"workers {workers}: first step {first:.1f} s (warm-up), then "
            f"{seconds[workers]:.1f} s a step (median of {args.repeat})"
        )
    one, many = results[1], results[args.workers]
    print(f"ratio (1 process / {args.workers} workers): {seconds[1] / seconds[args.workers]:.2f}x")
    print(
        f"largest differences: loss {abs(one[0] - many[0]):.2e}, gradient "
        f"{np.abs(one[1] - many[1]).max():.2e} (of {np.abs(one[1]).max():.2e})"
    )


if __name__ == "__main__":
    main()
