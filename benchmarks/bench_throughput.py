"""Training throughput: patches/s and peak memory of whole training steps, data held on the
device against today's host data path, for the physics network and ``universal``, at each batch
size, side by side in one run.

    python benchmarks/bench_throughput.py [--device cuda] [--batches 64 256 512] [--steps 20]
        [--precision auto] [--compile] [--data FOLDER]
    python benchmarks/bench_throughput.py --baseline-rev REV   # the CPU path against commit REV

A step is what the trainer does: draw a batch (patches, flips, partial periods), the sensor
(Eq. 2; for ``universal`` a new random pattern every step), noise, the LMMSE input, the
network forward and backward, and Adam. ``host``: patches cut on the CPU by numpy and copied,
noise drawn on the CPU and copied (the path before images were held on the device). ``device``:
:class:`splitcam.data.patches.DeviceImages` and noise drawn on the device. Targets on one H100:
20,000 patches/s of 64x64 for the physics network and 10,000 for ``universal``.

``--baseline-rev REV`` times the CPU data path (a batch of 8 patches, Gaussian and photon noise)
of this tree and of commit REV (checked out in a temporary git worktree), alternating, and prints
the ratio: the CPU path must not get slower.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from common import ROOT, SHARED_DATA, machine

from splitcam.data.patches import ImageCache, PatchSampler
from splitcam.patterns.random import PatternMix
from splitcam.physics.noise import GaussianNoise
from splitcam.physics.sensor import SplitterSensor, SwitchingSensor
from splitcam.physics.system import ImagingSystem
from splitcam.recon.base import fast_precision
from splitcam.recon.networks import build_network


def build(arch: str, device: torch.device, fast: bool, compile_: bool):
    if arch == "universal":
        sensor = SwitchingSensor("D")
        net = build_network({"arch": "universal"})
    else:
        sensor = SplitterSensor("D")
        net = build_network({"arch": "physics", "period": [2, 2]})
    system = ImagingSystem(sensor, net).to(device)
    if fast:
        system.channels_last = True
        system.network.to(memory_format=torch.channels_last)
    if compile_:
        system.compile_network()
    return system


def peak_memory_mib(device: torch.device) -> float:
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def throughput(arch, cache, batch, path, device, fast, compile_, steps) -> tuple[float, float]:
    """(patches/s, peak memory MiB) of ``steps`` training steps after 3 warm-up steps."""
    torch.manual_seed(0)
    on_device = path == "device"
    sampler = PatchSampler(
        cache,
        patch_size=64,
        seed=0,
        partial=0.5,
        period=(2, 2),
        device=device if on_device else None,
    )
    noise = GaussianNoise((0, 30), seed=0, device=device if on_device else None)
    system = build(arch, device, fast, compile_)
    opt = torch.optim.Adam(system.parameters(), lr=1e-4)
    mix = (
        PatternMix(["A", "B", "C", "D", "E", "bayer"], 0.3, seed=0) if arch == "universal" else None
    )

    def step(i: int) -> None:
        x = sampler.sample(batch).to(device, non_blocking=True)
        if mix is not None:
            system.sensor.set_pattern(mix.pattern(i))
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=fast):
            pred = system(x, noise)
        loss = F.mse_loss(pred.float(), x)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    for i in range(3):
        step(i)
    if device.type == "cuda":
        torch.cuda.synchronize(device)
        torch.cuda.reset_peak_memory_stats(device)
    t0 = time.perf_counter()
    for i in range(steps):
        step(3 + i)
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return steps * batch / (time.perf_counter() - t0), peak_memory_mib(device)


CPU_PATH = """
import json, sys, time, statistics, torch
from splitcam.data.patches import ImageCache, PatchSampler
from splitcam.physics.noise import GaussianNoise, PhotonNoise
torch.set_num_threads(1)
cache = ImageCache(sys.argv[1], min_size=64, max_images=64, progress=False)
sampler = PatchSampler(cache, patch_size=64, seed=0)
gauss, photon = GaussianNoise((0, 30), seed=0), PhotonNoise((10, 1e4), seed=0)
def one():
    x = sampler.sample(8)[:, :1]
    gauss(x); photon(x)
for _ in range(5): one()
times = []
for _ in range(int(sys.argv[2])):
    t = time.perf_counter(); one(); times.append(time.perf_counter() - t)
print(json.dumps(statistics.median(times)))
"""


def compare_with(rev: str, data: Path, reps: int, rounds: int) -> None:
    """The CPU data path of this tree against commit ``rev``, alternating ``rounds`` times."""
    with tempfile.TemporaryDirectory() as tmp:
        worktree = Path(tmp) / "base"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(worktree), rev],
            check=True,
            capture_output=True,
        )
        try:
            results: dict[str, list[float]] = {"this tree": [], rev: []}
            for _ in range(rounds):
                for label, src in (("this tree", ROOT / "src"), (rev, worktree / "src")):
                    out = subprocess.run(
                        [sys.executable, "-c", CPU_PATH, str(data), str(reps)],
                        capture_output=True,
                        text=True,
                        check=True,
                        env={"PYTHONPATH": str(src), "PATH": "/usr/bin:/bin"},
                    )
                    results[label].append(json.loads(out.stdout.strip().splitlines()[-1]))
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(worktree)],
                check=True,
            )
    now, base = min(results["this tree"]), min(results[rev])
    print(
        f"CPU data path (batch 8: patches, Gaussian and photon noise; best of {rounds} medians "
        f"of {reps}): this tree {now * 1e3:.2f} ms, {rev} {base * 1e3:.2f} ms, "
        f"ratio {base / now:.2f}x (above 1: this tree is faster)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--batches", type=int, nargs="+")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--archs", nargs="+", default=["physics", "universal"])
    parser.add_argument("--precision", default="auto")
    parser.add_argument("--compile", action="store_true", help="also time torch.compile")
    parser.add_argument("--data", type=Path, default=SHARED_DATA / "train")
    parser.add_argument("--max-images", type=int)
    parser.add_argument("--baseline-rev", help="compare the CPU data path with this commit")
    parser.add_argument("--reps", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    print(machine())
    if args.baseline_rev:
        compare_with(args.baseline_rev, args.data, args.reps, args.rounds)
        return
    device = torch.device(args.device)
    if device.type == "cuda":
        print(f"device: {torch.cuda.get_device_name(device)}")
    batches = args.batches or ([64, 256, 512] if device.type == "cuda" else [8, 64])
    fast = fast_precision(args.precision, device)
    cache = ImageCache(args.data, min_size=64, max_images=args.max_images, progress=False)
    print(
        f"{len(cache)} photos, {cache.nbytes / 2**20:.0f} MiB; precision "
        f"{'bfloat16 + channels-last' if fast else 'float32'}; {args.steps} timed steps each"
    )
    compiles = [False, True] if args.compile else [False]
    for arch in args.archs:
        for batch in batches:
            for compile_ in compiles:
                rates = {}
                for path in ("host", "device"):
                    rates[path] = throughput(
                        arch, cache, batch, path, device, fast, compile_, args.steps
                    )
                (h, hm), (d, dm) = rates["host"], rates["device"]
                tag = " compiled" if compile_ else ""
                print(
                    f"{arch:9} batch {batch:4}{tag}: host data {h:8.0f} patches/s "
                    f"(peak {hm:6.0f} MiB), device data {d:8.0f} patches/s (peak {dm:6.0f} MiB), "
                    f"ratio {d / h:.2f}x",
                    flush=True,
                )


if __name__ == "__main__":
    main()
