"""torcwa against fmmax on the Zou 2022 router: the same quadrant transmissions, side by side.

    python studies/fullwave/solvers.py [--orders 9 12] [--wavelengths 450,540,650]
        [--out FILE.md]

For each Fourier order, splitcam's solver (torcwa, :func:`splitcam.physics.fullwave.
quadrant_spectra`, ``(2 order + 1)^2`` terms) and fmmax (JAX, the invrs-gym Bayer sorter's
solver) at about the same number of terms, in fmmax's plain ``FFT`` formulation and its
``JONES_DIRECT`` vector formulation (faster convergence at sharp pillar edges), compute the
transmission into the blue pixel, both green pixels and the red pixel at normal incidence,
averaged over the two polarisations, and the seconds each took (one thread). fmmax is not a
dependency of splitcam: install it (``pip install 'splitcam[fmmax]'``) to run this comparison.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

from splitcam.physics.fullwave import RouterDesign, quadrant_spectra, read_design

DESIGN = Path(__file__).resolve().parents[2] / "experiments" / "fullwave" / "designs"
#: Zou et al.'s supplementary figure 7 (blue / both green / red pixel).
PUBLISHED = {450: (0.436, 0.394, 0.133), 540: (0.160, 0.575, 0.237), 650: (0.117, 0.270, 0.589)}


def fmmax_quadrants(design: RouterDesign, lam: float, terms: int, formulation: str):
    """``(2, 2)`` quadrant transmissions by fmmax (``FFT`` or ``JONES_DIRECT``), and its number
    of terms: :func:`~splitcam.physics.fullwave.quadrant_spectra` with an fmmax solver."""
    solver = "fmmax-jones" if formulation == "JONES_DIRECT" else "fmmax-fft"
    out = quadrant_spectra(design, [lam], solver=solver, terms=terms)
    return out["transmission"][:, :, 0], out["terms"]


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
