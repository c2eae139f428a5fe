"""`splitcam evaluate`: score trained networks and baselines with the paper's protocol."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..io.domains import DEFAULT_DOMAIN, DOMAINS
from ..io.paper import PAPER_PATTERNS, PAPER_SIGMAS
from ._common import (
    add_method_options,
    add_sensor_options,
    model_methods,
    sensor_flags_given,
    sensor_settings,
    warn_failed_runs,
    with_flips,
)

#: The main job (``splitcam evaluate`` with no method named) scores centre crops of this size of
#: the built-in photos, which keeps every shipped network on all six scenes within about 3 minutes
#: on a 2-core CPU in float32 (whole photos take several times longer).
MAIN_JOB_MAX_SIZE = 256


def _serves_one_of(model: str, given: list) -> bool:
    """Whether a shipped model reconstructs one of the patterns ``given`` (read already): a
    network for any pattern does; a network of one pattern if it is among them."""
    from ..recon.loading import load_model, model_serves_any_pattern

    if model_serves_any_pattern(model):
        return True
    own = load_model(model).pattern
    return any(g.pattern.equals(own) for g in given)


def _shipped_models() -> list[str]:
    """The shipped models' names, read from the weights folder (no torch import: --help stays
    fast)."""
    from ..io.weights import MODELS_DIR

    return sorted(p.stem for p in MODELS_DIR.glob("*.json"))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate",
        help="score trained runs and baselines with the paper's protocol",
        description="Simulates every test image with each method's pattern, adds the same "
        "deterministic noise for every method, reconstructs, and scores PSNR, SSIM and "
        "CIEDE2000 on 8-bit images. With no --checkpoint, --model or --method (the main job): "
        "the shipped network of every pattern and the training-free baselines (LMMSE for every "
        "pattern, bayer + Malvar 2004).",
    )
    _add_method_choice(p)
    _add_scene_options(p)
    _add_output_options(p)
    add_method_options(p)
    p.add_argument(
        "--restart",
        action="store_true",
        help="recompute everything instead of continuing the results in --out",
    )
    p.add_argument(
        "--update",
        action="store_true",
        help="score again the methods whose weights, pattern or precision changed since the "
        "folder's results (a model shipped since), keeping every other row",
    )
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=run)


def _add_method_choice(p: argparse.ArgumentParser) -> None:
    """What is scored: runs, shipped models, baselines, and their patterns."""
    p.add_argument(
        "--checkpoint",
        action="append",
        default=[],
        metavar="RUN",
        help="a trained run (repeatable)",
    )
    p.add_argument(
        "--method",
        action="append",
        metavar="NAME",
        help="baseline: bilinear, malvar2004, menon2007 (bayer), lmmse, or demosaicnet (the "
        "released networks of Gharbi et al. 2016 for bayer and xtrans; the optional extra "
        "splitcam[demosaicnet]) (repeatable)",
    )
    p.add_argument(
        "--model",
        action="append",
        default=[],
        metavar="NAME",
        help=f"a shipped model ({', '.join(_shipped_models())}; `splitcam models` describes "
        "them) or a model file (repeatable)",
    )
    p.add_argument(
        "--patterns",
        type=lambda s: [x for x in s.split(",") if x],
        default=None,
        help="the patterns of lmmse, demosaicnet and of a network for any pattern, comma-separated "
        f"names or files (default: {','.join(PAPER_PATTERNS)}); with no method named, the main "
        "job on these patterns only",
    )


def _add_scene_options(p: argparse.ArgumentParser) -> None:
    """What it is scored on: images, noise levels, the sensor, the light domain, crops."""
    p.add_argument(
        "--datasets",
        default="default",
        help="comma-separated: kodak24, mcmaster, folders; default: the sample photos "
        "shipped with scikit-image",
    )
    p.add_argument(
        "--sigmas",
        type=float,
        nargs="+",
        help="Gaussian noise levels, 8-bit units (default: 0 5 10 15 20, or none with --photons)",
    )
    p.add_argument(
        "--photons",
        type=float,
        nargs="+",
        metavar="N",
        help="photon-model exposures too: full-light photo-electrons of a lossless pixel (shot "
        "and read noise, the same photon flux for every pattern; rows N<photons>)",
    )
    add_sensor_options(p)
    p.add_argument(
        "--domain",
        choices=DOMAINS,
        default=DEFAULT_DOMAIN,
        help="light domain: srgb (default, the paper's protocol: 8-bit values taken as light) or "
        "linear (scenes decoded to linear radiance before the sensor and the noise, "
        "reconstructions encoded back to 8-bit sRGB before scoring; the LMMSE uses the linear "
        "image statistics, and a network must have been trained in the same domain)",
    )
    p.add_argument("--max-images", type=int, help="use at most N images per dataset")
    p.add_argument(
        "--max-size",
        type=int,
        metavar="N",
        help="score the centre N x N pixels of each image (dataset named NAME-Npx); default: "
        f"whole images, except the main job (no method named, built-in photos): "
        f"{MAIN_JOB_MAX_SIZE}; 0: whole images there too",
    )
    p.add_argument(
        "--crop",
        type=int,
        default=0,
        help="border pixels left out of the scores (default 0, as in the paper)",
    )


def _draw_charts(out: Path, rows: list, summary: dict) -> list[Path]:
    """PSNR against σ (Gaussian levels) and against exposure (photon levels) for each pooled
    image set (``sigma_curves.png``; ``sigma_curves_all-256px.png`` ... in a folder of whole
    photos and crops), where it has two levels or more to draw; charts that would not match
    the table are removed. Returns what was written."""
    from ..evaluation.tables import pooled_groups
    from ..physics.noise import parse_level_label

    for stale in [*out.glob("sigma_curves*.png"), *out.glob("exposure_curves*.png")]:
        stale.unlink()
    written = []
    pools = pooled_groups(rows)
    for pool in pools:
        suffix = "" if pool == "all" else f"_{pool}"
        curves = [(name, entry[pool]) for name, entry in summary.items() if pool in entry]
        levels: dict[str, set[str]] = {"sigma": set(), "photons": set()}
        for _, curve in curves:
            for level in curve:
                levels[parse_level_label(level)[0]].add(level)
        if len(levels["sigma"]) > 1:
            from ..viz.charts import sigma_chart

            path = out / f"sigma_curves{suffix}.png"
            sigma_chart(curves, path, patterns_of={n: e["pattern"] for n, e in summary.items()})
            written.append(path)
        photon = levels["photons"]
        if len(photon) > 1:
            from ..viz.charts import exposure_chart

            path = out / f"exposure_curves{suffix}.png"
            results = {
                name: {parse_level_label(lv)[1]: c[lv] for lv in c if lv in photon}
                for name, c in curves
            }
            networks = {n: e["pattern"] for n, e in summary.items() if not n.startswith("lmmse")}
            exposure_chart(results, path, title=f"{pool}: PSNR against exposure", networks=networks)
            written.append(path)
    return written


def run(args: argparse.Namespace) -> int:
    from ..data.testsets import load_datasets
    from ..evaluation.protocol import evaluate, parse_zoom
    from ..recon.registry import build_methods

    zooms = [parse_zoom(z) for z in args.zoom or ()]  # bad syntax fails before any work
    chosen = args.checkpoint or args.method or args.model
    if args.max_images is not None and args.max_images < 1:
        raise ValueError(
            f"--max-images must be >= 1 (leave it out for every image), got {args.max_images}"
        )
    if args.zoom and chosen and not args.save_images:
        raise ValueError(
            "--zoom draws zoomed side-by-side crops only with --save-images (the main job, with "
            "no method named, draws them anyway)"
        )
    options = {"tile": args.tile, "precision": args.precision, "domain": args.domain}
    # Built-in defaults (the main job): every shipped network, and the training-free baselines,
    # on centre crops of the built-in photos (within 3 minutes on a 2-core CPU): the shipped
    # networks of the evaluation's light domain (srgb by default; linear: those trained on
    # photons in linear light).
    models = _models(args, chosen)  # reads --patterns (args.given)
    max_size = args.max_size
    if max_size is None and not chosen and args.datasets == "default":
        max_size = MAIN_JOB_MAX_SIZE
    specs = [
        *args.checkpoint,
        *(args.method or ([] if chosen else ["lmmse", "malvar2004"])),
    ]
    warn_failed_runs([*args.checkpoint, *(args.method or [])])
    methods = model_methods(models, args.given, main_job=not chosen, options=options)
    methods += build_methods(
        specs,
        patterns_for_lmmse=args.given,
        lmmse_train=args.lmmse_train,
        tile=args.tile,
        precision=args.precision,
        progress=not args.quiet,
        domain=args.domain,
    )
    methods = with_flips(methods, args.flips)
    from ..physics.noise import Exposure

    if not args.photons and sensor_flags_given(args):
        raise ValueError(
            f"{', '.join(sensor_flags_given(args))} describe the photon model's sensor and have "
            f"no effect without --photons (the exposures to score)"
        )
    exposures = [Exposure(n, **sensor_settings(args)) for n in args.photons or ()]  # checked first
    paper_sigmas = list(PAPER_SIGMAS)
    sigmas = args.sigmas if args.sigmas is not None else [] if exposures else paper_sigmas
    datasets = load_datasets(args.datasets, args.max_images, max_size or None)
    try:
        rows = evaluate(
            methods,
            datasets,
            [*sigmas, *exposures],
            args.out,
            save_images=args.save_images,
            zoom_images=zooms if args.zoom else None,
            crop=args.crop,
            progress=not args.quiet,
            resume=not args.restart,
            rescore_changed=args.update,
            # the main job (no method named) also draws the zoomed side-by-side crops
            zoom_only=not chosen and not args.save_images,
            domain=args.domain,
        )
    except KeyboardInterrupt:
        print(
            f"splitcam evaluate: interrupted; the results so far are in "
            f"{args.out}/per_image.csv: run the same command again to continue",
            file=sys.stderr,
        )
        return 130
    _report(args, rows, chosen)
    return 0


def _models(args: argparse.Namespace, chosen: bool) -> list[str]:
    """The shipped models to evaluate: those named, or for the main job every shipped network
    of the evaluation's light domain (of the patterns asked for, where ``--patterns`` is
    given; it defaults to the paper's)."""
    from .. import patterns
    from ..recon.loading import model_names
    from ..recon.registry import model_domain

    given_patterns = args.patterns is not None
    if not given_patterns:
        args.patterns = list(PAPER_PATTERNS)
    args.given = [patterns.read(p) for p in args.patterns]  # each pattern read once
    if chosen:
        return args.model
    models = model_names()
    if given_patterns:
        # The main job on the patterns asked for: their own networks and the network for any
        # pattern, not every shipped network.
        models = [m for m in models if _serves_one_of(m, args.given)]
        print(f"the main job on {', '.join(args.patterns)}: {', '.join(models) or 'no network'}")
    other = [m for m in models if model_domain(m) != args.domain]
    if other:
        print(
            f"shipped networks of another light domain left out of this {args.domain}-domain "
            f"evaluation: {', '.join(other)}"
        )
    return [m for m in models if m not in other]


def _report(args: argparse.Namespace, rows: list, chosen: bool) -> None:
    """Print the tables of what the folder holds (this evaluation's rows and those of others
    kept beside them), draw the charts, and say what was written."""
    from ..evaluation.tables import CSV_NAME, markdown_tables, read_rows, summarise

    kept = read_rows(Path(args.out) / CSV_NAME)
    summary = summarise(kept)
    print(markdown_tables(summary))
    if len(kept) > len(rows):
        others = sorted({r.method for r in kept} - {r.method for r in rows})
        if others:
            print(f"(the table keeps the earlier results in {args.out} of: {', '.join(others)})")
        else:
            print(
                f"(the table keeps earlier results in {args.out} of these methods, on other "
                "images or levels)"
            )
    written = "per_image.csv, summary.json and table.md"
    for chart in _draw_charts(Path(args.out), kept, summary):
        written += f", {chart.name}"
    zoom = Path(args.out) / "zoom"
    if (not chosen or args.save_images) and zoom.is_dir() and any(zoom.iterdir()):
        written += " and the zoomed crops in zoom/"
    print(f"wrote {args.out}/{written}")


def _add_output_options(p: argparse.ArgumentParser) -> None:
    """What ``evaluate`` writes: the folder, reconstructions and zoomed crops."""
    p.add_argument("--out", default="results", help="output folder (default: results)")
    p.add_argument(
        "--save-images",
        action="store_true",
        help="write reconstructions and zoomed side-by-side crops",
    )
    p.add_argument(
        "--zoom",
        action="append",
        metavar="IMAGE[:TOP,LEFT,SIZE][@SIGMA]",
        help="image (and region, and noise level) for zoomed side-by-side crops (default: the "
        "most detailed region of the first image of each dataset, at every level)",
    )
