"""The universal network against the physics network, side by side in one run: training step
time at the same batch and precision, and peak memory of a tiled 12-megapixel reconstruction.

    python benchmarks/bench_universal.py [--threads 2] [--batch 8] [--steps 12]
        [--skip-large | --only-large]

Prints median seconds per training step (batch of 64x64 patches, Adam, MSE, sigma ~ U[0, 30])
for the physics network on pattern D, the universal network on pattern D, and the universal
network on a new random pattern every step (a new closed-form solve each step, as its training
does), each in float32 and in bfloat16 autocast + channels-last, with the ratio to the physics
network (the target: within 1.5x). Then, each in a fresh process, the peak resident memory of
reconstructing a 4000x3000 raw image of pattern E in 512-pixel tiles, and that ratio.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np
import torch
from common import machine

from splitcam.patterns.random import random_pattern
from splitcam.physics.sensor import SplitterSensor, SwitchingSensor
from splitcam.physics.system import ImagingSystem
from splitcam.recon.networks import build_network


def step_time(arch: str, random: bool, batch: int, steps: int, fast: bool) -> float:
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    net = build_network({"arch": arch, "period": [2, 2]})
    sensor = SwitchingSensor("D") if random else SplitterSensor("D")
    system = ImagingSystem(sensor, net)
    if fast:
        system.channels_last = True
        net.to(memory_format=torch.channels_last)
    opt = torch.optim.Adam(net.parameters(), 1e-4)
    x = torch.rand(batch, 3, 64, 64)
    gen = torch.Generator().manual_seed(0)

    def noise(raw):
        s = torch.rand(raw.shape[0], generator=gen)[:1].expand(raw.shape[0]) * 30
        return raw + torch.randn(raw.shape, generator=gen) * (s / 255).view(-1, 1, 1, 1), s

    times = []
    for _ in range(steps):
        if random:
            sensor.set_pattern(random_pattern(rng))
        t = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=fast):
            out = system(x, noise)
        loss = (out.float() - x).square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        times.append(time.perf_counter() - t)
    rest = sorted(times[2:])
    return rest[len(rest) // 2]


LARGE = """
import resource, json, sys, torch
from splitcam.physics.sensor import pattern_pixel_kernels
from splitcam.recon.base import NetworkReconstructor
from splitcam.recon.networks import build_network
from splitcam import patterns
torch.set_num_threads({threads})
arch = sys.argv[1]
pattern = patterns.get("E")
net = build_network({{"arch": arch, "period": list(pattern.period)}}).eval()
raw = torch.rand(1, 1, 3000, 4000)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
method = NetworkReconstructor(net, pattern, arch, tile=512, precision="fp32")
out = method.reconstruct(raw, 10.0)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({{"peak_mib": peak / 1024, "before_mib": before / 1024}}))
"""


def large_memory(arch: str, threads: int) -> dict:
    code = LARGE.format(threads=threads)
    out = subprocess.run(
        [sys.executable, "-c", code, arch], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--steps", type=int, default=12)
    parser.add_argument("--skip-large", action="store_true")
    parser.add_argument("--only-large", action="store_true", help="only the memory part")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(machine())
    if not args.only_large:
        print(f"training step, batch {args.batch} of 64x64, median of {args.steps - 2} steps")
        print("| precision | physics (D) | universal (D) | ratio | universal (random) | ratio |")
        print("|---|---|---|---|---|---|")
    for fast in () if args.only_large else (False, True):
        base = step_time("physics", False, args.batch, args.steps, fast)
        same = step_time("universal", False, args.batch, args.steps, fast)
        rand = step_time("universal", True, args.batch, args.steps, fast)
        label = "bf16 + channels-last" if fast else "fp32"
        print(
            f"| {label} | {base * 1e3:.0f} ms | {same * 1e3:.0f} ms | {same / base:.2f} | "
            f"{rand * 1e3:.0f} ms | {rand / base:.2f} |"
        )
    if not args.skip_large:
        phys = large_memory("physics", args.threads)
        uni = large_memory("universal", args.threads)
        print(
            f"4000x3000 raw of pattern E, 512-px tiles, fp32: peak RSS physics "
            f"{phys['peak_mib']:.0f} MiB, universal {uni['peak_mib']:.0f} MiB, ratio "
            f"{uni['peak_mib'] / phys['peak_mib']:.2f}"
        )


if __name__ == "__main__":
    main()
