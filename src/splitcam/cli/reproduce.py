"""`splitcam reproduce`: the paper's Tables 1-3 and Fig. 9 from the shipped models."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..io.paper import PAPER_PATTERNS, PAPER_SIGMAS
from ._common import add_flips, add_precision, with_flips


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="the paper's Tables 1-3 and Fig. 9 from the shipped models",
        description="Evaluates the shipped models (and Malvar 2004, the LMMSE of every pattern) on "
        "Kodak24 + McMaster at sigma 0-20 and writes OUT/reproduce.md: Table 1 with ranks, "
        "Tables 2 and 3, Fig. 9, the paper's conclusions checked, the learned patterns and the "
        "zoomed crops (kodim05 at sigma 10, kodim24 at sigma 5), beside the paper's numbers. "
        "Resumable: run it again to continue.",
    )
    p.add_argument("--datasets", default="kodak24,mcmaster")
    p.add_argument("--sigmas", type=float, nargs="+", default=list(PAPER_SIGMAS))
    p.add_argument("--out", default="reproduce")
    p.add_argument("--max-images", type=int, help="at most this many images per dataset")
    p.add_argument("--no-baselines", action="store_true")
    p.add_argument(
        "--update",
        action="store_true",
        help="score again the models whose shipped weights changed since the folder's results "
        "(a model shipped since), keeping every other row",
    )
    p.add_argument("--tile", type=int, default=512)
    # float32 by default: the committed tables are float32, and a resumed run adds rows to them.
    add_precision(p, "fp32")
    add_flips(p)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..data.testsets import load_datasets
    from ..evaluation.protocol import evaluate
    from ..evaluation.report import PAPER_MODELS, paper_tables
    from ..evaluation.tables import summarise
    from ..recon.loading import load_model, model_names
    from ..recon.registry import build_method, build_model
    from ..training.models import training_budget

    rows = dict(PAPER_MODELS)
    shipped = set(model_names())
    rows = {r: m for r, m in rows.items() if m in shipped}
    if not rows:
        raise ValueError("no shipped models to reproduce the paper with")
    methods = [build_model(m, tile=args.tile, precision=args.precision) for m in rows.values()]
    methods = with_flips(methods, args.flips)
    networks = {r: m.name for r, m in zip(rows, methods, strict=True)}
    if not args.no_baselines:
        methods.append(build_method("malvar2004"))
        methods += [build_method("lmmse", pattern=p) for p in PAPER_PATTERNS]
    datasets = load_datasets(args.datasets, args.max_images)
    names = {n for _, images in datasets for n, _ in images}
    # The paper's Figs. 4, 5, 7, 8: kodim05 at sigma 10, kodim24 at sigma 5.
    zoom_spec = [f"{z}@{s:g}" for z, s in (("kodim05", 10.0), ("kodim24", 5.0)) if z in names]
    out = Path(args.out)
    evaluation = out / "evaluation"
    result = evaluate(
        methods,
        datasets,
        args.sigmas,
        evaluation,
        zoom_images=zoom_spec,
        zoom_only=True,
        progress=not args.quiet,
        rescore_changed=args.update,
    )
    summary = summarise(result)
    from ..recon.base import fast_precision

    inference = "bfloat16" if fast_precision(args.precision, "cpu") else "float32"
    budgets, learned = {}, {}
    for row, name in rows.items():
        meta = load_model(name).meta
        flips = ", averaged over its sensor's exact flips (--flips)" if args.flips else ""
        budgets[row] = f"{training_budget(meta)}; evaluated in {inference}{flips}"
        if meta["pattern"].get("provenance") == "learned":
            from ..patterns import Pattern

            learned[row] = Pattern.from_dict(meta["pattern"])
    zooms = (
        sorted(str(p.relative_to(out)) for p in (evaluation / "zoom").glob("*.png"))
        if (evaluation / "zoom").is_dir()
        else []
    )
    report = paper_tables(
        summary,
        networks,
        out,
        budgets=budgets,
        learned=learned,
        zooms=zooms,
        baselines={r: f"lmmse-{r}" for r in PAPER_PATTERNS},
    )
    print(report.read_text(encoding="utf-8"))
    print(f"wrote {report}")
    return 0
