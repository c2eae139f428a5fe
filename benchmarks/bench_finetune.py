"""Fine-tuning step time of each way to fine-tune the shipped universal network to one pattern,
side by side in one run, with the ratio to a full fine-tune.

    python benchmarks/bench_finetune.py [--pattern rgbw] [--threads 1] [--batch 8] [--steps 30]

Each arm builds the run's system and optimiser the way ``splitcam train`` does
(:func:`splitcam.training.setup.build_optimizer`, :func:`splitcam.training.adapters.attach`),
starts from the shipped ``universal`` and trains on the same random 64x64 patches at sigma 15:

- full: every weight trains (``optim.adapter = none``);
- film: a per-channel scale and shift after every convolution, the network frozen;
- film + base 0.1: the same, the network's weights at a tenth of the rate.

The arms take turns step by step (so a busy machine slows each alike); the median seconds per
step and the steps each arm fits in 10 minutes at that pace are printed.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
from common import machine

from splitcam.recon.loading import load_model
from splitcam.training.adapters import attach
from splitcam.training.config import TrainConfig
from splitcam.training.setup import build_optimizer, build_system

ARMS = {
    "full": {},
    "film": {"optim.adapter": "film"},
    "film + base 0.1": {"optim.adapter": "film", "optim.base_lr_scale": 0.1},
}


def build(pattern: str, changes: dict) -> tuple:
    config = TrainConfig().override(
        {"pattern.name": pattern, "network.arch": "universal", **changes}
    )
    system = build_system(config)
    system.network.load_state_dict(load_model("universal").network.state_dict())
    attach(system, config.optim.adapter)
    return system, build_optimizer(config, system)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pattern", default="rgbw")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--steps", type=int, default=30)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(machine())
    arms = {name: build(args.pattern, changes) for name, changes in ARMS.items()}
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(args.batch, 3, 64, 64, generator=gen)

    def noise(raw):
        return raw + torch.randn(raw.shape, generator=gen) * 15 / 255, 15.0

    times: dict[str, list[float]] = {name: [] for name in arms}
    for step in range(args.steps + 2):
        for name, (system, optimizer) in arms.items():
            t = time.perf_counter()
            loss = (system(x, noise) - x).square().mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            if step >= 2:  # the first two warm up
                times[name].append(time.perf_counter() - t)
    full = statistics.median(times["full"])
    print(f"pattern {args.pattern}, batch {args.batch} of 64x64, {args.threads} thread(s)")
    print("| arm | s / step | ratio to full | steps in 10 min |")
    print("|---|---|---|---|")
    for name, values in times.items():
        med = statistics.median(values)
        print(f"| {name} | {med:.3f} | {full / med:.2f}x | {600 / med:.0f} |")


if __name__ == "__main__":
    main()
