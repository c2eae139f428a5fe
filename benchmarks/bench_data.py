"""How long a training step waits for data, compared with the step itself.

Times the decode-once cache of a folder of training images (:class:`splitcam.data.ImageCache`),
drawing one batch of 80 patches of 3x64x64 (:class:`splitcam.data.PatchSampler`), and one
training step of the paper's network on that batch (float32 and channels-last + bfloat16). The
target is a data time under 10% of the step time::

    python benchmarks/bench_data.py [--data FOLDER] [--steps N] [--batches N]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from bench_train import OPTIMISED, train_step_time
from common import SHARED_DATA, machine, timeit

from splitcam.data.patches import ImageCache, PatchSampler

BATCH = 80
PATCH = 64


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=SHARED_DATA / "train")
    parser.add_argument("--steps", type=int, default=2, help="timed training steps")
    parser.add_argument("--batches", type=int, default=200, help="timed batch draws")
    args = parser.parse_args()
    print(machine())

    start = time.perf_counter()
    cache = ImageCache(args.data, min_size=PATCH, progress=False)
    cache_time = time.perf_counter() - start
    print(
        f"decode-once cache: {len(cache)} images, {cache.nbytes / 2**20:.0f} MiB "
        f"{cache.dtype}, {cache_time:.2f} s ({cache_time / len(cache) * 1e3:.1f} ms/image)"
    )

    sampler = PatchSampler(cache, patch_size=PATCH, seed=0)
    data = timeit(lambda: sampler.sample(BATCH), repeat=args.batches, warmup=5)
    print(f"batch {BATCH}x3x{PATCH}x{PATCH}: median {data * 1e3:.2f} ms over {args.batches} draws")
    batch = sampler.sample(BATCH)
    for label, options in [("float32", {}), ("channels-last + bf16", OPTIMISED)]:
        step, _ = train_step_time("paper", batch, args.steps, **options)
        ratio = data / step
        verdict = "meets" if ratio < 0.10 else "MISSES"
        print(
            f"paper network step ({label}): {step:.2f} s; data / step = {ratio * 100:.3f}% "
            f"({verdict} the 10% target)"
        )


if __name__ == "__main__":
    main()
