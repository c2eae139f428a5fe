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


def _pattern_or_model(spec: str):
    """A pattern by name or file, or the pattern of a shipped model of one pattern (``A-opt``:
    its learned kernels)."""
    from . import patterns
    from .recon.networks import serves_any_pattern
    from .training.models import load_model, model_names

    try:
        return patterns.get(spec)
    except patterns.PatternError:
        if spec not in model_names():
            raise
        system, _ = load_model(spec)
        if serves_any_pattern(system.network):
            raise ValueError(f"model {spec} serves any pattern; it has none to show") from None
        return system.sensor.to_pattern(spec)


def cmd_patterns(args: argparse.Namespace) -> int:
    from . import patterns

    if args.action == "list":
        names = args.names or patterns.names()
        rows = []
        for name in names:
            p = _pattern_or_model(name)
            rows.append({**patterns.measure(p).row(), "provenance": p.provenance})
        print(_table(rows))
        return 0
    if len(args.names) != 1:
        raise ValueError(f"'patterns {args.action}' takes one pattern name or file")
    pattern = _pattern_or_model(args.names[0])
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


def _check_distinct(inputs: dict[str, str | None], outputs: dict[str, str | None]) -> None:
    """Refuse an output file that is one of the command's inputs or another of its outputs
    (the same file by any path): writing it would destroy what the user gave or just wrote."""

    def same(a: Path, b: Path) -> bool:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()

    seen: list[tuple[str, Path]] = []
    given = [(flag, Path(p)) for flag, p in inputs.items() if p]
    for flag, path in ((f, Path(p)) for f, p in outputs.items() if p):
        for other, known in given:
            if same(path, known):
                raise ValueError(
                    f"{flag} {path} is the file given as {other}: it would be overwritten; "
                    f"choose another output file"
                )
        for other, known in seen:
            if same(path, known):
                raise ValueError(f"{flag} and {other} name the same file {path}; choose two files")
        seen.append((flag, path))


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
    preview = Path(args.preview) if args.preview else out.with_name(out.stem + "_preview.png")
    _check_distinct({"IMAGE": str(image)}, {"--out": str(out), "--preview": str(preview)})
    rgb = torch.from_numpy(read_image(image)).permute(2, 0, 1)[None]
    # The evaluation protocol's simulation: float64 sensor, noise seeded from the image name and
    # sigma, so a simulation is reproducible and matches what `splitcam evaluate` feeds methods.
    raw = simulate(SplitterSensor(pattern), rgb, image.stem, args.sigma)[0, 0].numpy()
    out.parent.mkdir(parents=True, exist_ok=True)
    made = {"pattern": pattern.to_dict(), "noise": "gaussian", "sigma": float(args.sigma)}
    scale = write_raw(out, raw, meta=made)
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
    from .training.sweep import STOPPED
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
    photon_only = sorted(k for k in overrides if k.startswith("noise.") and k != "noise.model")
    model = overrides.get("noise.model", config.noise.model)
    if photon_only and model != "photon":
        flags = ", ".join("--" + k.split(".", 1)[1].replace("_", "-") for k in photon_only)
        raise ValueError(f"{flags}: settings of the photon model; add --noise photon")
    init_from = overrides.get("run.init_from", config.run.init_from)
    if not args.resume and init_from and "network.arch" not in overrides:
        overrides.update(_fine_tuning(init_from, overrides))
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
    if result.failure:
        print(f"splitcam train: failed: {result.failure}", file=sys.stderr)
        return 1
    return STOPPED if result.interrupted else 0


def _design_network(args: argparse.Namespace) -> dict:
    """What ``design --objective network`` needs: the frozen network of ``--model``, a sampler
    of training patches from ``--data`` (all but the held-out last images, as training holds
    out), and a fixed batch of patches of the held-out ones to score before and after."""
    from .data.patches import ImageCache, PatchSampler, list_images
    from .recon.networks import serves_any_pattern
    from .training.models import load_model

    if not args.data:
        raise ValueError("--objective network needs training images: --data DIR")
    system, _ = load_model(args.model)
    if not serves_any_pattern(system.network):
        raise ValueError(f"--model {args.model} serves one pattern; give a network for any pattern")
    files = list_images(args.data)
    hold = min(32, max(1, len(files) // 10)) if len(files) >= 2 else 0
    if hold >= len(files):
        raise ValueError(f"--data {args.data}: too few images ({len(files)})")
    size = 64
    train_cache = ImageCache(files[: len(files) - hold], min_size=size, progress=False)
    train = PatchSampler(train_cache, patch_size=size, seed=args.seed)
    held = files[len(files) - hold :] or files
    held_out = PatchSampler(
        ImageCache(held, min_size=size, progress=False), patch_size=size, seed=12345
    )
    return {
        "network": system.network,
        "patches": train,
        "batch_size": args.batch_size,
        "held_out": held_out.sample(32),
    }


#: Default budget (minutes) and peak learning rate of fine-tuning a network for any pattern to
#: one pattern (docs/results/universal/README.md: 3e-4 against 1e-3 side by side).
FINE_TUNE_MINUTES = 10.0
FINE_TUNE_LR = 3e-4


def _fine_tuning(init_from: str, overrides: dict) -> dict:
    """Settings implied by ``--init-from`` a network for any pattern (``universal``) when
    ``--arch`` is left out: its architecture, unless ``--steps`` or ``--time-limit`` is given a
    budget of :data:`FINE_TUNE_MINUTES`, and unless ``--lr`` is given :data:`FINE_TUNE_LR`."""
    from .training.trainer import source_network

    network = source_network(init_from)
    if not network or network.get("arch") != "universal":
        return {}
    implied = {
        "network.arch": "universal",
        "network.features": network.get("features", 64),
        "network.blocks": network.get("blocks", 10),
    }
    if "optim.steps" not in overrides and "run.time_limit" not in overrides:
        implied["run.time_limit"] = FINE_TUNE_MINUTES
        print(f"fine-tuning {init_from} for {FINE_TUNE_MINUTES:g} minutes (--time-limit)")
    if "optim.lr" not in overrides:
        implied["optim.lr"] = FINE_TUNE_LR
    return implied


def cmd_design(args: argparse.Namespace) -> int:
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from . import patterns
    from .io import atomic_path
    from .recon.design import design_pattern
    from .viz.patterns import draw_pattern

    out = Path(args.out)
    if out.suffix.lower() not in (".toml", ".json"):
        raise ValueError(f"--out must end in .toml or .json, got {out.name!r}")
    in_loop = _design_network(args) if args.objective == "network" else {}
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
        **{k: v for k, v in in_loop.items() if k != "held_out"},
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
    with atomic_path(figure) as tmp:
        fig.savefig(tmp, dpi=dpi)

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
    if in_loop:
        from .recon.design import network_psnr

        held_out, net = in_loop["held_out"], in_loop["network"]
        before = network_psnr(result.start, net, held_out, result.sigmas)
        after = network_psnr(result.pattern, net, held_out, result.sigmas)
        print(f"{args.model} network PSNR (dB) on {len(held_out)} held-out patches:")
        print(
            _table(
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
    from .data.imageio import read_image, read_raw, read_raw_meta, write_image
    from .methods import build_method, build_model
    from .physics.sensor import SplitterSensor
    from .physics.system import simulate

    if (args.image is None) == (args.raw is None):
        raise ValueError("give exactly one of --image (simulate, then reconstruct) or --raw")
    _check_distinct({"--image": args.image, "--raw": args.raw}, {"--out": args.out})
    given = [x for x in (args.method, args.checkpoint, args.model) if x]
    if len(given) != 1:
        raise ValueError(
            "give one of --model (a shipped model, e.g. D), --method (lmmse, malvar2004, ...) "
            "or --checkpoint (a run folder)"
        )
    spec = given[0]
    sigma, pattern = args.sigma, args.pattern
    recorded = None
    if args.raw:
        # What simulate recorded in the raw file: the noise level, and the pattern (which must
        # agree with whatever the command is told or the method was trained for).
        made = read_raw_meta(args.raw)
        if made is not None:
            recorded = patterns.Pattern.from_dict(made.get("pattern"), source=str(args.raw))
            if sigma is not None and sigma != made.get("sigma"):
                raise ValueError(
                    f"--sigma {sigma:g} contradicts the noise level recorded in {args.raw} "
                    f"(sigma {made.get('sigma'):g}); leave --sigma out"
                )
            if pattern is not None and not patterns.get(pattern).equals(recorded):
                raise ValueError(
                    f"--pattern {pattern} contradicts the pattern recorded in {args.raw} "
                    f"({recorded.name}); leave --pattern out"
                )
            sigma, pattern = float(made.get("sigma", 0.0)), pattern or recorded
        elif sigma is None or pattern is None:
            raise ValueError(
                f"{args.raw} does not record how it was made (not written by `splitcam "
                f"simulate`): give its noise level (--sigma) and its pattern (--pattern)"
            )
    sigma = 0.0 if sigma is None else sigma
    method = (
        build_model(spec, pattern=pattern, tile=args.tile, precision=args.precision)
        if args.model
        else build_method(
            spec,
            pattern=pattern,
            lmmse_train=args.lmmse_train,
            tile=args.tile,
            precision=args.precision,
            progress=not args.quiet,
        )
    )
    if pattern is not None and not patterns.get(pattern).equals(method.pattern):
        name = pattern.name if isinstance(pattern, patterns.Pattern) else pattern
        where = f"the raw image's pattern {name}" if recorded is not None else f"--pattern {name}"
        raise ValueError(f"{where} differs from the pattern of {spec} ({method.pattern.name})")
    if args.image:
        rgb = torch.from_numpy(read_image(args.image)).permute(2, 0, 1)[None]
        raw = simulate(SplitterSensor(method.pattern), rgb, Path(args.image).stem, sigma)
    else:
        raw = torch.from_numpy(read_raw(args.raw))[None, None]
    if hasattr(method, "progress"):
        method.progress = not args.quiet
    with torch.no_grad():
        out = method.reconstruct(raw, sigma)
    if Path(args.out).suffix.lower() == ".npy":  # float32 (H, W, 3), unclipped
        import numpy as np

        from .io import atomic_path

        with atomic_path(args.out) as tmp:
            np.save(tmp, out[0].permute(1, 2, 0).float().numpy())
    else:
        write_image(args.out, out[0].clamp(0, 1), bits=args.bits)
    print(f"{method.name}: wrote {args.out} ({out.shape[-1]}x{out.shape[-2]})")
    return 0


#: The main job (``splitcam evaluate`` with no method named) scores centre crops of this size of
#: the built-in photos: with every shipped network in float32 on a 2-core AVX2 CPU, whole photos
#: took 4 min 23 s for 4 networks (2026-11-25); the crops keep all six scenes within 3 minutes.
MAIN_JOB_MAX_SIZE = 256


def load_datasets(spec: str | None, max_images: int | None, max_size: int | None = None) -> list:
    """``[(dataset name, [(image name, rgb)])]`` for a comma-separated list of names/folders;
    with ``max_size`` every image is cut to its centre (the dataset name says so, which keeps
    resumed results of whole and cropped images apart)."""
    from .data.testsets import centre_crop, default_images, load_images

    if max_size is not None and max_size < 2:
        raise SystemExit(f"--max-size must be at least 2 pixels, got {max_size}")
    if not spec or spec == "default":
        named = [("skimage", default_images())]
    else:
        items = (s.strip() for s in spec.split(",") if s.strip())
        named = [(Path(item).name or item, load_images(item)) for item in items]
    out = []
    for name, images in named:
        images = images[:max_images] if max_images else images
        if max_size:
            images = [(n, centre_crop(rgb, max_size)) for n, rgb in images]
            name = f"{name}-{max_size}px"
        out.append((name, images))
    return out


def _model_methods(
    models: Sequence[str], pattern_specs: Sequence[str], *, main_job: bool, options: dict
) -> list:
    """The methods of ``--model`` names: a model of one pattern as itself, a model for any
    pattern (``universal``) once per pattern of ``--patterns``. In the main job the universal
    model reconstructs only the patterns that no shipped network serves, and says so."""
    from . import patterns
    from .methods import build_model
    from .training.models import model_serves_any_pattern

    universal = [spec for spec in models if model_serves_any_pattern(spec)]
    single = [build_model(spec, **options) for spec in models if spec not in universal]
    for spec in universal:
        wanted = list(pattern_specs)
        if main_job:
            served = [m.pattern for m in single]
            wanted = [p for p in wanted if not any(patterns.get(p).equals(s) for s in served)]
            for p in wanted:
                print(f"pattern {p} has no shipped network: reconstructed by the {spec} network")
        single += [build_model(spec, pattern=p, **options) for p in wanted]
    return single


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluation.protocol import evaluate, parse_zoom
    from .evaluation.tables import markdown_tables, summarise
    from .methods import build_methods
    from .training.models import model_names

    zooms = [parse_zoom(z) for z in args.zoom or ()]  # bad syntax fails before any work
    chosen = args.checkpoint or args.method or args.model
    options = {"tile": args.tile, "precision": args.precision}
    # Built-in defaults (the main job): every shipped network, and the training-free baselines,
    # on centre crops of the built-in photos (within 3 minutes on a 2-core CPU).
    models = args.model if chosen else model_names()
    max_size = args.max_size
    if max_size is None and not chosen and args.datasets == "default":
        max_size = MAIN_JOB_MAX_SIZE
    specs = [
        *args.checkpoint,
        *(args.method or ([] if chosen else ["lmmse", "malvar2004"])),
    ]
    methods = _model_methods(models, args.patterns, main_job=not chosen, options=options)
    methods += build_methods(
        specs,
        patterns_for_lmmse=args.patterns,
        lmmse_train=args.lmmse_train,
        tile=args.tile,
        precision=args.precision,
        progress=not args.quiet,
    )
    from .physics.noise import Exposure

    if not args.photons and _sensor_flags_given(args):
        raise ValueError(
            f"{', '.join(_sensor_flags_given(args))} describe the photon model's sensor and have "
            f"no effect without --photons (the exposures to score)"
        )
    exposures = [Exposure(n, **_sensor(args)) for n in args.photons or ()]  # checked first
    paper_sigmas = [0.0, 5.0, 10.0, 15.0, 20.0]  # SPEC section 7
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
            # the main job (no method named) also draws the zoomed side-by-side crops
            zoom_only=not chosen and not args.save_images,
        )
    except KeyboardInterrupt:
        print(
            f"splitcam evaluate: interrupted; the results so far are in "
            f"{args.out}/per_image.csv: run the same command again to continue",
            file=sys.stderr,
        )
        return 130
    # What the folder holds: this evaluation's rows and those of others kept beside them.
    from .evaluation.tables import CSV_NAME, read_rows

    kept = read_rows(Path(args.out) / CSV_NAME)
    summary = summarise(kept)
    print(markdown_tables(summary))
    if len(kept) > len(rows):
        others = sorted({r.method for r in kept} - {r.method for r in rows})
        print(f"(the table keeps the earlier results in {args.out} of: {', '.join(others)})")
    written = "per_image.csv, summary.json and table.md"
    chart = Path(args.out) / "sigma_curves.png"
    if len({r.level for r in kept}) > 1:
        from .viz.charts import sigma_chart

        curves = [(name, entry["all"]) for name, entry in summary.items()]
        sigma_chart(curves, chart, patterns_of={n: e["pattern"] for n, e in summary.items()})
        written += ", sigma_curves.png"
    else:
        chart.unlink(missing_ok=True)  # an earlier chart would not match the table
    zoom = Path(args.out) / "zoom"
    if (not chosen or args.save_images) and zoom.is_dir() and any(zoom.iterdir()):
        written += " and the zoomed crops in zoom/"
    print(f"wrote {args.out}/{written}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from .evaluation.report import make_report

    path = make_report(args.results, args.out)
    print(path.read_text(encoding="utf-8"))
    charts = [Path(args.out) / n for n in ("sigma_curves.png", "exposure_curves.png")]
    drawn = " and ".join(str(c) for c in charts if c.is_file())
    print(f"wrote {path} with pattern figures" + (f" and {drawn}" if drawn else ""))
    return 0


def cmd_models(args: argparse.Namespace) -> int:
    from .training.models import MODELS_DIR, export_model, load_model, model_names

    if args.action == "export":
        if not args.run or not args.name:
            raise ValueError("models export needs a run folder and --name")
        if args.ship and args.out:
            raise ValueError("give --ship (into the package's shipped models) or --out, not both")
        out = (MODELS_DIR if args.ship else Path(args.out or "models")) / args.name
        existing = [
            p for p in (out.with_suffix(".json"), out.with_suffix(".safetensors")) if p.exists()
        ]
        if existing and not args.force:
            what = f"the shipped model {args.name}" if args.ship else f"the model {existing[0]}"
            raise ValueError(f"{what} exists; --force replaces it")
        path = export_model(
            args.run, out, name=args.name, storage=args.storage, description=args.description or ""
        )
        size = path.with_suffix(".safetensors").stat().st_size
        print(f"wrote {path} and {path.with_suffix('.safetensors').name} ({size / 2**20:.2f} MiB)")
        return 0
    rows = []
    for name in model_names():
        _, meta = load_model(name)
        prov = meta.get("provenance", {})
        segs = prov.get("segments", [])
        rows.append(
            {
                "model": name,
                "pattern": "any"
                if (meta.get("config") or {}).get("pattern", {}).get("name") == "random"
                else meta["pattern"]["name"],
                "network": meta["network"]["arch"],
                "steps": str(prov.get("total_steps", "?")),
                "batch": str(segs[-1].get("batch_size") if segs else "?"),
                "train time": f"{prov.get('train_seconds', 0) / 60:.0f} min",
                "device": ", ".join(dict.fromkeys(str(g.get("device")) for g in segs)),
            }
        )
    if not rows:
        print(f"no models shipped in {MODELS_DIR}")
        return 0
    print(_table(rows))
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from .training.config import read_config_value
    from .training.sweep import (
        continue_from_snapshots,
        load_experiments,
        run_sweep,
        status,
        without_shipped,
    )

    overrides = {}
    for item in args.set or ():
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set expects KEY=VALUE (e.g. optim.steps=2000), got {item!r}")
        overrides[key.strip()] = read_config_value(value)
    experiments = load_experiments(args.experiments, args.out, data=args.data, overrides=overrides)
    if not args.retrain_shipped:
        experiments = without_shipped(experiments, args.snapshots)
    if args.dry_run:
        if args.snapshots:
            experiments = continue_from_snapshots(experiments, args.snapshots)
        for e in experiments:
            print(f"{e.name}: {status(e)} ({e.run_dir})")
        return 0
    slurm = {
        "partition": args.partition,
        "time": args.time,
        "gpus": args.gpus,
        "cpus": args.cpus,
        "wait": not args.no_wait,
    }
    result = run_sweep(
        experiments,
        executor=args.executor,
        jobs=args.jobs,
        threads=args.threads,
        slurm=slurm,
        snapshots=args.snapshots,
    )
    print("; ".join(f"{k}: {v}" for k, v in result.items()))
    return 0 if all(v in ("done", "partial") for v in result.values()) else 1


def cmd_reproduce(args: argparse.Namespace) -> int:
    from .evaluation.protocol import evaluate
    from .evaluation.report import TABLE1, paper_tables
    from .evaluation.tables import summarise
    from .methods import build_method, build_model
    from .training.models import load_model, model_names

    rows = {
        "A": "A",
        "B": "B",
        "C": "C",
        "D": "D",
        "E": "E",
        "bayer": "bayer",
        "A optimised": "A-opt",
        "D optimised": "D-opt",
        "D optimised (random init.)": "D-opt-random",
    }
    shipped = set(model_names())
    rows = {r: m for r, m in rows.items() if m in shipped}
    if not rows:
        raise ValueError("no shipped models to reproduce the paper with")
    methods = [build_model(m, tile=args.tile, precision=args.precision) for m in rows.values()]
    if not args.no_baselines:
        methods.append(build_method("malvar2004"))
        methods += [build_method("lmmse", pattern=p) for p in (*TABLE1, "bayer")]
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
    )
    summary = summarise(result)
    from .recon.base import fast_precision

    inference = "bfloat16" if fast_precision(args.precision, "cpu") else "float32"
    budgets, learned = {}, {}
    for row, name in rows.items():
        _, meta = load_model(name)
        prov = meta.get("provenance", {})
        segs = prov.get("segments", [])
        batch = {g.get("batch_size") for g in segs}
        devices = ", ".join(dict.fromkeys(str(g.get("device")) for g in segs))
        budgets[row] = (
            f"{prov.get('total_steps', '?')} steps of batch "
            f"{'/'.join(map(str, batch))}, {prov.get('train_seconds', 0) / 60:.0f} "
            f"min of training on {devices}; evaluated in {inference}"
        )
        if meta["pattern"].get("provenance") == "learned":
            from .patterns import Pattern

            learned[row] = Pattern.from_dict(meta["pattern"])
    label = {m.name: m.name for m in methods}
    zooms = (
        sorted(str(p.relative_to(out)) for p in (evaluation / "zoom").glob("*.png"))
        if (evaluation / "zoom").is_dir()
        else []
    )
    report = paper_tables(
        summary,
        {r: f"net-{m}" for r, m in rows.items() if f"net-{m}" in label},
        out,
        budgets=budgets,
        learned=learned,
        zooms=zooms,
        baselines={r: f"lmmse-{r}" for r in (*TABLE1, "bayer")},
    )
    print(report.read_text(encoding="utf-8"))
    print(f"wrote {report}")
    return 0


def cmd_study(args: argparse.Namespace) -> int:
    from .evaluation.exposure import (
        default_exposures,
        exposure_study,
        raw_snr_check,
        write_study,
    )

    if args.points < 1:
        raise ValueError(f"--points must be at least 1, got {args.points}")
    photons = args.photons or default_exposures(args.points)
    datasets = load_datasets(args.datasets, args.max_images)
    images = [img for _, imgs in datasets for img in imgs]
    names = ", ".join(f"{d} ({len(i)})" for d, i in datasets)
    from .methods import build_method

    methods = _model_methods(args.model, args.patterns, main_job=False, options={})
    methods += [build_method(c) for c in args.checkpoint]
    results = exposure_study(
        images,
        patterns=args.patterns,
        photons=photons,
        methods=methods,
        **_sensor(args),
        progress=not args.quiet,
    )
    snr = raw_snr_check(images, patterns=args.patterns) if "bayer" in args.patterns else None
    sensor = _sensor(args)
    note = (
        f"Images: {names}. Read noise {sensor['read_noise']:g} e-, "
        + (f"full well {args.full_well:g} e-, " if args.full_well else "no saturation, ")
        + (f"ADC {sensor['bits']} bits at {args.gain:g} e-/DN. " if args.gain else "no ADC. ")
        + "Command: "
        f"`splitcam study exposure {' '.join(sys.argv[3:])}`"
    )
    path = write_study(results, snr, args.out, note=note)
    print(path.read_text(encoding="utf-8"))
    print(f"wrote {path}, exposure.json and exposure.png")
    return 0


def cmd_optics(args: argparse.Namespace) -> int:
    import numpy as np

    from . import patterns
    from .io import atomic_path
    from .optics import Optics, bayer_collection, pattern_of, profile
    from .viz.patterns import draw_height_maps, draw_pattern

    period = tuple(int(v) for v in args.period.lower().split("x"))
    if len(period) != 2 or min(period) < 1:
        raise ValueError(f"--period must be like 2x2, got {args.period!r}")
    optics = Optics(
        pitch=args.pitch,
        distance=args.distance,
        samples=args.samples,
        index=args.index,
        spacer_index=args.spacer_index,
        max_height=args.max_height,
        kernel_size=(args.kernel, args.kernel),
    )
    out = Path(args.out)
    height = profile(args.profile, period, optics, args.seed)
    if args.design:
        from .recon.design import design_metasurface

        result = design_metasurface(
            period,
            optics,
            init=height if args.profile not in ("flat", "lens") else args.profile,
            steps=args.steps,
            lr=args.lr,
            seed=args.seed,
            name=out.stem,
            progress=not args.quiet,
            objective=args.objective,
        )
        height, pattern = result.height, result.pattern
        for s in result.psnr_before:
            print(
                f"sigma {s:g}: closed-form LMMSE {result.psnr_before[s]:.2f} -> "
                f"{result.psnr_after[s]:.2f} dB"
            )
        print(f"{len(result.history)} steps in {result.seconds:.1f} s")
    else:
        pattern = pattern_of(height, period, optics, name=out.stem)
    patterns.save(pattern, out)
    with atomic_path(out.with_suffix(".npy")) as tmp:
        np.save(tmp, height.cpu().numpy())
    fig = draw_pattern(pattern, out.with_suffix(".png"))
    del fig
    heights_png = out.with_name(out.stem + "_height.png")
    draw_height_maps(
        [(f"{out.stem}: height (µm)", height.cpu().numpy())],
        heights_png,
        period=period,
        pitch=optics.pitch,
        max_height=optics.max_height,
    )
    collected = pattern.kernels.sum((2, 3))
    for i, row in enumerate(collected):
        print(f"pixel {i}: collected R {row[0]:.3f}, G {row[1]:.3f}, B {row[2]:.3f} of its light")
    if period == (2, 2):
        r, g, b = bayer_collection(pattern)
        print(f"collection efficiency into RGGB pixels: R {r:.1%}, G {g:.1%}, B {b:.1%}")
    print(
        f"wrote {out}, {out.with_suffix('.npy')} (height map, µm), {out.with_suffix('.png')} "
        f"and {heights_png}"
    )
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
    p.set_defaults(handler=cmd_design)


def _add_method_options(p: argparse.ArgumentParser) -> None:
    """Options of how methods are built and run, shared by `evaluate` and `reconstruct`."""
    p.add_argument(
        "--lmmse-train",
        metavar="DIR",
        help="fit LMMSE on these training images (default: the shipped fits)",
    )
    p.add_argument("--tile", type=int, default=512, help="tile size in pixels (default 512)")
    _add_precision(p, "auto")


def _add_precision(p: argparse.ArgumentParser, default: str) -> None:
    """``--precision`` of network inference (``--fast``: the same as ``--precision bf16``)."""
    p.add_argument(
        "--precision",
        choices=["auto", "fp32", "bf16"],
        default=default,
        help=f"network inference: auto = bfloat16 + channels-last where the hardware has it "
        f"natively (about 3x faster there), fp32 = bit-exact float32 (default {default})",
    )
    p.add_argument(
        "--fast", dest="precision", action="store_const", const="bf16", help=argparse.SUPPRESS
    )


def _add_sensor_options(p: argparse.ArgumentParser) -> None:
    """The photon model's sensor besides the exposure (splitcam.physics.noise.Exposure), shared
    by `evaluate` and `study exposure`."""
    p.add_argument("--read-noise", type=float, help="photon model: electrons (default 2)")
    p.add_argument(
        "--full-well", type=float, help="photon model: saturation, electrons (default: none)"
    )
    p.add_argument(
        "--gain", type=float, help="photon model: ADC electrons per DN (default: no ADC)"
    )
    p.add_argument("--bits", type=int, help="photon model: ADC bits (default 12)")


def _sensor(args: argparse.Namespace) -> dict:
    """The keyword arguments of :class:`~splitcam.physics.noise.Exposure` from the options of
    :func:`_add_sensor_options`."""
    return {
        "read_noise": 2.0 if args.read_noise is None else args.read_noise,
        "full_well": args.full_well,
        "gain": args.gain,
        "bits": 12 if args.bits is None else args.bits,
    }


def _sensor_flags_given(args: argparse.Namespace) -> list[str]:
    """The photon-model sensor flags given on the command line."""
    names = {"read_noise": "--read-noise", "full_well": "--full-well", "gain": "--gain"}
    names["bits"] = "--bits"
    return [flag for name, flag in names.items() if getattr(args, name, None) is not None]


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
        "CIEDE2000 on 8-bit images. With no --checkpoint, --model or --method (the main job): "
        "the shipped network of every pattern and the training-free baselines (LMMSE for every "
        "pattern, bayer + Malvar 2004).",
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
        "--model",
        action="append",
        default=[],
        metavar="NAME",
        help="a shipped model (A-E, bayer, A-opt, D-opt, D-opt-random; `splitcam models`) or a "
        "model file (repeatable)",
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
    _add_sensor_options(p)
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
    p.add_argument("--force", action="store_true", help="replace an existing model of that name")
    p.add_argument("--storage", choices=["float16", "bfloat16", "float32"], default="float16")
    p.add_argument("--description", help="one line about the model")
    p.set_defaults(handler=cmd_models)

    p = sub.add_parser(
        "sweep",
        help="train a list of experiments, here or on a SLURM cluster (resumable)",
        description="Trains every experiment file (a `train` config; run folder OUT/<file "
        "name>) that is not finished, resuming interrupted ones; finished ones are skipped, so "
        "the same command continues a sweep. Locally --jobs trainings run side by side with the "
        "threads split between them; --executor slurm submits a job array through submitit.",
    )
    p.add_argument("experiments", nargs="+", metavar="FILE", help="experiment config files")
    p.add_argument("--out", default="runs", help="folder of the run folders (default: runs)")
    p.add_argument("--data", help="training images for every experiment (replaces data.train)")
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="a setting for every experiment, e.g. optim.steps=2000 (repeatable)",
    )
    p.add_argument("--executor", choices=["local", "slurm"], default="local")
    p.add_argument("--jobs", type=int, default=1, help="trainings at a time (default 1)")
    p.add_argument("--threads", type=int, help="CPU threads shared by local jobs (default: all)")
    p.add_argument("--partition", help="slurm partition")
    p.add_argument("--time", type=int, help="slurm time limit per job, minutes (default 60)")
    p.add_argument("--gpus", type=int, help="slurm GPUs per job")
    p.add_argument("--cpus", type=int, help="slurm CPUs per job")
    p.add_argument("--no-wait", action="store_true", help="slurm: submit and return")
    p.add_argument(
        "--snapshots",
        metavar="DIR",
        help="weights snapshots: when the sweep stops (Ctrl-C included), each unfinished run is "
        "exported to DIR/<name> (float16, small enough for git); a run with no folder continues "
        "from its snapshot on the schedule of one straight run",
    )
    p.add_argument(
        "--retrain-shipped",
        action="store_true",
        help="train experiments whose shipped model (same name) already has their budget; "
        "without it they are skipped unless their run folder or snapshot is there",
    )
    p.add_argument("--dry-run", action="store_true", help="show what each experiment needs")
    p.set_defaults(handler=cmd_sweep)

    p = sub.add_parser(
        "study",
        help="studies beyond the paper: `study exposure` (filters and splitters at equal light)",
        description="`splitcam study exposure`: PSNR and CIEDE2000 of the closed-form LMMSE of "
        "every pattern against exposure under the photon model (shot and read noise, the same "
        "photon flux for every pattern), the exposure below which each splitter beats the Bayer "
        "filter, and the raw SNR of each pattern against the filter next to theory.",
    )
    p.add_argument("study", choices=["exposure"])
    p.add_argument("--datasets", default="default")
    p.add_argument("--max-images", type=int, help="at most this many images per dataset")
    p.add_argument(
        "--patterns",
        type=lambda s: [x for x in s.split(",") if x],
        default=["A", "B", "C", "D", "E", "bayer"],
    )
    p.add_argument(
        "--photons", type=float, nargs="+", help="exposures (default: log-spaced from 1 to 10^4)"
    )
    p.add_argument("--points", type=int, default=9, help="default exposures: how many")
    _add_sensor_options(p)
    p.add_argument("--model", action="append", default=[], help="a shipped model too")
    p.add_argument(
        "--checkpoint",
        action="append",
        default=[],
        help="a trained run too (e.g. one trained with --noise photon)",
    )
    p.add_argument("--out", default="results/exposure")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=cmd_study)

    p = sub.add_parser(
        "optics",
        help="the pattern a metasurface makes (scalar wave optics), or design one",
        description="Computes the splitter kernels that a metasurface height map makes above "
        "the sensor (angular spectrum propagation, spectral integration; splitcam.optics) and "
        "writes the pattern file, its figure and the height map (.npy). With --design, "
        "optimises the height map from --profile for the closed-form LMMSE first.",
    )
    p.add_argument(
        "--profile", default="lens", help="flat, lens, random, or a height map .npy (µm)"
    )
    p.add_argument("--period", default="2x2", help="router period (default 2x2)")
    p.add_argument("--pitch", type=float, default=1.0, help="pixel pitch, µm (default 1)")
    p.add_argument("--distance", type=float, default=2.0, help="to the photodiodes, µm")
    p.add_argument("--samples", type=int, default=8, help="grid points per pixel (default 8)")
    p.add_argument("--index", type=float, default=2.0, help="pillar index (default 2.0)")
    p.add_argument("--spacer-index", type=float, default=1.0)
    p.add_argument("--max-height", type=float, default=1.2, help="µm (default 1.2)")
    p.add_argument("--kernel", type=int, default=3, help="kernel size (odd, default 3)")
    p.add_argument("--design", action="store_true", help="optimise the height map")
    p.add_argument(
        "--objective",
        choices=["lmmse", "routing"],
        default="lmmse",
        help="with --design: the closed-form LMMSE of the reconstruction (default), or the "
        "mean RGGB collection efficiency of a Bayer-type router (2x2)",
    )
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--lr", type=float, default=0.1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="pattern file (.toml or .json)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=cmd_optics)

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
    p.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 5.0, 10.0, 15.0, 20.0])
    p.add_argument("--out", default="reproduce")
    p.add_argument("--max-images", type=int, help="at most this many images per dataset")
    p.add_argument("--no-baselines", action="store_true")
    p.add_argument("--tile", type=int, default=512)
    # float32 by default: the committed tables are float32, and a resumed run adds rows to them.
    _add_precision(p, "fp32")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=cmd_reproduce)

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
    p.add_argument("--model", help="a shipped model (`splitcam models` lists them) or model file")
    p.add_argument(
        "--pattern",
        help="pattern name or file: for --method lmmse and a network for any pattern, and of a "
        "--raw file that does not record it",
    )
    p.add_argument("--image", help="colour image to simulate and reconstruct")
    p.add_argument("--raw", help="raw image to reconstruct")
    p.add_argument(
        "--sigma",
        type=float,
        help="noise sigma: added to --image (default 0); of --raw, needed only if the file does "
        "not record it (raw files from `splitcam simulate` do)",
    )
    _add_method_options(p)
    p.add_argument(
        "--out",
        required=True,
        help="output image: .png, .tif/.tiff or .jpg, or .npy (float32 H x W x 3, unclipped)",
    )
    p.add_argument(
        "--bits", type=int, choices=[8, 16], default=8, help="bits per channel of PNG/TIFF (8)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
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
