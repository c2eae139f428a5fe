"""A metasurface colour router from a height map: scalar wave optics to splitter kernels.

``splitcam.physics.optics`` turns the height map of dielectric pillars over a 2x2 pixel period
into the kernels of a pattern (angular-spectrum propagation to the photodiodes, weighted by the
colour channels' spectra), differentiable in the heights. Three height maps are compared: a
microlens over every pixel, random heights, and a router designed from the microlens for RGGB
collection (``splitcam.design.design_metasurface``, objective ``routing``). For each: the share
of red, green and blue light that reaches a pixel of its colour, the light collected, and the
closed-form LMMSE PSNR of the resulting pattern. Writes ``heights.png`` (the three height maps)
and ``router.png`` (where the designed router sends each colour).

    python examples/06_metasurface_router.py [--out DIR] [--tiny]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from splitcam import patterns
from splitcam.design import closed_form_psnr, design_metasurface
from splitcam.physics.optics import Optics, bayer_collection, pattern_of, profile
from splitcam.viz.patterns import draw_height_maps, draw_pattern

PERIOD = (2, 2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples-out/06", help="output folder")
    parser.add_argument("--tiny", action="store_true", help="coarse grid, 3 design steps")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    # pitch 1 µm, 2 µm above the photodiodes, n = 2 pillars up to 1.2 µm in air; samples: grid
    # points per pixel and axis (5 is the coarsest that resolves 400 nm; 8 is the default)
    # (tiny: 3 wavelengths instead of 16, 400-700 nm every 20 nm)
    if args.tiny:
        optics = Optics(samples=5, distance=2.0, wavelengths=[420.0, 540.0, 660.0])
    else:
        optics = Optics(samples=8, distance=2.0)
    steps = 3 if args.tiny else 150
    design = design_metasurface(PERIOD, optics, init="lens", steps=steps, objective="routing")
    heights = {
        "microlens": profile("lens", PERIOD, optics),
        "random": profile("random", PERIOD, optics, seed=0),
        f"designed ({steps} steps)": design.height,
    }
    print("height map            R/G/B to own colour   white   LMMSE PSNR σ=10 (dB)")
    for title, height in heights.items():
        pattern = pattern_of(height, PERIOD, optics, name=title)
        collect = bayer_collection(pattern)
        white = patterns.measure(pattern).white
        psnr = float(closed_form_psnr(pattern, [10.0])[0])
        cells = "/".join(f"{100 * c:.0f}" for c in collect)
        print(f"{title:<22}{cells + ' %':>20}   {white:5.2f}   {psnr:8.2f}")
    print(f"design took {design.seconds:.1f} s")

    path = draw_height_maps(
        [(t, h.numpy()) for t, h in heights.items()],
        out / "heights.png",
        period=PERIOD,
        pitch=optics.pitch,
        max_height=optics.max_height,
    )
    patterns.save(design.pattern, out / "router.toml")
    draw_pattern(design.pattern, out / "router.png")
    print(f"wrote {path}, {out / 'router.png'} and {out / 'router.toml'}")


if __name__ == "__main__":
    main()
