"""How far the RGB reduction of a spectral sensor is from the sensor itself on real spectra.

    python studies/spectral/metamerism.py [--patterns bayer-d5100,...] [--out FILE.md]

splitcam reduces a spectral pattern to RGB kernels exactly for scenes whose spectra are linear
in linear sRGB (splitcam.patterns.spectral). A real surface has its own spectrum, and two
surfaces of one colour (metamers) can give a pixel different signals. This script measures that
error on the 24 patches of the ColorChecker (the N. Ohta reflectances in colour-science) under
D65: for every patch and every pixel type of the pattern, the pixel's signal computed from the
patch's spectrum, wavelength by wavelength, against the signal of its RGB reduction given the
patch's linear sRGB colour (through the metamer of that colour in splitcam's scene family).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import colour
import numpy as np

from splitcam import patterns


def patch_spectra(grid: np.ndarray) -> tuple[list[str], np.ndarray]:
    """Names and reflectances ``(24, L)`` of the ColorChecker on ``grid``."""
    checker = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    names = list(checker)
    values = [np.interp(grid, checker[n].wavelengths, checker[n].values) for n in names]
    return names, np.array(values)


def linear_srgb(reflectance: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Linear sRGB under D65 of reflectances ``(N, L)`` (white: 1, 1, 1), on ``grid``."""
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    d65 = colour.SDS_ILLUMINANTS["D65"]
    xyz_bar = np.stack([np.interp(grid, cmfs.wavelengths, cmfs.values[:, i]) for i in range(3)], 1)
    light = np.interp(grid, d65.wavelengths, d65.values)
    xyz = (reflectance * light) @ xyz_bar / (light @ xyz_bar[:, 1])
    return colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False)


def errors(name: str) -> np.ndarray:
    """Relative error ``(24, pixel types)`` of the RGB reduction against the spectral signal."""
    pattern = patterns.get(name)
    spectral = pattern.metadata.get("spectral")
    if spectral is None:
        raise SystemExit(f"{name} is not a spectral pattern")
    grid = np.asarray(spectral["wavelengths"])
    kernels = np.asarray(spectral["kernels"]).sum(axis=(2, 3))  # (S, L): all light a splitter keeps
    rgb_kernels = pattern.kernels.sum(axis=(2, 3))  # (S, 3)
    from colour.recovery import MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019 as basis

    d65 = np.interp(
        grid, colour.SDS_ILLUMINANTS["D65"].wavelengths, colour.SDS_ILLUMINANTS["D65"].values
    )
    b = np.stack([np.interp(grid, basis.wavelengths, basis.values[:, c]) for c in range(3)], 1)
    n = (b * d65[:, None]).sum(axis=0)  # photons of each basis spectrum under D65
    _, reflectance = patch_spectra(grid)
    true = (reflectance * d65) @ kernels.T  # (24, S)
    # The patch's metamer in the scene family: linear sRGB times n (units of one basis each).
    reduced = (linear_srgb(reflectance, grid) * n) @ rgb_kernels.T
    return np.abs(reduced - true) / true


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--patterns", default="bayer-d5100,rgbw-d5100,bayer-sdmerrill")
    parser.add_argument("--out")
    args = parser.parse_args()
    lines = [
        "| pattern | mean error | largest error | patch and pixel of the largest |",
        "|---|---|---|---|",
    ]
    names, _ = patch_spectra(np.arange(400.0, 701.0, 10.0))
    for name in args.patterns.split(","):
        err = errors(name)
        i, s = np.unravel_index(int(err.argmax()), err.shape)
        lines.append(
            f"| {name} | {100 * err.mean():.2f} % | {100 * err.max():.2f} % | {names[i]}, "
            f"splitter {s} |"
        )
    text = "\n".join(lines)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
