"""Filters against routers at equal light: image quality against exposure, photon noise.

``splitcam.evaluation.exposure.exposure_study`` simulates every pattern under the same photon
flux, from a few to thousands of photo-electrons per full-light pixel (shot noise and 2 e- read
noise), in linear light (scenes decoded to radiance before the sensor and the noise), and scores
each pattern's closed-form LMMSE (its filters solved for the signal-dependent noise). Filters
absorb light (Bayer keeps a third, RGBW two thirds); routers move it. Writes
``exposure.png`` (PSNR and CIEDE2000 against exposure) and prints where each pattern overtakes
the Bayer filter.

    python examples/05_filters_vs_routers.py [--out DIR] [--tiny]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from splitcam import patterns
from splitcam.data.testsets import centre_crop, default_images
from splitcam.evaluation.exposure import crossover, default_exposures, exposure_study
from splitcam.viz.charts import exposure_chart

PATTERNS = ["bayer", "rgbw", "router-zou", "D"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples-out/05", help="output folder")
    parser.add_argument("--tiny", action="store_true", help="2 small images, 3 exposures")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    size, count = (48, 2) if args.tiny else (256, 6)
    images = [(n, centre_crop(im, size)) for n, im in default_images()[:count]]
    photons = [3.0, 100.0, 3000.0] if args.tiny else default_exposures(9)
    results = exposure_study(
        images,
        patterns=[patterns.get(p) for p in PATTERNS],
        photons=photons,
        read_noise=2.0,
        domain="linear",
        progress=False,
    )

    print("photo-electrons  " + "  ".join(f"{p:>10}" for p in PATTERNS) + "   (PSNR, dB)")
    for n in photons:
        print(f"{n:15.1f}  " + "  ".join(f"{results[p][n]['psnr']:10.2f}" for p in PATTERNS))
    bayer = {n: v["psnr"] for n, v in results["bayer"].items()}
    for p in PATTERNS[1:]:
        x = crossover({n: v["psnr"] for n, v in results[p].items()}, bayer)
        where = (
            "never"
            if x is None
            else "at every exposure"
            if math.isinf(x)
            else f"below {x:.0f} photo-electrons"
        )
        print(f"{p} beats the Bayer filter {where}")
    path = exposure_chart(
        results, out / "exposure.png", title="Closed-form LMMSE at equal light (linear domain)"
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
