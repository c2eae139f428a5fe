"""Estimate the pattern-free image statistics shipped in ``src/splitcam/weights`` (closed-form
LMMSE of any pattern) on the training images, leaving out the last 32 (sorted by name), which
``train`` holds out for validation and the benchmarks score on:
``python scripts/estimate_image_statistics.py [--train DIR] [--held-out 32] [--domain linear]``.

``--domain srgb`` (default) writes ``image_statistics.{json,safetensors}`` (moments of the 8-bit
display values / 255); ``--domain linear`` writes ``image_statistics_linear.{json,safetensors}``
(moments of the linear radiance each image decodes to with the sRGB transfer function, model.md
§13). ``--every K`` keeps every K-th image of the training list (all by default); the
subsample is recorded in the file's ``info``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.io.domains import DOMAINS
from splitcam.recon.closed_form import SHIPPED_PATHS, estimate_image_statistics

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", default=str(training_folder()))
    parser.add_argument("--held-out", type=int, default=32)
    parser.add_argument("--domain", choices=DOMAINS, default="srgb")
    parser.add_argument("--every", type=int, default=1, help="use every K-th image (default 1)")
    parser.add_argument("--out", help="output path (default: the shipped file of the domain)")
    args = parser.parse_args()
    if args.every < 1:
        parser.error(f"--every must be at least 1, got {args.every}")
    files = list_images(args.train)
    files = files[: len(files) - args.held_out] if args.held_out else files
    files = files[:: args.every]
    t0 = time.perf_counter()
    stats = estimate_image_statistics(files, progress=True, domain=args.domain)
    seconds = time.perf_counter() - t0
    stats.info.update(
        {
            "images": len(files),
            "held_out": args.held_out,
            "first": files[0].name,
            "last": files[-1].name,
        }
    )
    if args.every > 1:
        stats.info["every"] = args.every
    path = stats.save(args.out or SHIPPED_PATHS[args.domain])
    print(f"{len(files)} images ({args.domain}), {seconds:.1f} s -> {path}")


if __name__ == "__main__":
    main()
