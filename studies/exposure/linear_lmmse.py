"""Closed-form LMMSE at sigma 0 in the srgb and the linear domain, patterns D and bayer, on the
last 6 training images (sorted by name; inside the 32 that training and the image statistics
leave out): ``OMP_NUM_THREADS=1 python studies/exposure/linear_lmmse.py [TRAIN_DIR]``."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import torch

from splitcam import patterns
from splitcam.data.imageio import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.evaluation import evaluate, summarise
from splitcam.recon.closed_form import closed_form_lmmse

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    train = Path(sys.argv[1]) if len(sys.argv) > 1 else training_folder()
    files = list_images(train)[-6:]
    images = [(f.stem, torch.from_numpy(read_image(f)).permute(2, 0, 1)) for f in files]
    print("images:", ", ".join(n for n, _ in images))
    for domain in ("srgb", "linear"):
        t0 = time.perf_counter()
        methods = []
        for pattern in ("D", "bayer"):
            method = closed_form_lmmse(patterns.get(pattern), domain=domain)
            method.name = f"lmmse-{pattern}"
            methods.append(method)
        rows = evaluate(methods, [("train-last6", images)], [0.0], progress=False, domain=domain)
        summary = summarise(rows)
        for label, entry in summary.items():
            st = entry["all"]["0"]
            print(
                f"| {domain} | {label} | {st['psnr']:.2f} | {st['ssim']:.4f} | "
                f"{st['ciede2000']:.3f} |"
            )
        print(f"({domain}: {time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
