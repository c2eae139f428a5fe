"""torcwa against fmmax on the Zou 2022 router: the same quadrant transmissions, side by side.

    python studies/fullwave/solvers.py [--orders 9 12] [--wavelengths 450,540,650]
        [--out FILE.md]

For each Fourier order, splitcam's solver (torcwa, :func:`splitcam.physics.fullwave.
quadrant_spectra`, ``(2 order + 1)^2`` terms) and fmmax (JAX, the invrs-gym Bayer sorter's
solver) at about the same number of terms, in fmmax's plain ``FFT`` formulation and its
``JONES_DIRECT`` vector formulation (faster convergence at sharp pillar edges), compute the
transmission into the blue pixel, both green pixels and the red pixel at normal incidence,
averaged over the two polarisations, and the seconds each took (one thread). fmmax is not a
dependency of splitcam: install it (``pip install fmmax``) to run this comparison.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

from splitcam.physics.fullwave import RouterDesign, index_of, quadrant_spectra, read_design

DESIGN = Path(__file__).resolve().parents[2] / "experiments" / "fullwave" / "designs"
#: Zou et al.'s supplementary figure 7 (blue / both green / red pixel).
PUBLISHED = {450: (0.436, 0.394, 0.133), 540: (0.160, 0.575, 0.237), 650: (0.117, 0.270, 0.589)}


def fmmax_quadrants(design: RouterDesign, lam: float, terms: int, formulation: str, samples=64):
    """``(2, 2)`` quadrant transmissions by fmmax, and its number of terms."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from fmmax import basis, fields, fmm, scattering

    period = 2 * design.pitch
    lattice = basis.LatticeVectors(u=basis.X * period, v=basis.Y * period)
    expansion = basis.generate_expansion(
        primitive_lattice_vectors=lattice,
        approximate_num_terms=terms,
        truncation=basis.Truncation.CIRCULAR,
    )
    eps_p = index_of(design.pillar, lam) ** 2
    eps_b = index_of(design.background, lam) ** 2
    eps_s = index_of(design.substrate, lam) ** 2
    up = max(1, int(np.ceil(256 / max(design.grid.shape))))
    fine = np.kron(design.grid, np.ones((up, up)))
    layer = jnp.asarray(eps_b + (eps_p - eps_b) * fine.T, dtype=complex)  # fmmax: [x, y]

    def solve(permittivity):
        return fmm.eigensolve_isotropic_media(
            wavelength=jnp.asarray(lam / 1000.0),
            in_plane_wavevector=jnp.zeros(2),
            primitive_lattice_vectors=lattice,
            permittivity=permittivity,
            expansion=expansion,
            formulation=getattr(fmm.Formulation, formulation),
        )

    ambient = solve(jnp.full((1, 1), eps_b, complex))
    meta = solve(layer)
    substrate = solve(jnp.full((1, 1), eps_s, complex))
    inner = scattering.stack_s_matrices_interior(
        [ambient, meta, substrate],
        [jnp.zeros(()), jnp.asarray(design.thickness), jnp.asarray(design.depth)],
    )
    n = expansion.num_terms
    forward = jnp.zeros((2 * n, 2), complex).at[0, 0].set(1.0).at[n, 1].set(1.0)
    amplitudes = fields.stack_amplitudes_interior(inner, forward, jnp.zeros_like(forward))
    f_sub, b_sub = amplitudes[2]
    f_end = fields.propagate_amplitude(f_sub, jnp.asarray(design.depth), substrate)
    shape = (2 * samples, 2 * samples)

    def flux(f, b, result):
        e, h = fields.fields_from_wave_amplitudes(f, b, result)
        (ex, ey, _), (hx, hy, _), _ = fields.fields_on_grid(e, h, result, shape, (1, 1))
        return 0.5 * jnp.real(ex * jnp.conj(hy) - ey * jnp.conj(hx))  # [x, y, polarisation]

    sz = flux(f_end, b_sub, substrate)
    incident = jnp.mean(flux(forward, jnp.zeros_like(forward), ambient), axis=(0, 1))
    s = np.asarray(sz / incident).transpose(1, 0, 2)  # [y, x, polarisation]
    quads = s.reshape(2, samples, 2, samples, 2).mean(axis=(1, 3)) / 4
    return quads.mean(axis=-1), int(n)


def split(q: np.ndarray) -> tuple[float, float, float]:
    """Blue (row 0, column 1), both greens, red (row 1, column 0), as the design file lies."""
    return float(q[0, 1]), float(q[0, 0] + q[1, 1]), float(q[1, 0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orders", type=int, nargs="+", default=[9, 12])
    parser.add_argument("--wavelengths", default="450,540,650")
    parser.add_argument("--out")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    design = RouterDesign(read_design(DESIGN / "zou2022-16x16.csv"))
    lams = [float(v) for v in args.wavelengths.split(",")]
    lines = [
        "| solver | terms | wavelength | blue / green / red | published | seconds |",
        "|---|---|---|---|---|---|",
    ]
    for order in args.orders:
        terms = (2 * order + 1) ** 2
        for lam in lams:
            ref = (
                "{:.3f} / {:.3f} / {:.3f}".format(*PUBLISHED[int(lam)])
                if int(lam) in PUBLISHED
                else ""
            )
            t0 = time.perf_counter()
            q = quadrant_spectra(design, [lam], order=order)["transmission"][:, :, 0]
            row = ["torcwa", str(terms), f"{lam:g}", "{:.3f} / {:.3f} / {:.3f}".format(*split(q))]
            lines.append("| " + " | ".join(row + [ref, f"{time.perf_counter() - t0:.0f}"]) + " |")
            print(lines[-1], flush=True)
            for formulation in ("FFT", "JONES_DIRECT"):
                t0 = time.perf_counter()
                q, n = fmmax_quadrants(design, lam, terms, formulation)
                row = [f"fmmax {formulation}", str(n), f"{lam:g}"]
                row.append("{:.3f} / {:.3f} / {:.3f}".format(*split(q)))
                lines.append(
                    "| " + " | ".join(row + [ref, f"{time.perf_counter() - t0:.0f}"]) + " |"
                )
                print(lines[-1], flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
