"""`splitcam models`: list the shipped models, or export a run as a model."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import table


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "models",
        help="list the shipped trained models, or export a run as a model",
        description="`splitcam models` lists the trained models shipped with splitcam and their "
        "budget; `splitcam models export RUN --name NAME [--out DIR]` writes a run's network, "
        "pattern and provenance as NAME.safetensors + NAME.json (16-bit weights by default) "
        "into ./models (or --out DIR; --ship: the package's shipped models); an existing model "
        "is replaced only with --force. Use it with --model DIR/NAME.json.",
    )
    p.add_argument("action", nargs="?", choices=["list", "export"], default="list")
    p.add_argument("run", nargs="?", help="run folder or checkpoint (export)")
    p.add_argument("--name", help="model name (export)")
    p.add_argument("--out", help="folder to export into (default: ./models)")
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
    p.add_argument("--description", help="one line about the model")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..io import weights
    from ..recon.loading import load_model, model_names
    from ..training.models import export_model, model_summary

    if args.action == "export":
        if not args.run or not args.name:
            raise ValueError("models export needs a run folder and --name")
        if args.ship and args.out:
            raise ValueError("give --ship (into the package's shipped models) or --out, not both")
        out = (weights.MODELS_DIR if args.ship else Path(args.out or "models")) / args.name
        existing = [
            p for p in (out.with_suffix(".json"), out.with_suffix(".safetensors")) if p.exists()
        ]
        if existing and not args.force:
            what = f"the shipped model {args.name}" if args.ship else f"the model {existing[0]}"
            raise ValueError(f"{what} exists; --force replaces it")
        from ..io.checkpoints import which_checkpoint

        if (note := which_checkpoint(args.run)) is not None:
            print(note)
        path = export_model(
            args.run,
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
