"""`splitcam plot`: a run's curves, or several runs compared."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plot",
        help="draw a run's loss and validation PSNR curves (several runs: compare them)",
        description="One run: loss and PSNR against step (RUN/curves.png). Several runs: their "
        "validation PSNR against wall-clock time and against step, side by side.",
    )
    p.add_argument("run", nargs="+", help="run folder(s) (with metrics.jsonl)")
    p.add_argument("--out", help="PNG (default: RUN/curves.png, or runs_compared.png)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..viz.curves import compare_runs, plot_run

    if len(args.run) > 1:
        out = compare_runs(args.run, args.out or "runs_compared.png")
    else:
        out = plot_run(args.run[0], args.out)
    print(f"wrote {out}")
    return 0
