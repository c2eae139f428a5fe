"""Training-free baselines on Kodak24 + McMaster: LMMSE for every pattern, classical demosaicking.

Fits LMMSE (radius 4, default patches) for A, B, C, D, E and bayer on ``data/train``, scores it
on Kodak24 and McMaster (42 images) at sigma 0 and 10 with PSNR, SSIM and CIEDE2000 (model.md
§7, no border crop), and scores bilinear, Malvar 2004 and Menon 2007 demosaicking of the
bayer raw image at sigma 0. Also prints PSNR with a 10-pixel border crop at sigma 0, the
convention of published demosaicking tables (Malvar 2004: 35.78 dB Kodak, 34.43 dB McMaster), and
the paper's trained-network figures (model.md §8) for context. Nothing is fitted or tuned on
the test images.

    python benchmarks/bench_lmmse.py [--max-images N] [--sigmas 0 10] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from common import SHARED_DATA, machine

from splitcam import patterns
from splitcam.data.patches import ImageCache, load_validation
from splitcam.evaluation.metrics import mean_over_images
from splitcam.evaluation.screening import evaluate_method, screen_patterns
from splitcam.recon.demosaic import ClassicalDemosaic
from splitcam.recon.lmmse import DEFAULT_PATCHES, DEFAULT_RADIUS

PATTERNS = ["A", "B", "C", "D", "E", "bayer"]
CLASSICAL = ClassicalDemosaic.METHODS
SETS = ("kodak24", "mcmaster")
CROP = 10
#: Published Malvar 2004 PSNR with a 10-pixel border crop (Kodak, McMaster).
MALVAR_PUBLISHED = {"kodak24": 35.78, "mcmaster": 34.43}
#: Paper Table 1 (trained network, mean over the 42 images), model.md §8: PSNR per sigma.
PAPER_NET = {
    "A": {0: 40.02, 5: 37.58, 10: 35.72, 15: 34.44, 20: 33.47},
    "B": {0: 32.93, 5: 32.70, 10: 32.33, 15: 31.93, 20: 31.54},
    "C": {0: 31.53, 5: 31.37, 10: 31.08, 15: 30.77, 20: 30.45},
    "D": {0: 40.35, 5: 38.56, 10: 36.62, 15: 35.17, 20: 34.02},
    "E": {0: 35.65, 5: 34.84, 10: 33.89, 15: 33.08, 20: 32.37},
}


def _mean(rows: list[dict[str, Any]], keys: tuple[str, ...]) -> dict[str, float]:
    return {k: mean_over_images(r[k] for r in rows).mean for k in keys}


def _means(rows: list[dict[str, Any]], sets: dict[str, str], keys: tuple[str, ...]) -> dict:
    """Means over each test set and over all images."""
    out = {"all": _mean(rows, keys)}
    for name in SETS:
        part = [r for r in rows if sets[r["image"]] == name]
        if part:
            out[name] = _mean(part, keys)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--max-images", type=int, default=None, help="use only the first N images of each test set"
    )
    parser.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 10.0])
    parser.add_argument("--patches", type=int, default=DEFAULT_PATCHES)
    parser.add_argument("--radius", type=int, default=DEFAULT_RADIUS)
    parser.add_argument("--json", default=None, help="also write every figure to this file")
    args = parser.parse_args()
    start = time.perf_counter()
    print(machine())

    tests: list = []
    sets: dict[str, str] = {}
    for name in SETS:
        for stem, img in load_validation(SHARED_DATA / name, max_images=args.max_images):
            tests.append((stem, img))
            sets[stem] = name
    counts = {s: sum(v == s for v in sets.values()) for s in SETS}
    print(
        f"test images: {counts}; sigmas {args.sigmas}; LMMSE radius {args.radius}, "
        f"{args.patches} patches of 48x48 from data/train"
    )

    t0 = time.perf_counter()
    cache = ImageCache(SHARED_DATA / "train", min_size=48, progress=False)
    decode = time.perf_counter() - t0
    keys = ("psnr", "ssim", "ciede2000", f"psnr_crop{CROP}")
    screen = screen_patterns(
        [patterns.get(name) for name in PATTERNS],
        cache,
        tests,
        args.sigmas,
        radius=args.radius,
        patches=args.patches,
        psnr_crops=(CROP,),
    )
    entries = []  # (pattern, method, sigma, means, per-image rows)
    for pattern in PATTERNS:
        for sigma in args.sigmas:
            rows = [r for r in screen.per_image if r["pattern"] == pattern and r["sigma"] == sigma]
            entries.append((pattern, "lmmse", sigma, _means(rows, sets, keys), rows))
    classical_seconds = {}
    for method_name in CLASSICAL:
        t1 = time.perf_counter()
        rows = evaluate_method(ClassicalDemosaic(method_name), tests, [0.0], psnr_crops=(CROP,))
        classical_seconds[method_name] = time.perf_counter() - t1
        entries.append(("bayer", method_name, 0.0, _means(rows, sets, keys), rows))

    for sigma in args.sigmas:
        group = sorted((e for e in entries if e[2] == sigma), key=lambda e: -e[3]["all"]["psnr"])
        print(f"\nsigma = {sigma:g}  (no crop; mean over images; rank by PSNR over all images)")
        print(
            f"{'pattern':8} {'method':11} {'Kodak':>6} {'McM':>6} {'all':>6} {'SSIM':>7} "
            f"{'dE00':>5} {'rank':>4} {'Kodak/c10':>9} {'McM/c10':>8} {'paper net':>9}"
        )
        for place, (pattern, method_name, _, means, _rows) in enumerate(group, start=1):
            paper = PAPER_NET.get(pattern, {}).get(int(sigma)) if method_name == "lmmse" else None
            nan = {k: float("nan") for k in keys}
            kodak = means.get("kodak24", nan)
            mcm = means.get("mcmaster", nan)
            crop_key = f"psnr_crop{CROP}"
            print(
                f"{pattern:8} {method_name:11} {kodak['psnr']:6.2f} {mcm['psnr']:6.2f} "
                f"{means['all']['psnr']:6.2f} {means['all']['ssim']:7.4f} "
                f"{means['all']['ciede2000']:5.2f} {place:4d} {kodak[crop_key]:9.2f} "
                f"{mcm[crop_key]:8.2f} {'' if paper is None else f'{paper:.2f}':>9}"
            )
        if sigma == 0:
            print(
                f"published Malvar 2004 (crop {CROP}): Kodak {MALVAR_PUBLISHED['kodak24']:.2f}, "
                f"McMaster {MALVAR_PUBLISHED['mcmaster']:.2f}"
            )

    print(
        "\ntimes (s): decode data/train once "
        f"{decode:.1f}; per pattern LMMSE fit (incl. solving the filters) / evaluation "
        "(all sigmas; of which sensor+noise+reconstruction)"
    )
    for pattern in PATTERNS:
        rows = [r for r in screen.rows if r["pattern"] == pattern]
        recon = sum(r["seconds"] for r in screen.per_image if r["pattern"] == pattern)
        print(
            f"  {pattern:6} fit {rows[0]['fit_seconds']:5.1f}  eval "
            f"{sum(r['eval_seconds'] for r in rows):6.1f} (recon {recon:5.1f})"
        )
    for method_name, seconds in classical_seconds.items():
        recon = sum(r["seconds"] for e in entries if e[1] == method_name for r in e[4])
        print(f"  bayer {method_name:10} eval {seconds:6.1f} (recon {recon:5.1f})")
    total = time.perf_counter() - start
    print(f"total {total:.1f} s")

    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {
                    "machine": machine(),
                    "images": counts,
                    "sigmas": args.sigmas,
                    "patches": args.patches,
                    "radius": args.radius,
                    "total_seconds": total,
                    "decode_seconds": decode,
                    "results": [
                        {"pattern": p, "method": m, "sigma": s, "means": means, "per_image": rows}
                        for p, m, s, means, rows in entries
                    ],
                    "lmmse_rows": screen.rows,
                },
                fh,
                indent=1,
            )


if __name__ == "__main__":
    main()
