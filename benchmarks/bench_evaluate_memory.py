"""Peak memory and time of evaluating one large image: today's path against the untiled one.

    python benchmarks/bench_evaluate_memory.py [--size 6000x4000] [--pattern D] [--sigma 15]

Each variant runs in a fresh process (its peak resident memory is the process's ``ru_maxrss``),
one after the other, on the same random-but-smooth image:

- ``current``: what ``splitcam evaluate`` does per image and sigma
  (:func:`splitcam.evaluation.protocol.simulate_and_reconstruct` + :func:`score`): LMMSE in
  tiles, metrics strip by strip on uint8 images;
- ``untiled``: the path before (written out here as the baseline): the same simulation, the
  LMMSE filters applied to the whole image at once, and PSNR, SSIM (scikit-image) and CIEDE2000
  on whole float64 copies of both images.

Prints both, the ratios, and checks that the two give the same scores.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np
import torch
from common import machine


def _image(h: int, w: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    small = torch.rand(1, 3, h // 16 + 1, w // 16 + 1, generator=g)
    big = torch.nn.functional.interpolate(small, size=(h, w), mode="bilinear")
    return (big[0] + 0.02 * torch.rand(3, h, w, generator=g)).clamp(0, 1)


def run_variant(variant: str, h: int, w: int, pattern: str, sigma: float) -> dict:
    from splitcam.evaluation.metrics import SSIM_K1, SSIM_K2, SSIM_SIGMA, SSIM_WINDOW
    from splitcam.evaluation.protocol import score, simulate_and_reconstruct
    from splitcam.physics.sensor import SplitterSensor
    from splitcam.physics.system import simulate
    from splitcam.recon.lmmse import apply_filters
    from splitcam.recon.registry import build_method

    rgb = _image(h, w)
    method = build_method("lmmse", pattern=pattern)
    sensor = SplitterSensor(method.pattern)
    t0 = time.perf_counter()
    if variant == "current":
        pred = simulate_and_reconstruct(method, sensor, "bench", rgb, sigma)
        values = score(pred, rgb)
    else:
        from skimage.metrics import structural_similarity

        from splitcam.evaluation.metrics import delta_e_ciede2000, quantize, srgb_to_lab

        raw = simulate(sensor, rgb[None], "bench", sigma)
        weights, bias = method.statistics.filters(sigma)
        pred = apply_filters(raw, weights, bias, method.pattern.period)[0].clamp(0, 1)
        xq, yq = quantize(pred), quantize(rgb)
        mse = float(np.mean((xq - yq) ** 2))
        ssim = structural_similarity(
            xq,
            yq,
            win_size=SSIM_WINDOW,
            gaussian_weights=True,
            sigma=SSIM_SIGMA,
            use_sample_covariance=False,
            data_range=255.0,
            channel_axis=0,
            K1=SSIM_K1,
            K2=SSIM_K2,
        )
        lab_x = srgb_to_lab(np.moveaxis(xq, 0, -1))
        lab_y = srgb_to_lab(np.moveaxis(yq, 0, -1))
        values = {
            "psnr": 10 * np.log10(255.0**2 / mse),
            "ssim": float(ssim),
            "ciede2000": float(np.mean(delta_e_ciede2000(lab_x, lab_y))),
        }
    seconds = time.perf_counter() - t0
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {
        "variant": variant,
        "seconds": seconds,
        "peak_mb": peak_mb,
        **{k: float(v) for k, v in values.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="6000x4000", help="WIDTHxHEIGHT")
    parser.add_argument("--pattern", default="D")
    parser.add_argument("--sigma", type=float, default=15.0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--variant", help=argparse.SUPPRESS)
    args = parser.parse_args()
    w, h = (int(v) for v in args.size.lower().split("x"))
    torch.set_num_threads(args.threads)
    if args.variant:
        print(json.dumps(run_variant(args.variant, h, w, args.pattern, args.sigma)))
        return
    results = {}
    for variant in ("untiled", "current"):
        out = subprocess.run(
            [
                sys.executable,
                __file__,
                "--variant",
                variant,
                "--size",
                args.size,
                "--pattern",
                args.pattern,
                "--sigma",
                str(args.sigma),
                "--threads",
                str(args.threads),
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        results[variant] = json.loads(out.stdout.strip().splitlines()[-1])
    old, new = results["untiled"], results["current"]
    print(f"machine: {machine()}")
    print(
        f"one {w}x{h} image, LMMSE of {args.pattern}, sigma {args.sigma:g}, "
        f"{args.threads} threads, each variant in a fresh process"
    )
    print("| variant | peak memory | time | PSNR | SSIM | CIEDE2000 |")
    print("|---|---|---|---|---|---|")
    for r in (old, new):
        print(
            f"| {r['variant']} | {r['peak_mb'] / 1024:.2f} GiB | {r['seconds']:.1f} s "
            f"| {r['psnr']:.4f} | {r['ssim']:.5f} | {r['ciede2000']:.4f} |"
        )
    print(
        f"ratio untiled / current: memory {old['peak_mb'] / new['peak_mb']:.1f}x, "
        f"time {old['seconds'] / new['seconds']:.2f}x"
    )
    same = all(
        abs(old[k] - new[k]) < 1e-6 * max(1, abs(old[k])) for k in ("psnr", "ssim", "ciede2000")
    )
    print("scores identical: " + ("yes" if same else "NO"))


if __name__ == "__main__":
    main()
