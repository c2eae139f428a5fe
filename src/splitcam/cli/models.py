"""`splitcam models`: list the shipped models, export a run as a model, or gate candidates."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import table


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "models",
        help="list the shipped trained models, export a run as a model, or gate candidates",
        description="`splitcam models` lists the trained models shipped with splitcam and their "
        "budget; `splitcam models export RUN --name NAME [--out DIR]` writes a run's network, "
        "pattern and provenance as NAME.safetensors + NAME.json (16-bit weights by default) "
        "into ./models (or --out DIR; --ship: the package's shipped models); an existing model "
        "is replaced only with --force. Use it with --model DIR/NAME.json. `splitcam models gate "
        "NAME.json ... --data DIR` scores exported candidates against the shipped models of "
        "their names on held-out photos of DIR, whole at half size, and says which pass (the "
        "cleanest level rises, the noisiest falls by no more than 0.05 dB; "
        "splitcam.training.gate); --ship copies those that pass into the package's shipped "
        "models (--out DIR: there). `splitcam models blend START.json END.json --weight W "
        "--name NAME` writes the model whose weights are (1 - W) START + W END (two models of "
        "one network and pattern, as a stage and the model it started from), a candidate for "
        "the gate like an exported one.",
    )
    p.add_argument("action", nargs="?", choices=["list", "export", "gate", "blend"], default="list")
    p.add_argument(
        "paths",
        nargs="*",
        metavar="PATH",
        help="run folder or checkpoint (export); candidates NAME.json (gate); the two models "
        "(blend: shipped names or NAME.json)",
    )
    p.add_argument("--name", help="model name (export, blend)")
    p.add_argument(
        "--weight",
        type=float,
        help="blend: the second model's share of every weight, in [0, 1]",
    )
    p.add_argument("--out", help="folder to export into (default: ./models); gate: ship into it")
    p.add_argument(
        "--data",
        help="gate: the training photos whose held-out ones score (default: $SPLITCAM_DATA/train)",
    )
    p.add_argument("--table", help="gate: also write the table to this Markdown file")
    p.add_argument("--threads", type=int, help="gate: CPU threads")
    p.add_argument(
        "--ship", action="store_true", help="export into the package's shipped models instead"
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing model of that name; export a run that ended in failure "
        "(recorded in its provenance)",
    )
    p.add_argument("--storage", choices=["float16", "bfloat16", "float32"], default="float16")
    p.add_argument(
        "--description",
        help="one line about the model (default: composed from its provenance: the network, "
        "pattern, light, noise and each stage's recipe and steps)",
    )
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..io import weights
    from ..recon.loading import load_model, model_names
    from ..training.models import export_model, model_summary

    if args.action == "gate":
        return run_gate(args)
    if args.action == "blend":
        return run_blend(args)
    if args.action == "export":
        if len(args.paths) != 1 or not args.name:
            raise ValueError("models export needs a run folder and --name")
        out = _target(args)
        from ..io.checkpoints import which_checkpoint

        if (note := which_checkpoint(args.paths[0])) is not None:
            print(note)
        path = export_model(
            args.paths[0],
            out,
            name=args.name,
            storage=args.storage,
            description=args.description or "",
            force=args.force,
        )
        size = path.with_suffix(".safetensors").stat().st_size
        print(f"wrote {path} and {path.with_suffix('.safetensors').name} ({size / 2**20:.2f} MiB)")
        return 0
    rows = [model_summary(name, load_model(name).meta) for name in model_names()]
    if not rows:
        print(f"no models shipped in {weights.MODELS_DIR}")
        return 0
    print(table(rows))
    return 0


def _target(args: argparse.Namespace) -> Path:
    """Where export or blend writes NAME: refused where a model is and --force is not given."""
    from ..io import weights

    if args.ship and args.out:
        raise ValueError("give --ship (into the package's shipped models) or --out, not both")
    out = (weights.MODELS_DIR if args.ship else Path(args.out or "models")) / args.name
    existing = [
        p for p in (out.with_suffix(".json"), out.with_suffix(".safetensors")) if p.exists()
    ]
    if existing and not args.force:
        what = f"the shipped model {args.name}" if args.ship else f"the model {existing[0]}"
        raise ValueError(f"{what} exists; --force replaces it")
    return out


def run_blend(args: argparse.Namespace) -> int:
    from ..training.models import blend_models

    if len(args.paths) != 2 or not args.name or args.weight is None:
        raise ValueError("models blend needs two models, --weight W and --name NAME")
    if args.ship:
        raise ValueError("a blend is a candidate: write it with --out and ship it through the gate")
    out = _target(args)
    path = blend_models(
        args.paths[0],
        args.paths[1],
        args.weight,
        out,
        name=args.name,
        storage=args.storage,
        description=args.description or "",
    )
    print(f"wrote {path} and {path.with_suffix('.safetensors').name}")
    return 0


def run_gate(args: argparse.Namespace) -> int:
    from ..data.registry import training_folder
    from ..io import weights, write_text
    from ..training.gate import gate, gate_table, ship

    if not args.paths:
        raise ValueError("models gate needs candidates: exported models NAME.json")
    if args.ship and args.out:
        raise ValueError("give --ship (into the package's shipped models) or --out, not both")
    for path in map(Path, args.paths):
        if path.suffix != ".json" or not path.is_file():
            raise ValueError(f"{path}: not an exported model (NAME.json; splitcam models export)")
    data = Path(args.data) if args.data else training_folder()
    if not data.is_dir():
        raise FileNotFoundError(f"no training photos at {data}: give --data DIR")
    if args.table and Path(args.table).is_dir():
        raise ValueError(f"--table {args.table} is a folder: give the Markdown file to write")
    verdicts = gate([Path(p) for p in args.paths], data, threads=args.threads)
    table = gate_table(verdicts)
    print(table)
    if args.table:  # its folder made as --out's are: minutes of gating are not lost to it
        Path(args.table).parent.mkdir(parents=True, exist_ok=True)
        write_text(args.table, table)
    ship_to = weights.MODELS_DIR if args.ship else Path(args.out) if args.out else None
    if ship_to is None:
        names = [v.name for v in verdicts if v.ships]
        print("would ship: " + (", ".join(names) or "nothing") + " (--ship ships them)")
        return 0
    for name in ship(verdicts, ship_to):
        print(f"shipped {name} into {ship_to}")
    return 0
