"""How long a training step waits for data, compared with the step itself.

Times:

- the decode-once cache of a folder of training images (:class:`splitcam.data.ImageCache`),
- drawing one batch of 80 patches of 3x64x64 (:class:`splitcam.data.PatchSampler`),
- one training step of a stand-in network of the size of the reconstruction network: head conv
  4->64, 10 residual blocks of two 3x3 convs with 64 channels, tail conv 64->3, forward, backward
  and an Adam step on an 80x4x64x64 input.

The target is a data time under 10% of the step time. Run from the repository root::

    python benchmarks/bench_data.py [--data FOLDER] [--steps N] [--batches N]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import torch
from torch import nn

from splitcam.data import ImageCache, PatchSampler

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "train"
BATCH = 80
PATCH = 64


def machine_description() -> str:
    """One line: platform, CPU model, core count, torch version and threads."""
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return (
        f"{platform.platform()} | {cpu} | {os.cpu_count()} logical CPUs | "
        f"torch {torch.__version__} | {torch.get_num_threads()} threads"
    )


class _Residual(nn.Module):
    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv2(torch.relu(self.conv1(x)))


def stand_in_network(blocks: int = 10, channels: int = 64) -> nn.Module:
    """A network of the size and shape of the reconstruction network, for timing only."""
    return nn.Sequential(
        nn.Conv2d(4, channels, 3, padding=1),
        *[_Residual(channels) for _ in range(blocks)],
        nn.Conv2d(channels, 3, 3, padding=1),
    )


def time_calls(fn, repeats: int, warmup: int = 1) -> list[float]:
    """Wall-clock seconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed calls."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="training image folder")
    parser.add_argument("--steps", type=int, default=2, help="timed training steps")
    parser.add_argument("--batches", type=int, default=200, help="timed batch draws")
    args = parser.parse_args()

    print(machine_description())

    start = time.perf_counter()
    cache = ImageCache(args.data, min_size=PATCH, progress=False)
    cache_time = time.perf_counter() - start
    print(
        f"decode-once cache: {len(cache)} images, {cache.nbytes / 2**20:.0f} MiB "
        f"{cache.dtype}, {cache_time:.2f} s ({cache_time / len(cache) * 1e3:.1f} ms/image)"
    )

    sampler = PatchSampler(cache, patch_size=PATCH, seed=0)
    data_times = time_calls(lambda: sampler.sample(BATCH), args.batches, warmup=5)
    data_median = statistics.median(data_times)
    print(
        f"batch {BATCH}x3x{PATCH}x{PATCH}: median {data_median * 1e3:.2f} ms, "
        f"min {min(data_times) * 1e3:.2f} ms, max {max(data_times) * 1e3:.2f} ms "
        f"over {args.batches} draws"
    )

    torch.manual_seed(0)
    net = stand_in_network()
    optimiser = torch.optim.Adam(net.parameters(), lr=1e-4)
    raw_input = torch.rand(BATCH, 4, PATCH, PATCH)
    target = sampler.sample(BATCH)

    def step() -> None:
        optimiser.zero_grad(set_to_none=True)
        loss = nn.functional.mse_loss(net(raw_input), target)
        loss.backward()
        optimiser.step()

    parameters = sum(p.numel() for p in net.parameters())
    step_times = time_calls(step, args.steps, warmup=1)
    step_median = statistics.median(step_times)
    print(
        f"training step (stand-in, {parameters / 1e6:.2f} M parameters, forward+backward+Adam): "
        f"median {step_median:.2f} s over {args.steps} steps "
        f"({', '.join(f'{t:.2f}' for t in step_times)} s)"
    )
    ratio = data_median / step_median
    verdict = "meets" if ratio < 0.10 else "MISSES"
    print(f"data time / step time = {ratio:.2e} ({ratio * 100:.3f} %), {verdict} the 10 % target")


if __name__ == "__main__":
    main()
