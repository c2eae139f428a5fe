"""Estimate the pattern-free image statistics shipped in ``src/splitcam/weights`` (closed-form
LMMSE of any pattern) on the training images, leaving out the last 32 (sorted by name), which
``train`` holds out for validation and the benchmarks score on:
``python scripts/estimate_image_statistics.py [--train DIR] [--held-out 32]``."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from splitcam.data.patches import list_images
from splitcam.recon.closed_form import SHIPPED_PATH, estimate_image_statistics

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", default=str(ROOT.parent / "shared" / "data" / "train"))
    parser.add_argument("--held-out", type=int, default=32)
    args = parser.parse_args()
    files = list_images(args.train)
    files = files[: len(files) - args.held_out] if args.held_out else files
    t0 = time.perf_counter()
    stats = estimate_image_statistics(files, progress=True)
    stats.info.update(
        {
            "images": len(files),
            "held_out": args.held_out,
            "first": files[0].name,
            "last": files[-1].name,
        }
    )
    path = stats.save(SHIPPED_PATH)
    print(f"{len(files)} images, {time.perf_counter() - t0:.1f} s -> {path}")


if __name__ == "__main__":
    main()
