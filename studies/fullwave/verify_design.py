"""A designed router against the design it started from, both solved at the verification setting:
band efficiencies and the closed-form LMMSE PSNR at several exposures.

    python studies/fullwave/verify_design.py DESIGNED-spectra.csv START-spectra.csv \
        [--photons 10 30 100 300 1000] [--read-noise 2] [--stack silicon,ir-cut]

Each file is the ``NAME-spectra.csv`` that ``splitcam optics rcwa`` writes, or a spectral
pattern file of transmissions (``.toml``); the same solver, terms and wavelengths for both. The
PSNR is :meth:`splitcam.design.fullwave.FullwaveDesign.image_error` of the spectra: the expected
error of the closed-form LMMSE in linear light under the photon model, away from image borders,
no images needed. ``--stack``: every pixel behind that optical stack (as the design loss with
``rcwa-design --stack`` and the exposure study see it); the efficiencies stay the router's own.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import torch

from splitcam.design.fullwave import FullwaveDesign
from splitcam.patterns import read as read_pattern
from splitcam.physics.fullwave import RouterDesign, band_efficiencies


def spectra(path: Path) -> tuple[list[float], np.ndarray]:
    if path.suffix == ".toml":  # a spectral pattern file given by its transmissions
        info = read_pattern(str(path)).pattern.metadata
        if "transmission" not in info:
            raise SystemExit(f"{path}: a pattern given by its kernels, not its transmissions")
        lams = [float(v) for v in info["spectral"]["wavelengths"]]
        return lams, np.clip(np.asarray(info["transmission"], dtype=float), 0.0, None)
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    lams = rows[:, 0].tolist()
    t = rows[:, 1:5].T.reshape(2, 2, -1)  # T_row0_col0, T_row0_col1, T_row1_col0, T_row1_col1
    return lams, np.clip(t, 0.0, None)


def psnr_at(lams, t: np.ndarray, photons, read_noise: float = 2.0, optics=None) -> list[float]:
    """The closed-form LMMSE PSNR (dB) of a router with ``(2, 2, L)`` transmissions ``t`` at
    each exposure in ``photons``, every pixel behind ``optics`` where given."""
    out = []
    for n in photons:
        design = FullwaveDesign(
            RouterDesign(np.eye(2)),
            wavelengths=list(lams),
            photons=float(n),
            read_noise=read_noise,
            optics=optics,
        )
        with torch.no_grad():
            mse = float(design.image_error(torch.as_tensor(np.asarray(t, dtype=np.float64))))
        out.append(-10 * math.log10(mse))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("designed", type=Path)
    parser.add_argument("start", type=Path)
    parser.add_argument("--photons", type=float, nargs="+", default=[10, 30, 100, 300, 1000])
    parser.add_argument("--read-noise", type=float, default=2.0)
    parser.add_argument("--stack", help="comma-separated optical stack in front of every pixel")
    args = parser.parse_args()
    optics = None
    if args.stack:
        from splitcam.physics.stack import stack_of

        optics = stack_of(args.stack)
    if optics is not None:
        print(f"Every pixel behind {optics}.\n")
    print(
        "| router | blue / green / red band efficiency | "
        + " | ".join(f"LMMSE PSNR at N = {n:g}" for n in args.photons)
        + " |"
    )
    print("|---|---|" + "---|" * len(args.photons))
    for path in (args.start, args.designed):
        lams, t = spectra(path)
        bands = band_efficiencies(t, lams)
        cells = [f"{p:.2f}" for p in psnr_at(lams, t, args.photons, args.read_noise, optics)]
        print(
            f"| {path.stem.removesuffix('-spectra')} | {bands['blue']:.3f} / "
            f"{bands['green']:.3f} / {bands['red']:.3f} | " + " | ".join(cells) + " |"
        )


if __name__ == "__main__":
    main()
