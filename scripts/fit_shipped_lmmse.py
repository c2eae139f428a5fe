"""Fit the LMMSE statistics shipped in ``src/splitcam/weights/lmmse`` (one per built-in pattern)
on the CBSD432 training images: ``python scripts/fit_shipped_lmmse.py [--train DIR]``."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from splitcam import patterns
from splitcam.data.patches import ImageCache
from splitcam.data.registry import training_folder
from splitcam.io.weights import LMMSE_DIR
from splitcam.recon.lmmse import LMMSE

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", default=str(training_folder()))
    args = parser.parse_args()
    cache = ImageCache(args.train, min_size=48)
    out = LMMSE_DIR
    out.mkdir(parents=True, exist_ok=True)
    for name in patterns.names():
        t0 = time.perf_counter()
        lmmse = LMMSE.fit(name, cache, seed=0)
        lmmse.save(out / f"{name}.safetensors")
        print(f"{name}: {time.perf_counter() - t0:.1f} s -> {out / name}.safetensors")


if __name__ == "__main__":
    main()
