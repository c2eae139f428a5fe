"""Training and inference speed on this machine: the plain float32 eager baseline against the
optimised settings, side by side in one run, plus achieved GFLOP/s and large-image memory.

    python benchmarks/bench_train.py [--steps 3] [--skip-large] [--accuracy-steps 0]

Prints, for the paper's setting (batch 80 of 64x64, 10 blocks x 64 features, pattern D):
what ``--precision auto`` measures on this CPU (float32 against bfloat16, the faster taken);
training steps/s and patches/s (baseline, optimised, ratio) for the paper network and the packed
one; the achieved GFLOP/s against the CPU's nominal peak; data time per batch; seconds per
768x512 reconstruction (baseline, optimised, ratio); peak memory of a tiled 4000x3000
reconstruction (in a fresh process); and, with --accuracy-steps N, the validation PSNR of two
short fixed-seed training runs (float32 and optimised) and their difference.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from common import SHARED_DATA, machine, timeit

from splitcam.data.patches import ImageCache, PatchSampler
from splitcam.physics.noise import GaussianNoise
from splitcam.physics.sensor import SplitterSensor
from splitcam.physics.system import ImagingSystem
from splitcam.recon.networks import build_network
from splitcam.recon.tiling import reconstruct

OPTIMISED = {"channels_last": True, "bf16": True}


def cpu_peak_gflops() -> tuple[float, float, str]:
    """Nominal fp32 and bf16 peaks: cores x GHz x FLOP/cycle (2 AVX-512 FMA units: 64 fp32
    FLOP/cycle; AVX512-BF16 dot products double that). An estimate: the clock under load and the
    number of FMA units are not visible from inside a VM."""
    ghz = 0.0
    flags = ""
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("cpu MHz") and not ghz:
            ghz = float(line.split(":")[1]) / 1000
        if line.startswith("flags") and not flags:
            flags = line
    cores = torch.get_num_threads()
    fp32 = cores * ghz * 64
    bf16 = fp32 * 2 if "avx512_bf16" in flags else fp32
    note = f"{cores} cores x {ghz:.2f} GHz x 64 FLOP/cycle (fp32)"
    return fp32, bf16, note


def make_system(arch: str, channels_last: bool) -> ImagingSystem:
    net = build_network({"arch": arch, "period": [2, 2], "features": 64, "blocks": 10})
    system = ImagingSystem(SplitterSensor("D"), net)
    if channels_last:
        system.channels_last = True
        net.to(memory_format=torch.channels_last)
    return system


def train_step_time(
    arch: str,
    batch: torch.Tensor,
    steps: int,
    channels_last=False,
    bf16=False,
    foreach=None,
    compile_=False,
) -> tuple[float, float]:
    torch.manual_seed(0)
    system = make_system(arch, channels_last)
    if compile_:
        system.network = torch.compile(system.network)
    opt = torch.optim.Adam(system.parameters(), lr=1e-4, foreach=foreach)
    noise = GaussianNoise((0, 30), seed=0)

    def step():
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            pred = system(batch, noise)
        loss = F.mse_loss(pred.float(), batch)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    from torch.utils.flop_counter import FlopCounterMode

    if compile_:
        t = time.perf_counter()
        step()  # compilation happens here, outside the timed steps
        print(f"  torch.compile warm-up: {time.perf_counter() - t:.0f} s")
        return timeit(step, repeat=steps, warmup=0), 0.0
    with FlopCounterMode(display=False) as counter:
        step()
    return timeit(step, repeat=steps, warmup=0), counter.get_total_flops()


def large_image_memory(arch: str) -> dict:
    """Reconstruct a 4000x3000 raw image in tiles in a fresh process; report its peak RSS."""
    # VmHWM (peak resident memory of this process image) rather than ru_maxrss: Linux carries
    # ru_maxrss over exec() from the parent, so it would report the benchmark's own peak.
    code = f"""
import json, time, torch
from splitcam.recon.tiling import reconstruct
from splitcam.recon.networks import build_network
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM"):
            return int(line.split()[1]) / 1024
torch.manual_seed(0)
net = build_network({{"arch": "{arch}", "period": [2, 2]}}).eval()
raw = torch.rand(1, 1, 3000, 4000)
base = hwm()
t = time.perf_counter()
out = reconstruct(net, raw, tile=512, bf16=True, channels_last=True)
print(json.dumps({{"seconds": time.perf_counter() - t, "shape": list(out.shape),
    "peak_rss_mib": hwm(), "rss_before_mib": base}}))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def accuracy(steps: int) -> dict:
    """Validation PSNR after two short fixed-seed runs: float32 and the optimised settings."""
    from splitcam.training import TrainConfig, train

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, extra in [("float32", {}), ("optimised", OPTIMISED)]:
            settings = {
                "data.train": str(SHARED_DATA / "train"),
                "data.val_split": 32,
                "data.val_max_images": 8,
                "data.val_crop": 128,
                "data.batch_size": 16,
                "optim.steps": steps,
                "run.val_every": steps,
                "run.log_every": steps,
                "run.checkpoint_every": steps,
                "run.out": f"{tmp}/{label}",
                "run.seed": 0,
                **{f"run.{k}": v for k, v in extra.items()},
            }
            t = time.perf_counter()
            result = train(TrainConfig().override(settings), progress=False)
            results[label] = {
                **{k: v for k, v in result.last_metrics.items() if k.startswith("val_psnr")},
                "seconds": time.perf_counter() - t,
            }
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3, help="timed training steps per setting")
    parser.add_argument("--batch-size", type=int, default=80)
    parser.add_argument("--skip-large", action="store_true", help="skip the 4000x3000 run")
    parser.add_argument(
        "--only",
        choices=["train", "inference", "large", "accuracy", "compile"],
        help="run one part only",
    )
    parser.add_argument(
        "--accuracy-steps",
        type=int,
        default=0,
        help="also train float32 vs optimised for N steps and compare PSNR",
    )
    args = parser.parse_args()
    print(machine())
    fp32_peak, bf16_peak, note = cpu_peak_gflops()
    print(f"nominal peak: {fp32_peak:.0f} GFLOP/s fp32, {bf16_peak:.0f} GFLOP/s bf16 ({note})")
    from splitcam.recon.precision import measure

    # What --precision auto measures, the same steps timed both ways now (not the cached choice).
    print(f"precision auto here: {measure('cpu').reason}")

    cache = ImageCache(SHARED_DATA / "train", min_size=64, max_images=64, progress=False)
    sampler = PatchSampler(cache, patch_size=64, seed=0)
    data_s = timeit(lambda: sampler.sample(args.batch_size), repeat=20)
    batch = sampler.sample(args.batch_size)
    print(f"data: {data_s * 1e3:.2f} ms per batch of {args.batch_size}x3x64x64")

    def want(part: str) -> bool:
        return args.only is None or args.only == part

    for arch in ["paper", "packed"] if want("train") else []:
        base, flops = train_step_time(arch, batch, args.steps)
        fast, _ = train_step_time(arch, batch, args.steps, **OPTIMISED)
        b = args.batch_size
        print(
            f"train {arch:6}: baseline {1 / base:.3f} steps/s ({b / base:.1f} patches/s), "
            f"optimised {1 / fast:.3f} steps/s ({b / fast:.1f} patches/s), "
            f"ratio {base / fast:.2f}x; {flops / 1e9:.0f} GFLOP/step -> "
            f"{flops / base / 1e9:.0f} GFLOP/s fp32 ({100 * flops / base / 1e9 / fp32_peak:.0f}%"
            f" of peak), {flops / fast / 1e9:.0f} GFLOP/s optimised "
            f"({100 * flops / fast / 1e9 / bf16_peak:.0f}% of bf16 peak); data "
            f"{100 * data_s / fast:.2f}% of an optimised step"
        )

    if args.only == "compile":
        base, _ = train_step_time("paper", batch, args.steps, **OPTIMISED)
        comp, _ = train_step_time("paper", batch, args.steps, **OPTIMISED, compile_=True)
        print(
            f"torch.compile (paper, optimised settings): {1 / base:.3f} -> {1 / comp:.3f} "
            f"steps/s, ratio {base / comp:.2f}x"
        )

    torch.manual_seed(0)
    for arch in ["paper", "packed"] if want("inference") else []:
        net = build_network({"arch": arch, "period": [2, 2]}).eval()
        raw = torch.rand(1, 1, 512, 768)

        def baseline(net=net, raw=raw):
            with torch.no_grad():
                net(raw)

        def optimised(net=net, raw=raw):
            reconstruct(net, raw, tile=None, bf16=True, channels_last=True)

        tb = timeit(baseline, repeat=3)
        to = timeit(optimised, repeat=3)
        print(
            f"inference {arch:6} 768x512: baseline {tb:.2f} s, optimised {to:.2f} s, "
            f"ratio {tb / to:.2f}x"
        )

    if not args.skip_large and want("large"):
        for arch in ["paper"]:
            r = large_image_memory(arch)
            print(
                f"tiled 4000x3000 ({arch}, optimised, tile 512): {r['seconds']:.1f} s, "
                f"peak RSS {r['peak_rss_mib']:.0f} MiB (process start {r['rss_before_mib']:.0f}"
                f" MiB)"
            )
    if args.accuracy_steps and want("accuracy"):
        acc = accuracy(args.accuracy_steps)
        a, o = acc["float32"], acc["optimised"]
        print(
            f"accuracy after {args.accuracy_steps} steps (batch 16, seed 0, 8 held-out "
            f"images): "
            + ", ".join(
                f"{k}: float32 {a[k]:.3f} dB, optimised {o[k]:.3f} dB, "
                f"difference {o[k] - a[k]:+.3f} dB"
                for k in a
                if k.startswith("val")
            )
        )
        print(f"  wall time: float32 {a['seconds']:.0f} s, optimised {o['seconds']:.0f} s")


if __name__ == "__main__":
    main()
