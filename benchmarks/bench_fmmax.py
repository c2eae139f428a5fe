"""fmmax's periodic solve compiled once against the same solve run op by op, in one run.

    OMP_NUM_THREADS=1 python benchmarks/bench_fmmax.py [--terms 357] [--wavelengths 450 550 650]

``splitcam.physics.fullwave`` compiles fmmax's solve of a design (``jax.jit``) with the
wavelength, permittivities and direction traced, so one compilation serves every wavelength and
direction of a run. The baseline is the same function under ``jax.disable_jit()`` (every
operation dispatched on its own, as the solver ran before). Both solve the Zou router at each
wavelength, normal incidence; the compiled side's first solve (the compilation) is reported
apart. Prints seconds per solve, the ratio, and the largest difference in the quadrant
transmissions (the two orders of floating-point operations). Also times the compiled value and
gradient of a scalar of the transmissions with respect to the cell densities (what
``splitcam.design.fullwave`` asks per wavelength and step).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from common import machine

from splitcam.physics import fullwave

DESIGN = Path(__file__).resolve().parents[1] / "experiments/fullwave/designs/zou2022-16x16.csv"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--terms", type=int, default=357)
    parser.add_argument("--wavelengths", type=float, nargs="+", default=[450.0, 550.0, 650.0])
    parser.add_argument("--samples", type=int, default=16)
    args = parser.parse_args()
    import jax
    import jax.numpy as jnp

    design = fullwave.RouterDesign(grid=fullwave.read_design(DESIGN))
    core, n = fullwave._fmmax_core(design, args.terms, "JONES_DIRECT", args.samples)
    grid = jnp.asarray(design.grid)
    print(f"machine: {machine()}")
    print(f"Zou router, fmmax Jones-direct, {n} terms, {len(args.wavelengths)} wavelengths")

    eager, results = [], {}
    with jax.disable_jit():
        for lam in args.wavelengths:
            t0 = time.perf_counter()
            results[lam] = np.asarray(core(grid, lam, 0.0, 0.0)[0])
            eager.append(time.perf_counter() - t0)
    compiled, first, diff = [], None, 0.0
    for lam in args.wavelengths:
        t0 = time.perf_counter()
        quads = np.asarray(core(grid, lam, 0.0, 0.0)[0])
        seconds = time.perf_counter() - t0
        if first is None:
            first = seconds
        else:
            compiled.append(seconds)
        diff = max(diff, float(np.abs(quads - results[lam]).max()))
    weights = jnp.asarray(np.random.default_rng(0).normal(size=(2, 2, 2)))
    value_and_grad = jax.value_and_grad(
        lambda x, lam: (core(x, lam, 0.0, 0.0)[0] * weights).sum(), argnums=0
    )
    gradient = []
    for lam in args.wavelengths:
        t0 = time.perf_counter()
        jax.block_until_ready(value_and_grad(grid, lam))
        gradient.append(time.perf_counter() - t0)
    op_by_op = float(np.mean(eager))
    steady = float(np.mean(compiled)) if compiled else float("nan")
    print(f"op by op: {op_by_op:.1f} s per solve")
    print(f"compiled: first {first:.1f} s (with the compilation), then {steady:.1f} s per solve")
    print(f"ratio op by op / compiled: {op_by_op / steady:.1f}x")
    print(f"value and gradient, compiled: {np.mean(gradient[1:] or gradient):.1f} s per solve")
    print(f"largest difference in the transmissions: {diff:.1e}")


if __name__ == "__main__":
    main()
