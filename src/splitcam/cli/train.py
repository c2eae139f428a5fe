"""`splitcam train`: train a reconstruction network (optionally with the pattern)."""

from __future__ import annotations

import argparse
import os
import sys


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train",
        help="train a reconstruction network (optionally with the pattern)",
        description="Train the reconstruction network for a pattern, or the pattern and the "
        "network jointly (--learn-pattern). Settings: defaults (the paper's recipe) < --config "
        "FILE (TOML/YAML/JSON) < flags. Ctrl-C saves a checkpoint and exits; --resume "
        "continues a run.",
    )
    p.add_argument("--config", help="TOML, YAML or JSON configuration file")
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument(
        "--recipe",
        metavar="MODEL|FILE",
        help="train a shipped model (or a model's .json) again end to end: every stage its "
        "header records, with "
        "the settings and steps it recorded, in order, each from the last, into "
        '--out/<n>-<stage> (or the stages of a recipe FILE: stages = ["a.toml", ...]); a '
        "model blended from two trains each end and blends them; finished stages are skipped "
        "and an interrupted one resumed; other flags apply to every stage",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from ..training.config import train_flags

    # One flag per setting of the typed config, with its help and default from there. Every
    # default here is None, "not given": the config file's (or the dataclass's) value stays.
    for flag in train_flags():
        name = "--" + flag.name.replace("_", "-")
        text = flag.help.replace("%", "%%")
        if flag.kind is bool:  # --learn-pattern / --no-learn-pattern
            p.add_argument(name, action=argparse.BooleanOptionalAction, default=None, help=text)
        else:
            nargs = "+" if flag.many else None
            p.add_argument(name, type=flag.kind, nargs=nargs, default=None, help=text)
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..training import TrainConfig, train
    from ..training.config import dotted, read_config_file, train_flags
    from ..training.rundir import resume_config
    from ..training.starts import (
        FINE_TUNE_MINUTES,
        fine_tuning,
        own_pattern_start,
        photon_range,
        start_settings,
    )
    from ..training.sweep import STOPPED

    if args.recipe:
        return _run_recipe(args)
    if args.resume and not args.config:
        # Continue with the run's own settings (those of its checkpoint, or the config.json of a
        # run killed before its first one); flags given now override them.
        config = resume_config(args.out or TrainConfig().run.out)
        from_file = {}
    else:
        data = read_config_file(args.config) if args.config else {}
        if args.config:  # recorded in the provenance (a file may say otherwise)
            data.setdefault("run", {}).setdefault("config_file", args.config)
        config = TrainConfig.from_dict(data, source=args.config or "the defaults")
        from_file = dotted(data)  # the keys the file sets
    # Flags left out keep the config file's (or the default) value.
    overrides = {}
    for flag in train_flags():
        value = getattr(args, flag.name, None)
        if value is not None:
            overrides[flag.key] = value
    photon_only = sorted(k for k in overrides if k.startswith("noise.") and k != "noise.model")
    model = overrides.get("noise.model", config.noise.model)
    if photon_only and model != "photon":
        flags = ", ".join("--" + k.split(".", 1)[1].replace("_", "-") for k in photon_only)
        raise ValueError(f"{flags}: settings of the photon model; add --noise photon")
    if not args.resume:
        overrides.update(own_pattern_start({**from_file, **overrides}))
    init_from = overrides.get("run.init_from", config.run.init_from)
    given = {**from_file, **overrides}
    auto = not args.resume and init_from == "auto"
    if auto and "optim.steps" not in given and "run.time_limit" not in given:
        overrides["run.time_limit"] = FINE_TUNE_MINUTES
        print(f"fine-tuning for {FINE_TUNE_MINUTES:g} minutes (--time-limit), the search included")
    elif not args.resume and init_from and "network.arch" not in given:
        overrides.update(fine_tuning(init_from, given))
    if not args.resume and init_from and not auto:
        overrides.update(photon_range(init_from, given))
    config = config.override(overrides)
    if auto:
        from ..training.auto_init import choose_start

        config, _ = choose_start(config, lambda name: start_settings(name, given))
    # Under torchrun, train() also ends the process group, the same way on every rank.
    result = train(config, resume=args.resume, progress=not args.quiet)
    if int(os.environ.get("RANK", "0")) != 0:
        return 0  # under torchrun only rank 0 reports
    summary = ", ".join(
        f"{k} {v:.4g}"
        for k, v in result.last_metrics.items()
        if k in ("loss", "train_psnr", "val_psnr")
    )
    state = (
        "interrupted at" if result.interrupted else "failed at" if result.failure else "finished at"
    )
    print(f"{state} step {result.step}: {summary}; run folder {result.run_dir}")
    if result.failure:
        print(f"splitcam train: failed: {result.failure}", file=sys.stderr)
        return 1
    return STOPPED if result.interrupted else 0


def _run_recipe(args: argparse.Namespace) -> int:
    from ..training.config import train_flags
    from ..training.recipe import read_recipe, recipe_model, run_recipe
    from ..training.sweep import STOPPED

    if args.config or args.resume:
        raise ValueError(
            "--recipe names its own configuration files and continues by itself: "
            "leave --config and --resume out"
        )
    recipe = read_recipe(args.recipe)
    overrides = {}
    for flag in train_flags():
        value = getattr(args, flag.name, None)
        if value is not None and flag.key != "run.out":
            overrides[flag.key] = value
    out = args.out or f"runs/{recipe.model}"
    runs, blends = recipe.count()
    made_of = f"{runs} stages" + (f" and {blends} blend{'s' * (blends > 1)}" if blends else "")
    print(f"recipe {recipe.model}: {made_of} into {out}")
    results = run_recipe(recipe, out, overrides, progress=not args.quiet)
    if any(r.failure for r in results):
        print(f"splitcam train: failed: {results[-1].failure}", file=sys.stderr)
        return 1
    if any(r.interrupted for r in results):
        return STOPPED
    print(f"recipe {recipe.model}: every stage done; the model: {recipe_model(recipe, out)}")
    return 0
