"""`splitcam report`: one report over evaluation results, beside the paper's numbers."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="one report over evaluation results, beside the paper's numbers",
        description="Takes folders written by `splitcam evaluate` and writes DIR/report.md (all "
        "methods side by side with the paper's Table 1-3 and the differences), a figure of "
        "every pattern (learned ones too) and a chart of PSNR and CIEDE2000 against sigma.",
    )
    p.add_argument("results", nargs="+", metavar="RESULTS", help="folders from `evaluate`")
    p.add_argument("--out", default="report", help="output folder (default: report)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..evaluation.report import make_report

    path = make_report(args.results, args.out)
    print(path.read_text(encoding="utf-8"))
    charts = [Path(args.out) / n for n in ("sigma_curves.png", "exposure_curves.png")]
    drawn = " and ".join(str(c) for c in charts if c.is_file())
    print(f"wrote {path} with pattern figures" + (f" and {drawn}" if drawn else ""))
    return 0
