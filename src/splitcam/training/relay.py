"""One command for a GPU's minutes: fine-tune a queue of shipped networks, then gate them on a CPU.

    python -m splitcam.training.relay --minutes 9 --out DIR [--data PHOTOS] [--batch 256]
    python -m splitcam.training.relay --gate DIR [--dry-run] [--data PHOTOS]

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
  training is skipped and said. Within a slot of two runs (``--colour``), the second gets what
  is left of the slot when the first ends, at most its planned share (:func:`run_slot`), so a
  first run that set up for longer than expected (mining) does not carry the relay past
  ``--minutes``.
- Every run checkpoints each minute of training (``run.checkpoint_minutes``) into
  ``DIR/runs/NAME``; each finished run is exported as ``DIR/candidates/NAME.json`` +
  ``.safetensors`` (provenance: device, minutes, steps and batch, so patches seen), and
  ``DIR/relay.md`` tables the validation PSNR at the start and the end of every run, and on a
  CPU how much of its threads each network had (:func:`cpu_share`: two relays side by side
  that each ask for all the cores get about half, which the thread count alone hides).

**The gate** (``--gate DIR``, on a CPU) scores the candidates by the rule every shipped model
passes (``splitcam.training.gate``, also ``splitcam models gate``): held-out photos at half
size, at the model's own validation levels; a candidate ships when the cleanest level rises and the
noisiest falls by no more than 0.05 dB. ``DIR/gate.md`` holds the table; ``--dry-run`` prints
what would ship and writes nothing.

**The colour stage** (``--colour``, ``docs/results/colour``): each network's slot
becomes the stage ``bayer`` shipped with, scaled to the GPU: two thirds of it with a quarter of
the patches taking another patch's chroma and a quarter chroma-moved (``COLOUR_STAGE``), then a
third on the photos alone at half the rate, continued from the first (``runs/NAME-colour``, then
``runs/NAME``); the candidate is the second, its provenance holding both segments.
``--colour-mined P`` adds to the colour part the third lever, patches mined where the shipped
network errs most (``data.colour_mined``, scored by ``--mine-score``: ``chroma`` or ``rgb``;
:mod:`splitcam.training.mining`); the cool-down trains on the photos alone, as without it.

**Half size** (``--half-size``): every run trains on the photos at half their size
(``data.scales = [0.5]``), where the JPEG photos' chroma is as fine as their luma
(``docs/results/colour``, "The photos' own chroma"), and validates on them at half size
(``data.val_scale``), as the gate scores.

**Recipes**: every run records its stage file, ``experiments/gpu/relay/DATE/RUN.toml`` (the
relay's start date, the run's folder name), as ``run.config_file``; shipping a candidate writes
those files, from the settings its provenance records, into the source checkout the package is
shipped into (into the ``--ship-to`` folder when one is given; :func:`stages_root`)
(:func:`write_stage_files`), so a shipped model stays its own recipe
(:mod:`splitcam.training.recipe`).

``--device cpu --minutes 0.5`` runs the same path end to end (the test suite does so on tiny
settings). How to run it on a lent GPU: ``experiments/gpu/README.md``.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

from .config import MINE_SCORES
from .gate import SCALE

logger = logging.getLogger(__name__)

QUEUE = ["universal", "universal-photon", "A", "D", "D-opt", "B", "A-opt"]
SHARES = {"universal": 3, "universal-photon": 2}
FIRST_OVERHEAD_S = 30.0
MIN_SLOT_MIN = 0.2
MARKER = "relay.json"
#: Where the stage files of the relay's runs are named (repository-relative)
STAGE_DIR = "experiments/gpu/relay"
#: The colour stage of ``--colour``: the share of the patches given another patch's chroma and
#: the share chroma-moved (the stage the shipped ``bayer`` passed its gate with)
COLOUR_STAGE = {"data.colour_swap": 0.25, "data.colour_chroma": 0.25}
#: Of a ``--colour`` slot: the share the cool-down on the photos alone takes, and its rate
#: relative to the recipe's
COOLDOWN_SHARE, COOLDOWN_LR = 1 / 3, 0.5
#: The photos' sizes under ``--half-size``: the gate's
HALF_SIZE = (SCALE,)


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
    from ..recon.loading import model_names

    shipped = model_names()
    unknown = [n for n in queue if n not in shipped]
    if unknown:
        raise RelayError(
            f"unknown model {unknown[0]!r} in the queue; shipped: {', '.join(shipped)}"
        )
    if len(set(queue)) != len(queue):
        raise RelayError("a model is named twice in the queue")


def check_configs(args: argparse.Namespace, out: Path) -> None:
    """Every queued network's runs validated before any trains, so that a setting one of them
    cannot take (``--colour-mined`` for ``universal``, which trains on a new pattern each
    step) is refused at the start, not after the networks before it have trained."""
    from .config import ConfigError

    for name in args.queue:
        for config in relay_configs(name, args, out, 1.0):
            try:
                config.validate()
            except ConfigError as exc:
                raise RelayError(f"{name}: {exc}") from None


def relay_configs(name: str, args: argparse.Namespace, out: Path, minutes: float) -> list:
    """The runs of one queued network, in order, each continuing the one before: its recipe
    alone, or (``--colour``) the colour stage and the cool-down on the photos."""
    config = relay_config(name, args, out, minutes)
    if not args.colour:
        return [config]
    colour_dir = out / "runs" / f"{name}-colour"
    stage = config.override(
        {
            **COLOUR_STAGE,
            "data.colour_mined": args.colour_mined,
            "data.mine_score": args.mine_score,
            "run.out": str(colour_dir),
            "run.config_file": stage_file(out, colour_dir.name),
            "run.time_limit": minutes * (1 - COOLDOWN_SHARE),
        }
    )
    cooldown = config.override(
        {
            "run.init_from": str(colour_dir),
            "optim.lr": config.optim.lr * COOLDOWN_LR,
            "run.time_limit": minutes * COOLDOWN_SHARE,
        }
    )
    return [stage, cooldown]


def stage_file(out: Path, run: str) -> str:
    """The stage file a run of the relay in ``out`` records: under :data:`STAGE_DIR`, by the
    relay's start date."""
    started = json.loads((out / MARKER).read_text())["started"][:10]
    return f"{STAGE_DIR}/{started}/{run}.toml"


def write_stage_files(candidate: Path, root: Path) -> list[Path]:
    """Write, under ``root``, the stage file of every segment of the model ``candidate`` (its
    JSON) that names one under :data:`STAGE_DIR` not yet there: the settings the segment
    recorded, as TOML (unset values left to their defaults), checked to read back as those
    settings (a setting added since they were recorded at the value that reproduces them).
    Returns the files written."""
    import tomli_w

    from .config import TrainConfig
    from .recipe import replayable

    meta = json.loads(candidate.read_text())
    written = []
    for segment in meta["provenance"]["segments"]:
        file = segment.get("config_file") or ""
        path = root / file
        if not file.startswith(STAGE_DIR + "/") or path.exists():
            continue
        # As a saved run reads them: a setting added since the segment trained takes the value
        # that reproduces it (TrainConfig.from_saved).
        settings = replayable(TrainConfig.from_saved(segment["settings"]).to_dict())
        body = {
            sec: {k: v for k, v in vals.items() if v is not None} for sec, vals in settings.items()
        }
        head = (
            f"# A segment of {meta['name']} trained by the relay (splitcam.training.relay):\n"
            f"# {segment['steps']} steps of batch {segment['batch_size']} in "
            f"{segment['train_seconds'] / 60:.2f} minutes on {segment['device']}.\n"
            f"# The settings it recorded; splitcam train --recipe {meta['name']} replays it.\n"
        )
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(head + tomli_w.dumps(body))
        if replayable(TrainConfig.from_file(path).to_dict()) != settings:
            path.unlink()
            raise RelayError(f"{file} does not read back as the settings {meta['name']} recorded")
        written.append(path)
    return written


def stages_root(ship_to: Path) -> Path | None:
    """Where shipping into ``ship_to`` writes the stage files: the source checkout whose
    package folder it is (None for an installed package), or ``ship_to`` itself for a folder
    of one's own; never the current folder."""
    from ..io.weights import MODELS_DIR

    if ship_to.resolve() != MODELS_DIR.resolve():
        return ship_to
    root = MODELS_DIR.parents[3]  # src/splitcam/weights/models
    return root if (root / STAGE_DIR).is_dir() else None


#: CPU threads the gate scores with unless ``--threads`` says otherwise.
GATE_THREADS = 2


def relay_config(name: str, args: argparse.Namespace, out: Path, minutes: float):
    """The run of one queued network: its shipped recipe from its weights, at the relay's
    batch, rate, time slot, device and photos."""
    from ..recon.loading import load_model
    from . import TrainConfig
    from .schedule import scaled_lr

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
            "run.config_file": stage_file(out, name),
            "run.device": args.device,
            "run.time_limit": minutes,
            "run.checkpoint_minutes": 1.0,
            "run.checkpoint_every": 10**9,
            "run.val_every": 10**9,  # at the start and the end only
            "run.log_every": 50,
            "run.threads": args.threads,  # None: torch's own count (all of a GPU host's cores)
            "run.precision": args.precision,
            "run.compile": args.compile,
            **(
                {"data.scales": list(HALF_SIZE), "data.val_scale": HALF_SIZE[0]}
                if args.half_size
                else {}
            ),
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
        "colour": args.colour,
        "colour_mined": args.colour_mined,
        "mine_score": args.mine_score,
        "half_size": args.half_size,
    }
    marker.write_text(json.dumps(record, indent=1) + "\n")


def run_relay(args: argparse.Namespace) -> int:
    from ..data.patches import list_images
    from ..recon.loading import load_model
    from .models import described, export_model

    if not args.minutes > 0:
        raise RelayError(f"--minutes must be > 0, got {args.minutes}")
    if args.batch < 1:
        raise RelayError(f"--batch must be >= 1, got {args.batch}")
    check_queue(args.queue)
    list_images(args.data)  # a missing or empty photo folder, before anything is written
    out = Path(args.out)
    existed = out.exists()
    start_folder(out, args)
    try:
        check_configs(args, out)
    except RelayError:
        (out / MARKER).unlink()
        if not existed:
            out.rmdir()
        raise
    deadline = time.monotonic() + 60 * args.minutes
    overhead, rows = min(FIRST_OVERHEAD_S, 12 * args.minutes), []
    for i, name in enumerate(args.queue):
        left = deadline - time.monotonic()
        minutes = slot_minutes(left, args.queue[i:], overhead)
        if minutes < MIN_SLOT_MIN:
            print(f"{name}: skipped, {minutes:.2f} min of training left in its slot")
            rows.append({"model": name, "skipped": True})
            continue
        configs = relay_configs(name, args, out, minutes)
        print(f"{name}: {minutes:.2f} min at batch {args.batch}, peak lr {configs[0].optim.lr:.2g}")
        began, cpu_began = time.monotonic(), time.process_time()
        parts, result = run_slot(name, configs, 60 * minutes + overhead, overhead, args.progress)
        row = combine(parts)
        if args.device == "cpu":
            import torch

            row["cpu_share"] = cpu_share(
                time.process_time() - cpu_began, time.monotonic() - began, torch.get_num_threads()
            )
        overhead = max(0.0, time.monotonic() - began - row["train_s"])
        if row["failure"] is None:
            shipped = described(load_model(name).meta).rstrip(".")
            what = colour_stage_words(args) if args.colour else "the relay"
            export_model(
                result.run_dir,
                out / "candidates" / name,
                name=name,
                description=f"{shipped}; then {row['train_s'] / 60:.1f} minutes of training "
                f"({row['steps']} steps of batch {row['batch']}, {row['device']}) of {what} "
                "by the relay",
            )
        rows.append(row)
        write_table(out / "relay.md", rows, args)
    write_table(out / "relay.md", rows, args)
    print((out / "relay.md").read_text())
    return 0


def run_slot(
    name: str, configs: list, slot_s: float, overhead_s: float, progress: bool, clock=None
) -> tuple[list[dict], object]:
    """Train one network's runs in order within ``slot_s`` seconds of wall time, of which
    ``overhead_s`` is the set-up and validation expected of all of them together. Each run gets
    its planned minutes, cut to what is left of the slot less its part of that overhead (never
    under :data:`MIN_SLOT_MIN`, or its plan where that is shorter): so a run that set up for
    longer than expected, mining its patches before the colour part trains, shortens the run
    after it instead of running past the slot. Returns the runs' :func:`summarise` rows and
    the last run's result."""
    from . import train

    clock = clock or time.monotonic
    end, parts, result = clock() + slot_s, [], None
    for config in configs:
        left = (end - clock() - overhead_s / len(configs)) / 60
        planned = config.run.time_limit
        if left < planned:
            logger.info("%s: %.2f of its %.2f min left in the slot", name, left, planned)
            config = config.override({"run.time_limit": max(left, min(planned, MIN_SLOT_MIN))})
        result = train(config, progress=progress)
        parts.append(summarise(name, config, result))
        if result.failure is not None:
            break
    return parts, result


def cpu_share(cpu_s: float, wall_s: float, threads: int) -> float:
    """The share of ``threads`` a process had over ``wall_s`` seconds in which it used ``cpu_s``
    seconds of CPU time (all its threads together): about 1 when nothing else ran on its cores,
    about 1/2 when another busy process shared them."""
    if threads < 1 or wall_s <= 0:
        raise ValueError(f"threads must be >= 1 and wall_s > 0, got {threads} and {wall_s}")
    return cpu_s / (wall_s * threads)


def colour_stage_words(args: argparse.Namespace) -> str:
    """What ``--colour`` trains each network on, in the words of the relay's table and of its
    candidates' descriptions."""
    mined = (
        f", {args.colour_mined:g} of its patches mined by {args.mine_score} error,"
        if args.colour_mined
        else ""
    )
    return f"a colour stage{mined} and a cool-down on the photos"


def summarise(name: str, config, result) -> dict:
    from ..io import checkpoints as ckpt_io
    from .rundir import metrics_rows

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


def combine(parts: list[dict]) -> dict:
    """One row for a network's runs in order: steps, patches and seconds summed, validation
    from the first run's start to the last run's end, the first failure."""
    row = dict(parts[-1])
    for key in ("steps", "patches", "train_s"):
        row[key] = sum(p[key] for p in parts)
    row["patches_per_s"] = row["patches"] / max(row["train_s"], 1e-9)
    row["start"] = parts[0]["start"]
    row["failure"] = next((p["failure"] for p in parts if p["failure"]), None)
    return row


def write_table(path: Path, rows: list[dict], args: argparse.Namespace) -> None:
    from ..evaluation.tables import markdown_table

    header = ["model", "steps", "patches", "minutes", "patches/s", "validation start → end"]
    header += ["device", "CPU used"]
    cells = []
    for r in rows:
        if r.get("skipped"):
            cells.append([r["model"], "skipped: no time left in its slot", *[""] * 6])
            continue
        change = ", ".join(
            f"{k.removeprefix('val_psnr_')}: {r['start'][k]:.2f} → {r['end'][k]:.2f}"
            for k in r["start"]
            if r["start"][k] is not None and r["end"].get(k) is not None
        )
        if r["failure"]:
            change += f" (failed, not a candidate: {r['failure']})"
        cells.append(
            [
                r["model"],
                str(r["steps"]),
                str(r["patches"]),
                f"{r['train_s'] / 60:.2f}",
                f"{r['patches_per_s']:.0f}",
                change,
                r["device"],
                f"{r['cpu_share']:.2f} of its threads" if "cpu_share" in r else "",
            ]
        )
    title = f"# Relay: {args.minutes:g} minutes, batch {args.batch}, on {args.device}"
    if args.colour:
        title += f" (each {colour_stage_words(args)})"
    lines = [title, "", *markdown_table(header, cells)]
    path.write_text("\n".join(lines) + "\n")


# --- the gate, on a CPU (splitcam.training.gate) -------------------------------------------


def run_gate(args: argparse.Namespace) -> int:
    from ..io.weights import MODELS_DIR
    from .gate import gate, gate_table, ship

    folder = Path(args.gate)
    found = sorted((folder / "candidates").glob("*.json"))
    if not (folder / MARKER).exists() or not found:
        raise RelayError(f"{folder} holds no relay candidates (candidates/NAME.json)")
    verdicts = gate(found, Path(args.data), threads=args.threads or GATE_THREADS)
    for verdict in verdicts:
        if verdict.refused is not None:
            print(f"skipped: {verdict.refused}", flush=True)
    table = gate_table(verdicts)
    if args.dry_run:
        print(table)
        names = [v.name for v in verdicts if v.ships]
        print("would ship: " + (", ".join(names) or "nothing"))
        return 0
    (folder / "gate.md").write_text(table)
    ship_to = Path(args.ship_to) if args.ship_to else MODELS_DIR
    root = stages_root(ship_to)
    for name in ship(verdicts, ship_to):
        print(f"shipped {name}")
        if root is None:
            print("  its stage files not written: the package is not a source checkout")
            continue
        for path in write_stage_files(ship_to / f"{name}.json", root):
            print(f"  its stage {path}")
    print(table)
    return 0


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    from ..data.registry import training_folder

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
    parser.add_argument(
        "--colour",
        action="store_true",
        help="each slot a colour stage (a quarter of the patches chroma-swapped, a quarter "
        "chroma-moved), then a third on the photos alone at half the rate",
    )
    parser.add_argument(
        "--colour-mined",
        type=float,
        default=0.0,
        metavar="P",
        help="with --colour: the share of the colour part's patches drawn from windows mined "
        "where the shipped network errs most (data.colour_mined)",
    )
    parser.add_argument(
        "--mine-score",
        choices=MINE_SCORES,
        default=MINE_SCORES[0],
        help="with --colour-mined: score the windows by their chroma error or by the error of "
        "all three channels (data.mine_score)",
    )
    parser.add_argument(
        "--half-size",
        action="store_true",
        help="train on the photos at half size, where their JPEG chroma is as fine as their luma",
    )
    parser.add_argument("--device", default="cuda", help="cuda, cuda:N or cpu")
    parser.add_argument("--precision", default="auto", help="auto, fp32 or bf16")
    parser.add_argument("--compile", action="store_true", help="torch.compile the networks")
    parser.add_argument("--progress", action="store_true", help="progress bars")
    parser.add_argument("--gate", metavar="DIR", help="score a relay's candidates (on a CPU)")
    parser.add_argument("--dry-run", action="store_true", help="with --gate: change nothing")
    parser.add_argument(
        "--threads",
        type=int,
        help="CPU threads of each run (default: torch's own count; give 1 to each of two "
        "relays side by side on a CPU, which otherwise share its cores at a fraction of the "
        f"speed) or, with --gate, of the scoring (default {GATE_THREADS})",
    )
    parser.add_argument(
        "--ship-to", help="with --gate: ship into this folder (default: the package's)"
    )
    args = parser.parse_args(argv)
    if args.gate is None and (args.minutes is None or args.out is None):
        parser.error("give --minutes and --out (a relay) or --gate DIR")
    if args.gate is not None and args.minutes is not None:
        parser.error("--gate scores a finished relay: leave --minutes out")
    if not 0 <= args.colour_mined <= 1:
        parser.error(f"--colour-mined must be a share in [0, 1], got {args.colour_mined}")
    if args.colour_mined and not args.colour:
        parser.error("--colour-mined mines patches for the colour stage: give --colour too")
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
