"""`splitcam design`: design a pattern in seconds."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import check_writable, table


def _network_objective(args: argparse.Namespace) -> dict:
    """What ``design --objective network`` needs: the frozen network of ``--model`` and the
    patches of ``--data`` (:func:`splitcam.design.training_patches`)."""
    from ..design import training_patches
    from ..recon.loading import load_model
    from ..recon.networks import serves_any_pattern

    if not args.data:
        raise ValueError("--objective network needs training images: --data DIR")
    system = load_model(args.model)
    if not serves_any_pattern(system.network):
        raise ValueError(f"--model {args.model} serves one pattern; give a network for any pattern")
    patches, held_out = training_patches(args.data, seed=args.seed)
    return {
        "network": system.network,
        "patches": patches,
        "batch_size": args.batch_size,
        "held_out": held_out,
    }


def register(sub: argparse._SubParsersAction) -> None:
    from ..design.defaults import DEFAULT_LR, DEFAULT_SIGMAS, DEFAULT_STEPS, OBJECTIVES

    p = sub.add_parser(
        "design",
        help="design a pattern in seconds for the closed-form LMMSE",
        description="Optimises the kernels of a pattern (same layout and kernel size; softmax "
        "kernels, so non-negative and light-conserving) by gradient descent on the closed-form "
        "LMMSE error averaged over --sigmas, with no images. Writes the pattern file and a "
        "figure beside it (same name, .png: the start next to the designed pattern) and prints "
        "the closed-form PSNR per sigma before and after.",
    )
    p.add_argument("--pattern", default="D", help="start pattern, name or file (default: D)")
    p.add_argument("--out", required=True, help="pattern file to write (.toml or .json)")
    p.add_argument(
        "--init",
        choices=["support", "exact", "random"],
        default="support",
        help="start from the pattern's support (default), exactly, or at random",
    )
    p.add_argument(
        "--sigmas",
        type=float,
        nargs="+",
        default=list(DEFAULT_SIGMAS),
        metavar="SIGMA",
        help="noise levels of the objective, 8-bit units (default: "
        + " ".join(f"{s:g}" for s in DEFAULT_SIGMAS)
        + ")",
    )
    p.add_argument(
        "--steps", type=int, default=DEFAULT_STEPS, help=f"Adam steps (default {DEFAULT_STEPS})"
    )
    p.add_argument(
        "--lr", type=float, default=DEFAULT_LR, help=f"Adam learning rate (default {DEFAULT_LR})"
    )
    p.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default="mse",
        help="mse: the mean closed-form MSE over the sigmas (default); psnr: the mean PSNR; "
        "network: the PSNR of a frozen network for any pattern (--model) on training patches "
        "(--data), one sigma per step in turn",
    )
    p.add_argument(
        "--model",
        default="universal",
        help="with --objective network: the network (default universal)",
    )
    p.add_argument("--data", help="with --objective network: folder of training images")
    p.add_argument(
        "--batch-size", type=int, default=8, help="with --objective network: patches per step"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of --init random (default 0)")
    p.add_argument("--name", help="name of the designed pattern (default: START-designed)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    group = add_search_options(p, "--lr, --steps, --init, --seed and --objective (mse, psnr)")
    group.add_argument(
        "--report-every",
        type=int,
        default=50,
        metavar="STEPS",
        help="with --search: a trial designs in stages of STEPS steps and reports its score "
        "after each; from step 100 on, a trial below the median of the finished ones at the "
        "same step is pruned (0: one stage, no pruning; default 50)",
    )
    p.set_defaults(handler=run)


def add_search_options(p: argparse.ArgumentParser, searched: str) -> argparse._ArgumentGroup:
    """``--search N`` and ``--study DIR`` (shared with `optics`); returns their group."""
    g = p.add_argument_group("design search (Optuna; install with: pip install 'splitcam[search]')")
    g.add_argument(
        "--search",
        type=int,
        metavar="N",
        help=f"run N trials of a search over {searched}: each left at its default is searched, "
        "one given another value is held fixed. Prints the best trials, writes the best "
        "pattern to --out and the trials' patterns and figures to --study",
    )
    g.add_argument(
        "--study",
        default="search",
        metavar="DIR",
        help="with --search: the study's folder (journal file, trial patterns, figures; "
        "default search/). A search on an existing study adds trials to it; several "
        "processes or cluster jobs can run on one study at once",
    )
    g.add_argument(
        "--search-seed",
        type=int,
        default=0,
        metavar="S",
        help="with --search: seed of the sampler (default 0); give each process that shares "
        "a study its own, or they draw the same settings",
    )
    return g


def fixed_settings(args: argparse.Namespace, defaults: dict[str, tuple[str, object]]) -> dict:
    """The searched settings held fixed: those whose option has a value other than its
    default (``defaults``: setting -> (option attribute, default))."""
    return {
        name: getattr(args, attr)
        for name, (attr, default) in defaults.items()
        if getattr(args, attr) != default
    }


def fmt(value: object) -> str:
    """A parameter of a trial for a table."""
    return f"{value:.3g}" if isinstance(value, float) else str(value)


def search_error(command: str, exc: ModuleNotFoundError) -> int:
    """Say that optuna is missing (exit status 1); re-raise other missing modules."""
    import sys

    if exc.name != "optuna":
        raise exc
    print(f"splitcam {command}: error: {exc}", file=sys.stderr)
    return 1


def _search(args: argparse.Namespace, out: Path, start) -> int:
    """``design --search N``: the search, its table, the best pattern and the figures."""
    from ..design.defaults import DEFAULT_LR, DEFAULT_STEPS
    from ..design.search import search_patterns

    space = fixed_settings(
        args,
        {
            "lr": ("lr", DEFAULT_LR),
            "steps": ("steps", DEFAULT_STEPS),
            "init": ("init", "support"),
            "seed": ("seed", 0),
            "objective": ("objective", "mse"),
        },
    )
    if space.get("objective") == "network":
        raise ValueError("--search designs for the closed-form objectives: --objective mse or psnr")
    if args.search < 1:
        raise ValueError(f"--search needs a number of trials >= 1, got {args.search}")
    try:
        search = search_patterns(
            start,
            trials=args.search,
            folder=args.study,
            sigmas=args.sigmas,
            space=space,
            report_every=args.report_every,
            seed=args.search_seed,
            progress=not args.quiet,
        )
    except ModuleNotFoundError as exc:
        return search_error("design", exc)
    _print_search(search, space)
    return _write_best(search, args, out)


def _print_search(search, space: dict) -> None:
    """The state of the study and its ten best trials."""
    trials = search.study.trials
    states = [t.state.name.lower() for t in trials]
    fixed = ", ".join(f"{k} {fmt(v)}" for k, v in space.items()) or "none"
    print(
        f"search in {search.folder}: {len(trials)} trial{'s' * (len(trials) != 1)}, "
        f"{states.count('complete')} finished, "
        f"{states.count('pruned')} pruned (fixed: {fixed})"
    )
    finished = search.best()
    if not finished:
        return
    baseline = next((t.values[0] for t in finished if t.user_attrs.get("baseline")), None)
    rows = []
    for t in finished[:10]:
        row = {"trial": str(t.number), "PSNR (dB)": f"{t.values[0]:.3f}"}
        if baseline is not None:
            row["vs default"] = f"{round(t.values[0] - baseline, 3) + 0.0:+.3f}"
        row.update({k: fmt(t.params.get(k, "-")) for k in ("lr", "steps", "init", "objective")})
        row["seed"] = fmt(t.params.get("seed", "-"))
        row["s"] = f"{t.user_attrs.get('seconds', 0.0):.1f}"
        row["default"] = "yes" if t.user_attrs.get("baseline") else ""
        rows.append(row)
    print(f"best trials by closed-form LMMSE PSNR ({search.settings['metric']} over sigmas):")
    print(table(rows))


def _write_best(search, args: argparse.Namespace, out: Path) -> int:
    """Design the best trial again, check its score, write it to ``out`` and the figures."""
    import dataclasses

    from .. import patterns
    from ..viz.patterns import draw_design
    from ..viz.search import draw_curves

    best = search.trial()
    result, (score,) = search.reproduce(best.number)
    print(
        f"best trial {best.number}: {best.values[0]:.4f} dB; designed again: {score:.4f} dB"
        + ("" if abs(score - best.values[0]) < 1e-9 else " (differs: not reproduced)")
    )
    name = args.name or f"{result.start.name}-designed"
    metadata = {**result.pattern.metadata, "search": str(search.folder), "trial": best.number}
    pattern = dataclasses.replace(result.pattern, name=name, metadata=metadata)
    out.parent.mkdir(parents=True, exist_ok=True)
    patterns.save(pattern, out)
    figure = draw_design(result.start, pattern, out.with_suffix(".png"))
    curves = [
        (f"trial {t.number}", sorted(t.intermediate_values.items()), t.state.name == "PRUNED")
        for t in search.study.trials
        if t.intermediate_values
    ]
    curves_png = search.folder / "curves.png"
    draw_curves(curves, curves_png, title=f"design search from {result.start.name}")
    print(f"wrote {out}, {figure} and {curves_png}")
    return 0


def run(args: argparse.Namespace) -> int:
    from .. import patterns
    from ..design import design_pattern
    from ..viz.patterns import draw_design

    out = Path(args.out)
    if out.suffix.lower() not in (".toml", ".json"):
        raise ValueError(f"--out must end in .toml or .json, got {out.name!r}")
    check_writable(out)
    start = patterns.get(args.pattern)
    if args.search is not None:
        return _search(args, out, start)
    in_loop = _network_objective(args) if args.objective == "network" else {}
    result = design_pattern(
        start,
        init=args.init,
        sigmas=args.sigmas,
        steps=args.steps,
        lr=args.lr,
        seed=args.seed,
        objective=args.objective,
        name=args.name,
        progress=not args.quiet,
        **{k: v for k, v in in_loop.items() if k != "held_out"},
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    patterns.save(result.pattern, out)

    figure = draw_design(result.start, result.pattern, out.with_suffix(".png"))
    before, after = result.psnr_before, result.psnr_after
    rows = [
        {
            "sigma": f"{s:g}",
            result.start.name: f"{before[s]:.2f}",
            result.pattern.name: f"{after[s]:.2f}",
            "gain": f"{after[s] - before[s]:+.2f}",
        }
        for s in result.sigmas
    ]
    print(
        f"closed-form LMMSE PSNR (dB) from {result.start.name} ({args.init} start), "
        f"{args.steps} steps in {result.seconds:.1f} s:"
    )
    print(table(rows))
    if in_loop:
        from ..design import network_psnr

        held_out, net = in_loop["held_out"], in_loop["network"]
        before = network_psnr(result.start, net, held_out, result.sigmas)
        after = network_psnr(result.pattern, net, held_out, result.sigmas)
        print(f"{args.model} network PSNR (dB) on {len(held_out)} held-out patches:")
        print(
            table(
                [
                    {
                        "sigma": f"{s:g}",
                        result.start.name: f"{before[s]:.2f}",
                        result.pattern.name: f"{after[s]:.2f}",
                        "gain": f"{after[s] - before[s]:+.2f}",
                    }
                    for s in result.sigmas
                ]
            )
        )
    print(f"wrote {out} and {figure}")
    return 0
