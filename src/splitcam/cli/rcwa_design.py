"""`splitcam optics rcwa-design`: a router's layer designed through Maxwell's equations for the
image it gives at one exposure (splitcam.design.fullwave)."""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
from pathlib import Path

from .rcwa import add_stack_options, add_workers_option, stacked, wavelengths_of


def register(optics_sub: argparse._SubParsersAction) -> None:
    p = optics_sub.add_parser(
        "rcwa-design",
        help="design a router's layer through Maxwell's equations for the image at an exposure",
        description="Optimises the cells of a 2x2-pixel metasurface layer by gradient descent "
        "through RCWA (torcwa, splitcam[fullwave], or fmmax) on the closed-form LMMSE error of "
        "the image at one exposure (photon model, linear light), with a conic filter (minimum "
        "feature) and a projection driven to 0/1 over the run (splitcam.design.fullwave). "
        "Saved after every step in OUT/state.*: the same command continues an interrupted "
        "run. --solver fmmax-jones (splitcam[fmmax]) solves nearer the converged setting in "
        "fewer terms (its gradient holds the formulation's vector field fixed). At the end "
        "the binary design is solved again and OUT holds NAME.csv (the design), "
        "NAME-density.csv, NAME-spectra.csv/.png, NAME.toml (its spectral pattern) and "
        "report.md/.png (objective against steps, the layer).",
    )
    p.add_argument(
        "start",
        nargs="+",
        help="design CSV to start from (e.g. experiments/fullwave/designs/best-240325.csv), or "
        "noise:ROWSxCOLS (a random start of that many cells); several: layers stacked, the top "
        "one first, each a CSV or noise (with --thickness and --spacer)",
    )
    p.add_argument("--out", required=True, help="folder of the run and its results")
    p.add_argument("--name", help="the design's name (default: the folder's)")
    p.add_argument("--photons", type=float, default=100.0, help="target exposure N (default 100)")
    p.add_argument("--read-noise", type=float, default=2.0, help="electrons (default 2)")
    _add_descent_options(p)
    p.add_argument(
        "--f-number", type=float, help="design behind a lens's cone (7 directions per solve)"
    )
    p.add_argument(
        "--stack",
        help="design for a sensor behind this optical stack in front of every pixel, "
        "comma-separated as `splitcam study exposure --stack` takes it (silicon, ir-cut, lens, "
        "CSV files); the spectra written stay the router's own (default: a bare pixel)",
    )
    p.add_argument("--samples", type=int, default=16, help="flux grid points per pixel")
    p.add_argument("--seed", type=int, default=0, help="of a noise: start (default 0)")
    p.add_argument("--threads", type=int, help="CPU threads (default: torch's)")
    add_workers_option(
        p, "each step's solves (wavelengths times directions; a continued run may change it)"
    )
    p.add_argument("--quiet", action="store_true")
    add_stack_options(p, wavelengths="450,550,650", order=5)
    p.set_defaults(handler=run)


def _add_descent_options(p: argparse.ArgumentParser) -> None:
    """The descent: its steps, rates and sharpness, the binary phase and the feature size."""
    p.add_argument(
        "--steps",
        type=int,
        default=50,
        help="gradient steps on continuous densities (default 50; 0: binary steps only)",
    )
    p.add_argument("--lr", type=float, default=0.1, help="Adam's step (default 0.1)")
    p.add_argument(
        "--beta",
        type=float,
        nargs=2,
        default=[2.0, 32.0],
        metavar=("START", "END"),
        help="projection sharpness, geometric from START to END over the run (default 2 32)",
    )
    p.add_argument(
        "--binary-steps",
        type=int,
        default=0,
        help="steps after the continuation on the binary layer itself (straight-through "
        "gradient at the last sharpness); the best binary layer is the design (default 0). "
        "The one setting a continued run may change: fewer ends the binary phase early",
    )
    p.add_argument(
        "--binary-lr",
        type=float,
        help="Adam's step in the binary steps (default: --lr); a smaller one flips fewer cells "
        "a step",
    )
    p.add_argument(
        "--backtrack",
        action="store_true",
        help="a binary step that scores below the best layer so far sends the next one back "
        "to that layer at half the rate (a descent that settles instead of oscillating); may "
        "be switched on when a run is continued",
    )
    p.add_argument(
        "--feature",
        type=float,
        default=0.08,
        help="minimum feature size, µm: the brush that paints every pillar and gap of the "
        "binary design (default 0.08, the leaderboard's)",
    )
    p.add_argument(
        "--filter",
        type=float,
        help="the conic filter's radius, µm (default: --feature). A radius as wide as the "
        "feature blurs away the start's features of that width (a disc as wide as the radius "
        "filters to 0.5 at its centre); the binary layer keeps --feature whatever the filter",
    )


def _start_grid(items: list[str], seed: int):
    """The start's grid: one layer's, or the layers' stacked (each a design file or noise; the
    noise of layer ``i`` drawn from ``seed + i``)."""
    import numpy as np

    from ..physics.fullwave import read_design

    grids = []
    for i, text in enumerate(items):
        match = re.fullmatch(r"noise:(\d+)x(\d+)", text)
        if match:
            rows, cols = int(match[1]), int(match[2])
            if min(rows, cols) < 2:
                raise ValueError(f"a noise: start needs at least 2x2 cells, got {rows}x{cols}")
            grids.append(np.random.default_rng(seed + i).uniform(0.3, 0.7, (rows, cols)))
        else:
            grids.append(read_design(text))
    return stacked(items, grids)


def run(args: argparse.Namespace) -> int:
    from ..design.fullwave import FullwaveDesign
    from ..physics.fullwave import check_solver

    check_solver(args.solver)
    grid = _start_grid(args.start, args.seed)
    lams = wavelengths_of(args.wavelengths)
    settings = _settings_of(args, grid, lams)
    design = FullwaveDesign.from_settings(grid, settings, workers=args.workers)
    with design:  # stops the worker processes, whatever happens
        return _design(args, design, grid, settings, lams)


def _design(args: argparse.Namespace, design, grid, settings: dict, lams: list[float]) -> int:
    """The descent, then the binary design's files and report."""
    import numpy as np
    import torch

    from ..design.fullwave import run_design

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder")
    name = args.name or out.name
    if args.threads:
        torch.set_num_threads(args.threads)
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=args.steps + args.binary_steps, desc="rcwa-design", unit="step")

    def shown(row: dict) -> None:
        if bar is not None:
            bar.n = row["step"]
            bar.set_postfix(psnr=f"{row['psnr']:.2f}", beta=f"{row['beta']:.3g}")
            bar.refresh()

    result = run_design(
        design,
        out,
        steps=args.steps,
        lr=args.lr,
        beta_start=args.beta[0],
        beta_end=args.beta[1],
        binary_steps=args.binary_steps,
        binary_lr=args.binary_lr,
        backtrack=args.backtrack,
        settings=settings,
        progress=shown,
    )
    if bar is not None:
        bar.close()
    binary = design.binary(result["theta"], result["beta"])
    density = design.densities(result["theta"], result["beta"]).detach().numpy()
    with torch.no_grad():  # the start as given (a published design, or the noise), for scale
        start_t = design.transmission(torch.from_numpy(grid))[0].clamp_min(0.0)
        start = {
            "psnr": -10.0 * math.log10(float(design.image_error(start_t))),
            "transmission": start_t.numpy(),
        }
    return _finish(args, design, out, name, binary, density, result["history"], lams, np, start)


def _settings_of(args: argparse.Namespace, grid, lams: list[float]) -> dict:
    """What the run was started with: a continued run must have the same (``optics``,
    ``filter`` and ``spacer`` only where given, a layer's start and thickness as one value, so
    that runs saved before them continue)."""
    settings = {
        "start": args.start[0] if len(args.start) == 1 else list(args.start),
        "seed": args.seed,
        "grid": list(grid.shape),
        "stack": [
            args.pitch,
            args.thickness[0] if len(args.thickness) == 1 else list(args.thickness),
            args.depth,
            args.pillar,
            args.background,
            args.substrate,
        ],
        "wavelengths": lams,
        "photons": args.photons,
        "read_noise": args.read_noise,
        "f_number": args.f_number,
        "order": args.order,
        "solver": args.solver,
        "terms": args.terms,
        "samples": args.samples,
        "feature": args.feature,
    }
    if args.stack:
        settings["optics"] = args.stack
    if args.filter is not None:  # absent otherwise: runs saved before it continue
        settings["filter"] = args.filter
    if args.spacer:
        settings["spacer"] = args.spacer
    return settings


def _finish(
    args, design, out: Path, name: str, binary, density, history, lams, np, start: dict
) -> int:
    """Solve the binary design again, write its files and the report, say the result."""
    import torch

    from ..io import write_text
    from ..patterns.files import save_transmission
    from ..physics.fullwave import quadrant_spectra
    from .rcwa import _say_roles, _solved_by, _write_spectra, file_stem, stack_text

    stem = file_stem(name)
    g = design.geometry
    solved = quadrant_spectra(
        dataclasses.replace(g, grid=binary),
        lams,
        order=args.order,
        solver=args.solver,
        terms=args.terms,
        samples=args.samples,
        directions=design.directions,
        cache=out / f"{stem}-solves.jsonl",
        workers=design.workers,
    )
    t = np.clip(solved["transmission"], 0.0, None)
    error = float(design.image_error(torch.from_numpy(t)))
    names, layers = _write_layers(out, stem, g, binary, density)
    where = f"f/{args.f_number:g} cone" if args.f_number else "normal incidence"
    info = {
        "provenance": f"designed through RCWA ({_solved_by(args, solved['terms'])}, {where}) "
        "for the "
        f"closed-form LMMSE at N = {args.photons:g}, read noise {args.read_noise:g} e-"
        + (f", every pixel behind {design.optics}" if design.optics is not None else "")
        + "; "
        f"{len(history)} steps; binary, minimum feature {args.feature:g} µm",
        "description": f"metasurface router {', '.join(f'{n}.csv' for n in names)}: "
        f"{stack_text(g, args.pillar, args.background, args.substrate)}",
        "reference": "splitcam optics rcwa-design",
    }
    pattern_file = save_transmission(out / f"{stem}.toml", name, lams, t, **info)
    _write_spectra(out, stem, lams, {**solved, "transmission": t})
    _say_roles(lams, t, solved["reflection"], out / f"{stem}-spectra.png", f"{name}: {where}")
    psnr = -10.0 * math.log10(error)
    start_psnr = start["psnr"]
    chart = _report_chart(history, density.reshape(layers.shape), layers, out / "report.png")
    first = (
        ""
        if history[0].get("binary")
        else f"{history[0]['psnr']:.2f} dB at the first step (its densities pulled to "
        "[0.25, 0.75]), "
    )
    lines = [
        f"# {name}: a router designed for the image at N = {args.photons:g}",
        "",
        info["provenance"] + ".",
        "",
        f"- Closed-form LMMSE PSNR at the target exposure: {start_psnr:.2f} dB for the start "
        f"as given ({' + '.join(args.start)}), {first}{_last_steps(history)}, {psnr:.2f} dB "
        f"for the binary design solved again; all at {_solved_by(args, solved['terms'])}.",
        *(
            _measured_feature(layer, 2.0 * g.pitch / max(g.cells), n if len(names) > 1 else "")
            for n, layer in zip(names, layers, strict=True)
        ),
        f"- Reflection {float(solved['reflection'].mean()):.3f}; solving time "
        f"{sum(r['seconds'] for r in history) / 60:.1f} minutes over {len(history)} steps.",
        _files_line(names, stem, pattern_file.name),
        "",
        *_band_table(lams, {"the start as given": start["transmission"], "the design": t}),
        "",
        f"![report]({chart.name})",
        "",
    ]
    write_text(out / "report.md", "\n".join(lines))
    print(
        f"designed {name}: LMMSE PSNR at N = {args.photons:g}: {start_psnr:.2f} dB (the start "
        f"as given) -> {psnr:.2f} dB (binary, solved again); wrote "
        f"{', '.join(f'{out}/{n}.csv' for n in names)}, {pattern_file.name} and report.md"
    )
    return 0


def _write_layers(out: Path, stem: str, geometry, binary, density) -> tuple[list[str], object]:
    """Each layer's binary design and densities as CSVs: ``(file stems, (layers, rows, cols)
    binary layers)``."""
    from ..io import write_text

    names = _layer_files(stem, len(geometry.layers))
    layers = binary.reshape(geometry.layers.shape)
    for name, layer, dense in zip(names, layers, density.reshape(layers.shape), strict=True):
        write_text(out / f"{name}.csv", _csv(layer))
        write_text(out / f"{name}-density.csv", _csv(dense, "{:.4f}"))
    return names, layers


def _files_line(names: list[str], stem: str, pattern: str) -> str:
    """The report's list of the files written."""
    return (
        f"- Files: {_and(f'`{n}.csv`' for n in names)} (the design"
        f"{', a layer each, the top one first' if len(names) > 1 else ''}), "
        f"{_and(f'`{n}-density.csv`' for n in names)}, `{stem}-spectra.csv`, "
        f"`{pattern}` (use it as `--pattern`)."
    )


def _layer_files(stem: str, layers: int) -> list[str]:
    """The stems of a design's files: ``stem`` for one layer, ``stem-layer1``, ``stem-layer2``
    ... (the top one first) for layers stacked."""
    return [stem] if layers == 1 else [f"{stem}-layer{i + 1}" for i in range(layers)]


def _and(items) -> str:
    items = list(items)
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def _measured_feature(binary, cell: float, which: str = "") -> str:
    """The binary layer's minimum solid and void length scales, measured (the rule the
    binary steps keep, checked on the design written); ``which``: the layer's name, where
    there are several."""
    from ..design.lengthscale import minimum_length_scale

    solid, void = minimum_length_scale(binary)
    on = f"layer `{which}.csv`" if which else "the design"
    return (
        f"- Minimum feature, measured on {on} (periodic): solid {solid} cells "
        f"({solid * cell:.3g} µm), void {void} cells ({void * cell:.3g} µm)."
    )


def _band_table(lams: list[float], spectra: dict) -> list[str]:
    """Band efficiency (the leaderboard's) and colour purity per band, of each of ``spectra``
    (``(2, 2, L)`` transmissions), each by the pixels it sorts each band to."""
    from ..evaluation.tables import markdown_table
    from ..physics.fullwave import FullwaveError, band_efficiencies, band_purities

    rows = []
    for label, t in spectra.items():
        try:
            eff = band_efficiencies(t, lams)
        except FullwaveError:  # blue and red sent to one pixel: no bands to score
            rows.append([label, *["no sorting"] * 6])
            continue
        pur = band_purities(t, lams, eff["quadrants"])
        bands = ("blue", "green", "red")
        rows.append([label, *(_share(eff[b]) for b in bands), *(_share(pur[b]) for b in bands)])
    head = ["router", "efficiency: blue", "green", "red", "purity: blue", "green", "red"]
    return [
        "Band efficiency (mean transmission of a band into its own pixels) and purity (the "
        "share of what those pixels receive that is their band), at the design's wavelengths "
        "(–: no design wavelength in the band):",
        "",
        *markdown_table(head, rows),
    ]


def _share(value: float) -> str:
    """A band's efficiency or purity for the table; a band no design wavelength falls in has
    none (NaN)."""
    return "–" if math.isnan(value) else f"{value:.3f}"


def _last_steps(history: list[dict]) -> str:
    """The report's words for the end of the run: the last continuous step, and the best of the
    binary steps where there were some."""
    continuous = [r for r in history if not r.get("binary")]
    binary = [r for r in history if r.get("binary")]
    said = []
    if continuous:
        said.append(f"{continuous[-1]['psnr']:.2f} dB at the last step of continuous densities")
    if binary:
        best = max(binary, key=lambda r: r["psnr"])
        said.append(
            f"{binary[0]['psnr']:.2f} dB for its first binary layer and {best['psnr']:.2f} dB for "
            f"the best of {len(binary)} binary steps (step {best['step']}, the design)"
        )
    return ", ".join(said)


def _csv(grid, fmt: str = "{:g}") -> str:
    return "\n".join(",".join(fmt.format(v) for v in row) for row in grid) + "\n"


def _report_chart(history, density, binary, path: Path) -> Path:
    """The objective against steps, then each layer's densities and binary design
    (``(layers, rows, cols)``, the top one first)."""
    from matplotlib.figure import Figure

    from ..viz._save import save_figure

    count = len(binary)
    fig = Figure(figsize=(11 + 7.4 * (count - 1), 3.6))
    ax1, *images = fig.subplots(1, 1 + 2 * count)
    for binary_rows, label in ((False, "continuous densities"), (True, "binary layer")):
        rows = [r for r in history if bool(r.get("binary")) == binary_rows]
        if rows:
            ax1.plot([r["step"] for r in rows], [r["psnr"] for r in rows], "-o", ms=3, label=label)
    if any(r.get("binary") for r in history):
        ax1.legend(fontsize=8)
    ax1.set_xlabel("step")
    ax1.set_ylabel("closed-form LMMSE PSNR (dB)")
    ax1.grid(alpha=0.3)
    panels = []
    for i in range(count):
        layer = f"layer {i + 1}: " if count > 1 else ""
        panels += [
            (density[i], f"{layer}densities (black: pillar)"),
            (binary[i], f"{layer}binary design"),
        ]
    for ax, (image, title) in zip(images, panels, strict=True):
        ax.imshow(image, cmap="gray_r", vmin=0, vmax=1)
        ax.set_title(title, fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
