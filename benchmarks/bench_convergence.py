"""Image quality per CPU-hour: train recipes for the same wall-clock budget and score them.

    python benchmarks/bench_convergence.py [--minutes 30] [--threads 2] [--recipes packed physics]
        [--pattern D] [--out runs/convergence] [--doc docs/results/convergence.md]

Each recipe trains alone on the machine (one after the other, ``--threads`` intra-op threads),
on the training folder minus its last ``--held-out`` images (sorted by name), for ``--minutes``
of training. Then every run, and the LMMSE of the same pattern, reconstruct those held-out
images *whole* through the evaluation protocol (the same simulation, noise and scores as
``splitcam evaluate``), at sigma 0 and 15. Printed, per recipe: steps done, PSNR and CIEDE2000
at both sigmas, and the differences to the LMMSE. Kodak24 and McMaster are never used here: they
are for reporting only. The curves of all runs go to ``<out>/curves.png``.

A second table scores the same images cut to whole periods of the pattern: an image whose size
is not a multiple of the period (the held-out 481x321) ends part-way through one, an edge that a
network trained on whole-period patches only never saw (``data.partial_periods`` teaches it).

Recipes (``--recipes``; dotted config overrides on top of the defaults):

- ``packed``: the blind packed network at constant lr 1e-4, batch 16 of 64x64 (the recipe the
  issue compares against);
- ``physics``: the physics-informed network with warm-up and cosine decay (the new default);
- ``physics-joint``: the same, learning the pattern from the start pattern's support, first
  designed for the closed-form LMMSE (``pattern.design_steps``, 300 steps, seconds).

``physics+pattern.name=FILE`` trains on a pattern file instead of ``--pattern`` (e.g. one that
``splitcam design`` wrote: design first, then train the network for the fixed designed pattern);
the LMMSE row stays that of ``--pattern``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import torch
from common import ROOT, SHARED_DATA, machine

COMMON = {
    "data.batch_size": 16,
    "data.patch_size": 64,
    "run.precision": "auto",  # bfloat16 where the CPU has it natively, float32 elsewhere
    "run.log_every": 20,
    "run.checkpoint_every": 200,
    "optim.steps": 10**7,  # the time limit ends the run
}

RECIPES: dict[str, dict[str, object]] = {
    "packed": {
        "network.arch": "packed",
        "optim.lr": 1e-4,
        "optim.schedule": "constant",
        "optim.warmup_steps": 0,
    },
    "physics": {
        "network.arch": "physics",
        "optim.lr": 5e-4,
        "optim.schedule": "cosine",
        "optim.warmup_steps": 100,
    },
    "physics-joint": {
        "network.arch": "physics",
        "optim.lr": 5e-4,
        "optim.schedule": "cosine",
        "optim.warmup_steps": 100,
        "pattern.learn": True,
        "pattern.init": "support",
        "pattern.design_steps": 300,  # `splitcam design` first (seconds), then joint training
    },
}


def _nest(dotted: dict[str, object]) -> dict[str, dict[str, object]]:
    out: dict[str, dict[str, object]] = {}
    for key, value in dotted.items():
        section, _, name = key.partition(".")
        out.setdefault(section, {})[name] = value
    return out


def recipe(name: str) -> dict[str, object]:
    """A recipe by name; ``base+key=value,key=value`` is ``base`` with those settings changed
    (e.g. ``physics+optim.lr=1e-3``)."""
    from splitcam.training.config import read_config_value

    base, _, changes = name.partition("+")
    if base not in RECIPES:
        raise SystemExit(f"unknown recipe {base!r}; known: {', '.join(RECIPES)}")
    settings = dict(RECIPES[base])
    for item in filter(None, changes.split(",")):
        key, _, value = item.partition("=")
        settings[key] = read_config_value(value)
    return settings


def run_name(name: str) -> str:
    """A folder name for a recipe name (``physics+optim.lr=1e-3`` → ``physics_optim-lr-1e-3``)."""
    for a, b in (("+", "_"), ("=", "-"), (",", "_"), (".", "-"), ("/", "-")):
        name = name.replace(a, b)
    return name


def train(name: str, args: argparse.Namespace) -> tuple[Path, float]:
    run = Path(args.out) / (run_name(name) + args.tag)
    overrides = {
        **COMMON,
        "pattern.name": args.pattern,  # a recipe may name its own (e.g. a designed pattern file)
        **recipe(name),
        "data.train": str(args.train),
        "data.val_split": args.held_out,
        "data.val_max_images": 4,  # a cheap curve during training; the scores come after
        "data.val_crop": 128,
        "run.val_every": 200,
        "run.out": str(run),
        "run.threads": args.threads,
        "run.time_limit": args.minutes,
        "run.seed": args.seed,
    }
    config = run.with_suffix(".json")
    config.parent.mkdir(parents=True, exist_ok=True)
    config.write_text(json.dumps(_nest(overrides), indent=1))
    env = {**os.environ, "OMP_NUM_THREADS": str(args.threads)}
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "splitcam", "train", "--config", str(config), "--quiet"]
    if (run / "config.json").exists() and not args.restart:
        cmd.append("--resume")
    print(f"[{name}] training {args.minutes} min: {' '.join(cmd)}", flush=True)
    subprocess.run(cmd, check=False, env=env, cwd=ROOT)
    return run, time.perf_counter() - t0


def held_out_images(folder: Path, count: int) -> list[tuple[str, torch.Tensor]]:
    from splitcam.data.imageio import read_image
    from splitcam.data.patches import list_images

    files = list_images(folder)[-count:]
    return [(f.stem, torch.from_numpy(read_image(f)).permute(2, 0, 1).contiguous()) for f in files]


def score(method, images, sigmas) -> dict[float, dict[str, float]]:
    from splitcam.evaluation.metrics import mean_over_images
    from splitcam.evaluation.protocol import score_images

    values: dict[float, dict[str, list[float]]] = {}
    for _, sigma, _, s in score_images(method, images, sigmas):
        for key in ("psnr", "ciede2000"):
            values.setdefault(sigma, {}).setdefault(key, []).append(s[key])
    return {
        sigma: {k: mean_over_images(v).mean for k, v in d.items()} for sigma, d in values.items()
    }


def table(rows: list[tuple[str, str, dict[float, dict[str, float]]]]) -> list[str]:
    """Markdown rows: PSNR and CIEDE2000 at sigma 0 and 15, and PSNR against the first row."""
    base = rows[0][2]
    lines = [
        "| recipe | steps | PSNR σ0 | ΔPSNR σ0 | PSNR σ15 | ΔPSNR σ15 "
        "| CIEDE2000 σ0 | CIEDE2000 σ15 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, steps, s in rows:
        d0 = s[0.0]["psnr"] - base[0.0]["psnr"]
        d15 = s[15.0]["psnr"] - base[15.0]["psnr"]
        lines.append(
            f"| {name} | {steps} | {s[0.0]['psnr']:.2f} | {d0:+.2f} | {s[15.0]['psnr']:.2f} "
            f"| {d15:+.2f} | {s[0.0]['ciede2000']:.3f} | {s[15.0]['ciede2000']:.3f} |"
        )
    return lines


def steps_of(run: Path) -> int:
    lines = (run / "metrics.jsonl").read_text().splitlines()
    return max(json.loads(line).get("step", 0) for line in lines if line.strip())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--recipes",
        nargs="+",
        default=["packed", "physics"],
        help=f"recipes: {', '.join(RECIPES)}, or BASE+key=value,... (default: packed physics)",
    )
    parser.add_argument("--pattern", default="D")
    parser.add_argument("--train", type=Path, default=SHARED_DATA / "train")
    parser.add_argument("--held-out", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/convergence")
    parser.add_argument("--tag", default="", help="suffix of the run folders (e.g. 5min)")
    parser.add_argument("--doc", help="also write the table to this Markdown file")
    parser.add_argument("--restart", action="store_true", help="retrain runs that exist")
    parser.add_argument("--score-only", action="store_true", help="score existing runs")
    args = parser.parse_args()

    from splitcam.patterns import get as get_pattern
    from splitcam.recon.registry import build_method
    from splitcam.viz.curves import compare_runs

    torch.set_num_threads(args.threads)
    runs = {}
    for name in args.recipes:
        if args.score_only:
            runs[name] = Path(args.out) / (run_name(name) + args.tag)
        else:
            runs[name], _ = train(name, args)
    images = held_out_images(args.train, args.held_out)
    # The same images cut to whole periods: shows what the image edge that ends part-way
    # through a period (481x321 here) costs each recipe.
    ph, pw = get_pattern(args.pattern).period
    periods = [(n, t[:, : t.shape[1] // ph * ph, : t.shape[2] // pw * pw]) for n, t in images]
    sigmas = [0.0, 15.0]
    t0 = time.perf_counter()
    methods = [("LMMSE of " + args.pattern, "-", build_method("lmmse", pattern=args.pattern))]
    for name, run in runs.items():  # float32 inference: comparable with the earlier runs
        methods.append((name, str(steps_of(run)), build_method(str(run), precision="fp32")))
    whole = [(name, steps, score(m, images, sigmas)) for name, steps, m in methods]
    cut = [(name, steps, score(m, periods, sigmas)) for name, steps, m in methods]
    curves_path = Path(args.doc).with_suffix(".png") if args.doc else Path(args.out) / "curves.png"
    curves = compare_runs([str(r) for r in runs.values()], curves_path)

    h, w = images[0][1].shape[1:]
    lines = [
        f"{args.minutes:g} minutes of training per recipe, {args.threads} threads, each alone; "
        f"pattern {args.pattern}; scored on the last {args.held_out} training images (whole), "
        f"held out from training. Δ: against the LMMSE.",
        "",
        *table(whole),
        "",
        f"The same images cut to whole periods of {ph}x{pw} (e.g. {h}x{w} → "
        f"{h // ph * ph}x{w // pw * pw}): without the edge that ends part-way through a period.",
        "",
        *table(cut),
        "",
        f"Machine: {machine()}. Scoring took {time.perf_counter() - t0:.0f} s.",
        f"Command: python {' '.join(sys.argv)}",
        f"Curves: {curves}",
    ]
    text = "\n".join(lines)
    print(text)
    if args.doc:
        Path(args.doc).parent.mkdir(parents=True, exist_ok=True)
        Path(args.doc).write_text(text + "\n")


if __name__ == "__main__":
    main()
