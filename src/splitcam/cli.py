"""The ``splitcam`` command. It only parses arguments and calls the library.

Errors a user can cause (a bad pattern, an unreadable image, a missing folder) are printed as one
line, ``splitcam <command>: error: ...``, with exit status 1; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from . import __version__

Handler = Callable[[argparse.Namespace], int]


def _table(rows: list[dict[str, str]]) -> str:
    """A Markdown table (also readable as plain text)."""
    keys = list(rows[0])
    widths = {k: max(len(k), *(len(r[k]) for r in rows)) for k in keys}
    lines = ["| " + " | ".join(k.ljust(widths[k]) for k in keys) + " |"]
    lines.append("|" + "|".join("-" * (widths[k] + 2) for k in keys) + "|")
    lines += ["| " + " | ".join(r[k].ljust(widths[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def cmd_patterns(args: argparse.Namespace) -> int:
    from . import patterns

    if args.action == "list":
        names = args.names or patterns.names()
        rows = []
        for name in names:
            p = patterns.get(name)
            rows.append({**patterns.measure(p).row(), "provenance": p.provenance})
        print(_table(rows))
        return 0
    if len(args.names) != 1:
        raise ValueError(f"'patterns {args.action}' takes one pattern name or file")
    pattern = patterns.get(args.names[0])
    if args.action == "show":
        from .viz.patterns import draw_pattern

        out = Path(args.out or f"pattern_{pattern.name}.png")
        draw_pattern(pattern, out)
        print(f"wrote {out}")
    else:
        out = Path(args.out or f"{pattern.name}.toml")
        patterns.save(pattern, out)
        print(f"wrote {out}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    import torch

    from . import patterns
    from .data.imageio import read_image, write_image, write_raw
    from .physics.sensor import SplitterSensor
    from .physics.system import simulate
    from .viz.raw import false_colour

    image = Path(args.image)
    pattern = patterns.get(args.pattern)
    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".npy"):
        raise ValueError(f"--out must end in .png or .npy, got {out.name!r}")
    rgb = torch.from_numpy(read_image(image)).permute(2, 0, 1)[None]
    # The evaluation protocol's simulation: float64 sensor, noise seeded from the image name and
    # sigma, so a simulation is reproducible and matches what `splitcam evaluate` feeds methods.
    raw = simulate(SplitterSensor(pattern), rgb, image.stem, args.sigma)[0, 0].numpy()
    out.parent.mkdir(parents=True, exist_ok=True)
    scale = write_raw(out, raw)
    preview = Path(args.preview) if args.preview else out.with_name(out.stem + "_preview.png")
    write_image(preview, false_colour(raw, pattern))
    stored = f"16-bit PNG, full scale {scale:g}" if out.suffix.lower() == ".png" else "float32"
    print(
        f"pattern {pattern.name}, sigma {args.sigma:g}: raw {raw.shape[1]}x{raw.shape[0]}, "
        f"values {raw.min():.3f}..{raw.max():.3f}"
    )
    print(f"wrote {out} ({stored}) and {preview} (false-colour preview)")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from .training import TrainConfig, train
    from .training.config import train_flags
    from .training.trainer import resume_config

    if args.resume and not args.config:
        # Continue with the run's own settings (those of its checkpoint, or the config.json of a
        # run killed before its first one); flags given now override them.
        config = resume_config(args.out or TrainConfig().run.out)
    else:
        config = TrainConfig.from_file(args.config) if args.config else TrainConfig()
    # Flags left out keep the config file's (or the default) value.
    overrides = {}
    for flag in train_flags():
        value = getattr(args, flag.name, None)
        if value is not None:
            overrides[flag.key] = value
    config = config.override(overrides)
    # Under torchrun, train() also ends the process group, the same way on every rank.
    result = train(config, resume=args.resume, progress=not args.quiet)
    if int(os.environ.get("RANK", "0")) != 0:
        return 0  # under torchrun only rank 0 reports
    summary = ", ".join(
        f"{k} {v:.4g}"
        for k, v in result.last_metrics.items()
        if k in ("loss", "train_psnr", "val_psnr")
    )
    state = "interrupted at" if result.interrupted else "finished at"
    print(f"{state} step {result.step}: {summary}; run folder {result.run_dir}")
    return 130 if result.interrupted else 0


def cmd_design(args: argparse.Namespace) -> int:
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from . import patterns
    from .recon.design import design_pattern
    from .viz.patterns import draw_pattern

    out = Path(args.out)
    if out.suffix.lower() not in (".toml", ".json"):
        raise ValueError(f"--out must end in .toml or .json, got {out.name!r}")
    result = design_pattern(
        args.pattern,
        init=args.init,
        sigmas=args.sigmas,
        steps=args.steps,
        lr=args.lr,
        seed=args.seed,
        objective=args.objective,
        name=args.name,
        progress=not args.quiet,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    patterns.save(result.pattern, out)

    # The figure: the start (left) and the designed pattern (right), each drawn by draw_pattern.
    halves = []
    for pattern in (result.start, result.pattern):
        fig = draw_pattern(pattern, dpi=110)
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        halves.append(np.asarray(canvas.buffer_rgba())[..., :3])
    height = max(h.shape[0] for h in halves)
    halves = [
        np.pad(h, ((0, height - h.shape[0]), (0, 0), (0, 0)), constant_values=255) for h in halves
    ]
    gap = np.full((height, 24, 3), 255, dtype=np.uint8)
    gap[:, 11:13] = 160
    image = np.concatenate([halves[0], gap, halves[1]], axis=1)
    dpi = 110
    fig = Figure(figsize=(image.shape[1] / dpi, image.shape[0] / dpi), dpi=dpi)
    fig.figimage(image)
    figure = out.with_suffix(".png")
    fig.savefig(figure, dpi=dpi)

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
    print(_table(rows))
    print(f"wrote {out} and {figure}")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from .viz.curves import compare_runs, plot_run

    if len(args.run) > 1:
        out = compare_runs(args.run, args.out or "runs_compared.png")
    else:
        out = plot_run(args.run[0], args.out)
    print(f"wrote {out}")
    return 0


def cmd_reconstruct(args: argparse.Namespace) -> int:
    import torch

    from . import patterns
    from .data.imageio import read_image, read_raw, write_image
    from .methods import build_method
    from .physics.sensor import SplitterSensor
    from .physics.system import simulate

    if (args.image is None) == (args.raw is None):
        raise ValueError("give exactly one of --image (simulate, then reconstruct) or --raw")
    spec = args.method or args.checkpoint
    if spec is None:
        raise ValueError("give --method (lmmse, malvar2004, ..., or a run folder) or --checkpoint")
    method = build_method(
        spec,
        pattern=args.pattern,
        lmmse_train=args.lmmse_train,
        tile=args.tile,
        fast=args.fast,
        progress=not args.quiet,
    )
    if args.pattern is not None and not patterns.get(args.pattern).equals(method.pattern):
        raise ValueError(
            f"--pattern {args.pattern} differs from the pattern of {spec} ({method.pattern.name})"
        )
    if args.image:
        rgb = torch.from_numpy(read_image(args.image)).permute(2, 0, 1)[None]
        raw = simulate(SplitterSensor(method.pattern), rgb, Path(args.image).stem, args.sigma)
    else:
        raw = torch.from_numpy(read_raw(args.raw))[None, None]
    with torch.no_grad():
        out = method.reconstruct(raw, args.sigma)
    write_image(args.out, out[0].clamp(0, 1))
    print(f"{method.name}: wrote {args.out} ({out.shape[-1]}x{out.shape[-2]})")
    return 0


def load_datasets(spec: str | None, max_images: int | None) -> list:
    """``[(dataset name, [(image name, rgb)])]`` for a comma-separated list of names/folders."""
    from .data.testsets import default_images, load_images

    if not spec or spec == "default":
        images = default_images()
        return [("skimage", images[:max_images] if max_images else images)]
    out = []
    for item in (s.strip() for s in spec.split(",") if s.strip()):
        images = load_images(item)
        out.append((Path(item).name or item, images[:max_images] if max_images else images))
    return out


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluation.protocol import evaluate, parse_zoom
    from .evaluation.tables import markdown_tables, summarise
    from .methods import build_methods

    zooms = [parse_zoom(z) for z in args.zoom or ()]  # bad syntax fails before any work
    specs = [
        *args.checkpoint,
        *(args.method or ([] if args.checkpoint else ["lmmse", "malvar2004"])),
    ]
    methods = build_methods(
        specs,
        patterns_for_lmmse=args.patterns,
        lmmse_train=args.lmmse_train,
        tile=args.tile,
        fast=args.fast,
        progress=not args.quiet,
    )
    datasets = load_datasets(args.datasets, args.max_images)
    try:
        rows = evaluate(
            methods,
            datasets,
            args.sigmas,
            args.out,
            save_images=args.save_images,
            zoom_images=zooms if args.zoom else None,
            crop=args.crop,
            progress=not args.quiet,
            resume=not args.restart,
        )
    except KeyboardInterrupt:
        print(
            f"splitcam evaluate: interrupted; the results so far are in "
            f"{args.out}/per_image.csv: run the same command again to continue",
            file=sys.stderr,
        )
        return 130
    print(markdown_tables(summarise(rows)))
    print(f"wrote {args.out}/per_image.csv, summary.json and table.md")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from .evaluation.report import make_report

    path = make_report(args.results, args.out)
    print(path.read_text(encoding="utf-8"))
    print(f"wrote {path} with pattern figures and {Path(args.out) / 'sigma_curves.png'}")
    return 0


def _add_train_parser(sub) -> None:
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
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from .training.config import train_flags

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
    p.set_defaults(handler=cmd_train)


def _add_design_parser(sub) -> None:
    from .recon.design import DEFAULT_LR, DEFAULT_SIGMAS, DEFAULT_STEPS, OBJECTIVES

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
        help="mse: the mean closed-form MSE over the sigmas (default); psnr: the mean PSNR",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of --init random (default 0)")
    p.add_argument("--name", help="name of the designed pattern (default: START-designed)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=cmd_design)


def _add_method_options(p: argparse.ArgumentParser) -> None:
    """Options of how methods are built and run, shared by `evaluate` and `reconstruct`."""
    p.add_argument(
        "--lmmse-train",
        metavar="DIR",
        help="fit LMMSE on these training images (default: the shipped fits)",
    )
    p.add_argument("--tile", type=int, default=512, help="tile size in pixels (default 512)")
    p.add_argument(
        "--fast",
        action="store_true",
        help="bfloat16 + channels-last network inference (see README for its cost)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="splitcam",
        description="Design and evaluate colour image sensors built on metasurface colour "
        "splitters.",
    )
    parser.add_argument("--version", action="version", version=f"splitcam {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser(
        "patterns",
        help="list, draw or export splitter patterns",
        description="`splitcam patterns` prints the design-principle measures of every pattern; "
        "`patterns show D --out d.png` draws one; `patterns export D --out d.toml` writes its "
        "pattern file (a starting point for your own).",
    )
    p.add_argument("action", nargs="?", choices=["list", "show", "export"], default="list")
    p.add_argument("names", nargs="*", metavar="PATTERN", help="pattern names or files")
    p.add_argument("--out", help="output file (PNG for show, .json/.toml for export)")
    p.set_defaults(handler=cmd_patterns)

    p = sub.add_parser(
        "simulate",
        help="simulate the raw image a splitter sensor records of a picture",
        description="Writes the raw image (16-bit PNG with its scale recorded, or .npy) and a "
        "false-colour preview PNG beside it.",
    )
    p.add_argument("image", help="colour image (PNG, JPEG, TIFF, BMP; 8 or 16 bit)")
    p.add_argument("--pattern", default="D", help="pattern name or file (default: D)")
    p.add_argument(
        "--sigma", type=float, default=0.0, help="Gaussian noise sigma in 8-bit units (default: 0)"
    )
    p.add_argument("--out", required=True, help="raw output, .png or .npy")
    p.add_argument("--preview", help="preview PNG (default: <out>_preview.png)")
    p.set_defaults(handler=cmd_simulate)

    _add_train_parser(sub)

    _add_design_parser(sub)

    p = sub.add_parser(
        "evaluate",
        help="score trained runs and baselines with the paper's protocol",
        description="Simulates every test image with each method's pattern, adds the same "
        "deterministic noise for every method, reconstructs, and scores PSNR, SSIM and "
        "CIEDE2000 on 8-bit images. With no --checkpoint and no --method: the training-free "
        "baselines (LMMSE for every pattern, bayer + Malvar 2004).",
    )
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
        help="baseline: bilinear, malvar2004, menon2007 (bayer) or lmmse (repeatable)",
    )
    p.add_argument(
        "--patterns",
        type=lambda s: [x for x in s.split(",") if x],
        default=["A", "B", "C", "D", "E", "bayer"],
        help="patterns for lmmse, comma-separated names or files (default: all)",
    )
    p.add_argument(
        "--datasets",
        default="default",
        help="comma-separated: kodak24, mcmaster, folders; default: the sample photos "
        "shipped with scikit-image",
    )
    p.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 5.0, 10.0, 15.0, 20.0])
    p.add_argument("--max-images", type=int, help="use at most N images per dataset")
    p.add_argument(
        "--crop",
        type=int,
        default=0,
        help="border pixels left out of the scores (default 0, as in the paper)",
    )
    p.add_argument("--out", default="results", help="output folder (default: results)")
    p.add_argument(
        "--save-images",
        action="store_true",
        help="write reconstructions and zoomed side-by-side crops",
    )
    p.add_argument(
        "--zoom",
        action="append",
        metavar="IMAGE[:TOP,LEFT,SIZE]",
        help="image (and region) for zoomed side-by-side crops (default: the most "
        "detailed region of the first image of each dataset)",
    )
    _add_method_options(p)
    p.add_argument(
        "--restart",
        action="store_true",
        help="recompute everything instead of continuing the results in --out",
    )
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=cmd_evaluate)

    p = sub.add_parser(
        "report",
        help="one report over evaluation results, beside the paper's numbers",
        description="Takes folders written by `splitcam evaluate` and writes DIR/report.md (all "
        "methods side by side with the paper's Table 1-3 and the differences), a figure of "
        "every pattern (learned ones too) and a chart of PSNR and CIEDE2000 against sigma.",
    )
    p.add_argument("results", nargs="+", metavar="RESULTS", help="folders from `evaluate`")
    p.add_argument("--out", default="report", help="output folder (default: report)")
    p.set_defaults(handler=cmd_report)

    from .data.testsets import add_cli as add_data_cli

    add_data_cli(sub)

    p = sub.add_parser(
        "plot",
        help="draw a run's loss and validation PSNR curves (several runs: compare them)",
        description="One run: loss and PSNR against step (RUN/curves.png). Several runs: their "
        "validation PSNR against wall-clock time and against step, side by side.",
    )
    p.add_argument("run", nargs="+", help="run folder(s) (with metrics.jsonl)")
    p.add_argument("--out", help="PNG (default: RUN/curves.png, or runs_compared.png)")
    p.set_defaults(handler=cmd_plot)

    p = sub.add_parser(
        "reconstruct",
        help="reconstruct a colour image with a trained run or a baseline",
        description="--image: simulate the sensor on a colour image (with --sigma noise), then "
        "reconstruct; --raw: reconstruct a raw image (.png written by `simulate`, or .npy). "
        "Large images are processed in overlapping tiles.",
    )
    p.add_argument(
        "--method", help="lmmse, bilinear, malvar2004, menon2007, or a run folder / checkpoint file"
    )
    p.add_argument("--checkpoint", help="run folder or checkpoint file (same as --method RUN)")
    p.add_argument("--pattern", help="pattern name or file (for --method lmmse)")
    p.add_argument("--image", help="colour image to simulate and reconstruct")
    p.add_argument("--raw", help="raw image to reconstruct")
    p.add_argument("--sigma", type=float, default=0.0, help="noise sigma for --image")
    _add_method_options(p)
    p.add_argument("--out", required=True, help="output PNG")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=cmd_reconstruct)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except KeyboardInterrupt:
        print(f"splitcam {args.command}: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError, TypeError) as exc:
        if args.debug:
            raise
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"splitcam {args.command}: error: {message}", file=sys.stderr)
        return 1
