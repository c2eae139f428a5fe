"""One command for a GPU's minutes: fine-tune a queue of shipped networks, then gate them on a CPU.

    python experiments/gpu/relay.py --minutes 9 --out DIR [--data PHOTOS] [--batch 256]
    python experiments/gpu/relay.py --gate DIR [--dry-run] [--data PHOTOS]

**The relay** trains each network of the queue from its shipped weights, on its own recipe (the
configuration its last training segment saved: pattern, noise, light domain, copies at half
size, weight average...), at ``--batch`` patches per step with the recipe's peak rate carried
over by ``--lr-rule`` (:func:`splitcam.training.schedule.scaled_lr`; kept as it is by default,
which measured best at batch 64) and a cosine decay over its time slot. The whole command ends
within ``--minutes`` of wall time. The training photos are decoded once and held on the device
(:class:`splitcam.data.patches.DeviceImages`).

- The queue: ``universal`` first (it serves every pattern), then ``universal-photon``, then the
  per-pattern networks furthest below the paper (A, D, D-opt, B, A-opt).
- **The minutes rule**: shares of 3 for ``universal``, 2 for ``universal-photon``, 1 for every
  other network. Each network in turn gets the wall time left times its share over the shares
  still to come, less the set-up and validation time measured on the network before it (for
  the first, 30 s or a fifth of the minutes, whichever is less); a slot under 0.2 minutes of
  training is skipped and said.
- Every run checkpoints each minute of training (``run.checkpoint_minutes``) into
  ``DIR/runs/NAME``; each finished run is exported as ``DIR/candidates/NAME.json`` +
  ``.safetensors`` (provenance: device, minutes, steps and batch, so patches seen), and
  ``DIR/relay.md`` tables the validation PSNR at the start and the end of every run.

**The gate** (``--gate DIR``, on a CPU) scores every candidate against the shipped model of its
name on held-out photos, whole (481x321 or 321x481: odd sides, ending part-way through periods):
the first 8 of the 32 photos every run holds out (its validation photos, whole rather than
cropped) and the last 12, which no training or choice uses. It scores at the model's own
validation levels, cleanest first (σ 0 and 15 for the Gaussian models; 300 and 3
photo-electrons for ``universal-photon``), and a network of any pattern on the patterns its
validation uses. A candidate ships when the mean PSNR rises at the cleanest level and falls by
no more than 0.05 dB at the noisiest (the rule of docs/results/gpu). ``DIR/gate.md`` holds the
table; ``--dry-run`` prints what would ship and writes nothing.

A candidate that is not a continuation of the shipped model of its name (another pattern to
start from, or a network of other patterns) is skipped with its reason in the table; the rest
are gated. A model that learns its pattern (A-opt) goes on learning it, so its candidate's
pattern moves: the patterns compared are the ones both started from.

``--device cpu --minutes 0.5`` runs the same path end to end (the test suite does so on tiny
settings). How to run it on a lent GPU: ``experiments/gpu/README.md``.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import sys
import time
from pathlib import Path

QUEUE = ["universal", "universal-photon", "A", "D", "D-opt", "B", "A-opt"]
SHARES = {"universal": 3, "universal-photon": 2}
FIRST_OVERHEAD_S = 30.0
MIN_SLOT_MIN = 0.2
MARKER = "relay.json"
GATE_RISE_DB = 0.0
GATE_FALL_DB = 0.05
VAL_FIRST = 8
LAST_UNUSED = 12


class RelayError(ValueError):
    """Bad input to the relay or the gate: one line, nothing changed."""


def share(name: str) -> int:
    return SHARES.get(name, 1)


def slot_minutes(left_s: float, queue: list[str], overhead_s: float) -> float:
    """Training minutes of ``queue[0]``: the wall time left times its share of the shares still
    to come, less the expected set-up and validation time."""
    part = left_s * share(queue[0]) / sum(share(n) for n in queue)
    return max(0.0, (part - overhead_s) / 60.0)


def check_queue(queue: list[str]) -> None:
    from splitcam.recon.loading import model_names

    shipped = model_names()
    unknown = [n for n in queue if n not in shipped]
    if unknown:
        raise RelayError(
            f"unknown model {unknown[0]!r} in the queue; shipped: {', '.join(shipped)}"
        )
    if len(set(queue)) != len(queue):
        raise RelayError("a model is named twice in the queue")


def relay_config(name: str, args: argparse.Namespace, out: Path, minutes: float):
    """The run of one queued network: its shipped recipe from its weights, at the relay's
    batch, rate, time slot, device and photos."""
    from splitcam.recon.loading import load_model
    from splitcam.training import TrainConfig
    from splitcam.training.schedule import scaled_lr

    saved = load_model(name).meta["config"]
    config = TrainConfig.from_saved(saved, source=f"the shipped {name}")
    return config.override(
        {
            "data.train": str(args.data),
            "data.val": None,
            "data.batch_size": args.batch,
            "optim.lr": scaled_lr(
                config.optim.lr, config.data.batch_size, args.batch, args.lr_rule
            ),
            "optim.steps": 10**9,  # the time slot ends the run
            "pattern.design_steps": 0,  # the kernels come from the shipped model
            "run.init_from": name,
            "run.continue_schedule": False,
            "run.out": str(out / "runs" / name),
            "run.device": args.device,
            "run.time_limit": minutes,
            "run.checkpoint_minutes": 1.0,
            "run.checkpoint_every": 10**9,
            "run.val_every": 10**9,  # at the start and the end only
            "run.log_every": 50,
            "run.threads": None,
            "run.precision": args.precision,
            "run.compile": args.compile,
        }
    )


def start_folder(out: Path, args: argparse.Namespace) -> None:
    """Refuse a folder another relay wrote into; mark this one as the relay's."""
    marker = out / MARKER
    if marker.exists() or (out / "candidates").exists():
        raise RelayError(
            f"{out} holds another relay's candidates; give a new --out (gate those with --gate)"
        )
    out.mkdir(parents=True, exist_ok=True)
    record = {
        "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "minutes": args.minutes,
        "queue": args.queue,
        "batch": args.batch,
        "device": args.device,
        "data": str(args.data),
    }
    marker.write_text(json.dumps(record, indent=1) + "\n")


def run_relay(args: argparse.Namespace) -> int:
    from splitcam.data.patches import list_images
    from splitcam.recon.loading import load_model
    from splitcam.training import train
    from splitcam.training.models import export_model

    if not args.minutes > 0:
        raise RelayError(f"--minutes must be > 0, got {args.minutes}")
    if args.batch < 1:
        raise RelayError(f"--batch must be >= 1, got {args.batch}")
    check_queue(args.queue)
    list_images(args.data)  # a missing or empty photo folder, before anything is written
    out = Path(args.out)
    start_folder(out, args)
    deadline = time.monotonic() + 60 * args.minutes
    overhead, rows = min(FIRST_OVERHEAD_S, 12 * args.minutes), []
    for i, name in enumerate(args.queue):
        left = deadline - time.monotonic()
        minutes = slot_minutes(left, args.queue[i:], overhead)
        if minutes < MIN_SLOT_MIN:
            print(f"{name}: skipped, {minutes:.2f} min of training left in its slot")
            rows.append({"model": name, "skipped": True})
            continue
        config = relay_config(name, args, out, minutes)
        print(f"{name}: {minutes:.2f} min at batch {args.batch}, peak lr {config.optim.lr:.2g}")
        began = time.monotonic()
        result = train(config, progress=args.progress)
        row = summarise(name, config, result)
        overhead = max(0.0, time.monotonic() - began - row["train_s"])
        if result.failure is None:
            shipped = load_model(name).meta.get("description", "").rstrip(".")
            export_model(
                result.run_dir,
                out / "candidates" / name,
                name=name,
                description=f"{shipped}; then {row['train_s'] / 60:.1f} GPU minutes "
                f"({row['steps']} steps of batch {row['batch']}, {row['device']}) by the GPU relay",
            )
        rows.append(row)
        write_table(out / "relay.md", rows, args)
    write_table(out / "relay.md", rows, args)
    print((out / "relay.md").read_text())
    return 0


def summarise(name: str, config, result) -> dict:
    from splitcam.io import checkpoints as ckpt_io
    from splitcam.training.rundir import metrics_rows

    meta = ckpt_io.load(result.run_dir / ckpt_io.CHECKPOINT_NAME).meta
    vals = [r for r in metrics_rows(result.run_dir) if any(k.startswith("val_psnr_") for k in r)]
    levels = sorted({k for r in vals for k in r if k.startswith("val_psnr_")})
    steps = int(meta["step"])
    seconds = float(meta.get("train_seconds", 0.0))
    return {
        "model": name,
        "steps": steps,
        "batch": config.data.batch_size,
        "patches": steps * config.data.batch_size,
        "train_s": seconds,
        "patches_per_s": steps * config.data.batch_size / max(seconds, 1e-9),
        "device": meta.get("device", "?"),
        "start": {k: vals[0].get(k) for k in levels} if vals else {},
        "end": {k: vals[-1].get(k) for k in levels} if vals else {},
        "failure": result.failure,
    }


def write_table(path: Path, rows: list[dict], args: argparse.Namespace) -> None:
    lines = [
        f"# Relay: {args.minutes:g} minutes, batch {args.batch}, on {args.device}",
        "",
        "| model | steps | patches | minutes | patches/s | validation start → end | device |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r.get("skipped"):
            lines.append(f"| {r['model']} | skipped: no time left in its slot | | | | | |")
            continue
        change = ", ".join(
            f"{k.removeprefix('val_psnr_')}: {r['start'][k]:.2f} → {r['end'][k]:.2f}"
            for k in r["start"]
            if r["start"][k] is not None and r["end"].get(k) is not None
        )
        if r["failure"]:
            change += f" (failed, not a candidate: {r['failure']})"
        lines.append(
            f"| {r['model']} | {r['steps']} | {r['patches']} | {r['train_s'] / 60:.2f} | "
            f"{r['patches_per_s']:.0f} | {change} | {r['device']} |"
        )
    path.write_text("\n".join(lines) + "\n")


# --- the gate, on a CPU --------------------------------------------------------------------


def held_out_photos(config: dict, data: Path) -> list[tuple[str, object]]:
    """The run's validation photos (the first 8 it holds out) and the last 12, whole."""
    import torch

    from splitcam.data.imageio import read_image
    from splitcam.data.patches import list_images
    from splitcam.training import TrainConfig
    from splitcam.training.validation import held_out

    settings = TrainConfig.from_saved(config).override({"data.train": str(data), "data.val": None})
    validation = held_out(settings)[: settings.data.val_max_images or VAL_FIRST]
    chosen = list(dict.fromkeys([*validation, *list_images(data)[-LAST_UNUSED:]]))
    return [(p.stem, torch.from_numpy(read_image(p)).permute(2, 0, 1).contiguous()) for p in chosen]


def gate_levels(config: dict) -> list:
    """The model's validation levels, cleanest first."""
    from splitcam.physics.noise import Exposure

    noise = config.get("noise") or {}
    if noise.get("model") == "photon":
        settings = {k: noise[k] for k in ("read_noise", "full_well", "gain", "bits") if k in noise}
        return [Exposure(float(n), **settings) for n in sorted(noise["val_photons"], reverse=True)]
    return sorted(float(s) for s in config["data"]["val_sigmas"])


def check_candidate(name: str, candidate, shipped) -> None:
    """Refuse a candidate that is not a continuation of the shipped model of its name: one that
    serves other patterns, or (for a network of one pattern) started from another pattern. A
    model that learns its pattern (A-opt) moves its pattern as it trains, so the patterns
    compared are the ones both started from, not the learned ones."""
    from splitcam import patterns
    from splitcam.recon.networks import serves_any_pattern

    any_shipped = serves_any_pattern(shipped.network)
    if serves_any_pattern(candidate.network) != any_shipped:
        raise RelayError(f"candidate {name}: it and the shipped {name} serve different patterns")
    if not any_shipped:
        start = patterns.Pattern.from_dict(candidate.meta["start_pattern"])
        shipped_start = shipped.meta.get("start_pattern")
        origin = patterns.Pattern.from_dict(shipped_start) if shipped_start else shipped.pattern
        if not start.equals(origin):
            raise RelayError(
                f"candidate {name} was trained from pattern {start.name}, the shipped {name} "
                f"from {origin.name}"
            )


def mean_scores(spec, config: dict, photos, levels, threads: int) -> list[float]:
    """Mean PSNR per level over the photos (and, for a network of any pattern, its validation
    patterns)."""
    from splitcam.evaluation.protocol import mean_psnr
    from splitcam.recon.registry import build_method

    domain = (config.get("data") or {}).get("domain") or "srgb"
    pats = config["pattern"]["val_patterns"] if config["pattern"]["name"] == "random" else [None]
    per_pattern = []
    for pattern in pats:
        method = build_method(spec, pattern=pattern, precision="fp32", domain=domain)
        scores = mean_psnr(method, photos, levels, domain=domain)
        per_pattern.append([scores[level] for level in scores])
    return [sum(col) / len(col) for col in zip(*per_pattern, strict=True)]


def run_gate(args: argparse.Namespace) -> int:
    import torch

    from splitcam.io.tensorfiles import paired_paths
    from splitcam.io.weights import MODELS_DIR
    from splitcam.physics.noise import level_label
    from splitcam.recon.loading import load_model, model_names

    folder = Path(args.gate)
    found = sorted((folder / "candidates").glob("*.json"))
    if not (folder / MARKER).exists() or not found:
        raise RelayError(f"{folder} holds no relay candidates (candidates/NAME.json)")
    ship_to = Path(args.ship_to) if args.ship_to else MODELS_DIR
    shipped_names = model_names()
    gated, refused = [], {}
    for path in found:
        try:
            if path.stem not in shipped_names:
                raise RelayError(f"candidate {path.stem}: no shipped model of that name")
            check_candidate(path.stem, load_model(path), load_model(path.stem))
            gated.append(path)
        except RelayError as err:
            refused[path.stem] = str(err)
            print(f"skipped: {err}", flush=True)
    torch.set_num_threads(args.threads)
    lines = [
        "# Gate: the validation photos and the last 12, whole; ship when the cleanest level "
        f"rises and the noisiest falls by no more than {GATE_FALL_DB} dB",
        "",
        "| model | photos | levels | shipped | candidate | change | ships |",
        "|---|---|---|---|---|---|---|",
    ]
    decisions = {}
    for name, reason in refused.items():
        decisions[name] = False
        lines.append(f"| {name} | | | | | not gated: {reason} | no |")
    for path in gated:
        name = path.stem
        config = load_model(path).meta["config"]
        photos = held_out_photos(config, Path(args.data))
        levels = gate_levels(config)
        before = mean_scores(name, config, photos, levels, args.threads)
        after = mean_scores(str(path), config, photos, levels, args.threads)
        change = [a - b for a, b in zip(after, before, strict=True)]
        ships = change[0] > GATE_RISE_DB and change[-1] >= -GATE_FALL_DB
        decisions[name] = ships
        fmt = " / ".join
        lines.append(
            f"| {name} | {len(photos)} | {fmt(level_label(v) for v in levels)} | "
            f"{fmt(f'{v:.2f}' for v in before)} | {fmt(f'{v:.2f}' for v in after)} | "
            f"{fmt(f'{v:+.2f}' for v in change)} | {'yes' if ships else 'no'} |"
        )
        print(lines[-1], flush=True)
    table = "\n".join(lines) + "\n"
    if args.dry_run:
        print(table)
        print("would ship: " + (", ".join(n for n, s in decisions.items() if s) or "nothing"))
        return 0
    (folder / "gate.md").write_text(table)
    for name, ships in decisions.items():
        if ships:
            for src in paired_paths(folder / "candidates" / name):
                shutil.copyfile(src, ship_to / src.name)
            print(f"shipped {name} into {ship_to}")
    print(table)
    return 0


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    from splitcam.data.registry import training_folder

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, help="wall-clock minutes the relay may take")
    parser.add_argument("--out", help="folder for runs, candidates and the table")
    parser.add_argument(
        "--data",
        default=str(training_folder()),
        help="training photos (default: $SPLITCAM_DATA/train, splitcam.data.registry)",
    )
    parser.add_argument("--queue", nargs="+", default=QUEUE, help="models, in order")
    parser.add_argument("--batch", type=int, default=256, help="patches per step")
    parser.add_argument(
        "--lr-rule",
        choices=["none", "sqrt", "linear"],
        default="none",
        help="how each recipe's peak rate carries to --batch (docs/results/batch: keeping it "
        "measured best at batch 64, the linear rule diverged)",
    )
    parser.add_argument("--device", default="cuda", help="cuda, cuda:N or cpu")
    parser.add_argument("--precision", default="auto", help="auto, fp32 or bf16")
    parser.add_argument("--compile", action="store_true", help="torch.compile the networks")
    parser.add_argument("--progress", action="store_true", help="progress bars")
    parser.add_argument("--gate", metavar="DIR", help="score a relay's candidates (on a CPU)")
    parser.add_argument("--dry-run", action="store_true", help="with --gate: change nothing")
    parser.add_argument("--threads", type=int, default=2, help="with --gate: CPU threads")
    parser.add_argument(
        "--ship-to", help="with --gate: ship into this folder (default: the package's)"
    )
    args = parser.parse_args(argv)
    if args.gate is None and (args.minutes is None or args.out is None):
        parser.error("give --minutes and --out (a relay) or --gate DIR")
    if args.gate is not None and args.minutes is not None:
        parser.error("--gate scores a finished relay: leave --minutes out")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        return run_gate(args) if args.gate else run_relay(args)
    except (RelayError, FileNotFoundError) as exc:
        print(f"relay: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
