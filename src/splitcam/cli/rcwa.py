"""`splitcam optics rcwa`: the full-wave spectra of a 2x2-pixel metasurface router, and its
spectral pattern file."""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path


def register(optics_sub: argparse._SubParsersAction) -> None:
    p = optics_sub.add_parser(
        "rcwa",
        help="full-wave spectra of a 2x2-pixel metasurface router (RCWA) and its pattern",
        description="Solves Maxwell's equations for a metasurface design (RCWA, "
        "splitcam.physics.fullwave; the optional extra splitcam[fullwave]) and writes to --out "
        "the transmission into each pixel quadrant per wavelength and polarisation "
        "(NAME-spectra.csv, NAME-spectra.png) and the spectral pattern file (NAME.toml) that every "
        "other command takes as --pattern. Cost: about (2 order + 1)^6 per wavelength and "
        "direction (order 9: 20 s, order 12: 90 s on one CPU core). Every solve is kept in "
        "NAME-solves.jsonl as it finishes: the same command run again after an interruption "
        "continues where it stopped.",
    )
    p.add_argument(
        "design",
        nargs="+",
        help="CSV grid of 0/1 or densities in [0, 1], rows along y; several: layers stacked, "
        "the top one (where light arrives) first",
    )
    p.add_argument("--out", required=True, help="folder for the spectra and NAME.toml")
    p.add_argument(
        "--name",
        help="the pattern's name, and of the files written (default: the design file's stem)",
    )
    add_stack_options(p, wavelengths="400:700:10", order=9)
    p.add_argument(
        "--f-number",
        type=float,
        help="average over the cone of light of a lens at this f-number, > 0.5 (7 directions); "
        "default: normal incidence",
    )
    p.add_argument(
        "--chief-ray",
        type=float,
        default=0.0,
        help="degrees off the normal of the light's central direction (the chief ray: 0 at the "
        "centre of a lens's field, about 25-30 at the corner of a phone camera's; default 0)",
    )
    p.add_argument(
        "--chief-ray-azimuth",
        type=float,
        default=0.0,
        help="degrees: the direction the chief ray tilts towards in the design's plane (0 along "
        "its columns, x; 45 along its diagonal, towards a corner of the field; default 0)",
    )
    p.add_argument("--threads", type=int, help="CPU threads (default: torch's)")
    add_workers_option(p, "the solves (wavelengths times directions)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=run)


def add_workers_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--workers``: processes of one thread each that share the full-wave solves."""
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        help=f"processes, one thread each, that share {what}: the same results in up to 1/W "
        "of the time on W free cores (less with fmmax, whose JAX already spreads a solve over "
        "more than one core; default 1)",
    )


#: splitcam.physics.fullwave.SOLVERS, written here so that building the parser imports no numpy
#: (tests/physics/test_fullwave.py checks that the two agree).
SOLVERS = ("torcwa", "fmmax-fft", "fmmax-jones")


def add_stack_options(
    p: argparse.ArgumentParser,
    *,
    wavelengths: str,
    order: int,
    solvers: tuple[str, ...] | None = None,
) -> None:
    """The layer stack, the wavelengths, the solver and its Fourier order or terms: the options
    of every command that solves a router (``optics rcwa``, ``optics rcwa-design``)."""
    p.add_argument("--pitch", type=float, default=1.0, help="pixel pitch, µm (default 1)")
    p.add_argument(
        "--thickness",
        type=float,
        nargs="+",
        default=[0.6],
        help="layer, µm (default 0.6); layers stacked: one for every layer or one per layer",
    )
    p.add_argument(
        "--spacer",
        type=float,
        default=0.0,
        help="µm of the background between layers stacked (default 0: they touch)",
    )
    p.add_argument("--depth", type=float, default=2.4, help="monitor below it, µm (default 2.4)")
    p.add_argument("--pillar", default="Si3N4", help="material or index (default Si3N4)")
    p.add_argument("--background", default="vacuum", help="material or index (default vacuum)")
    p.add_argument("--substrate", default="SiO2", help="material or index (default SiO2)")
    p.add_argument(
        "--wavelengths",
        default=wavelengths,
        help=f"nm: FIRST:LAST:STEP or a list A,B,C (default {wavelengths})",
    )
    p.add_argument(
        "--order", type=int, default=order, help=f"Fourier order per axis (default {order})"
    )
    solvers = solvers or SOLVERS
    p.add_argument(
        "--solver",
        choices=solvers,
        default=solvers[0],
        help=f"{' or '.join(solvers)} (default {solvers[0]}): torcwa needs splitcam[fullwave], "
        "fmmax in its FFT or Jones-direct formulation splitcam[fmmax] (fmmax-jones with "
        "--terms 1000 is the invrs-gym leaderboard's setting)",
    )
    p.add_argument(
        "--terms",
        type=int,
        help="fmmax: about this many Fourier terms, circular truncation (default (2 order + 1)^2)",
    )


def stack_of(args: argparse.Namespace, grid):
    """The :class:`~splitcam.physics.fullwave.RouterDesign` of :func:`add_stack_options`."""
    from ..physics.fullwave import RouterDesign, material_of

    return RouterDesign(
        grid,
        pitch=args.pitch,
        thickness=args.thickness,
        depth=args.depth,
        pillar=material_of(args.pillar),
        background=material_of(args.background),
        substrate=material_of(args.substrate),
        spacer=args.spacer,
    )


def read_layers(paths):
    """The design files of :func:`add_stack_options`'s stack, read: one file's grid, or the
    layers of several stacked (:func:`stacked`).

    Raises:
        FullwaveError: A file :func:`~splitcam.physics.fullwave.read_design` refuses, or
            layers of different grids.
    """
    from ..physics.fullwave import read_design

    return stacked(paths, [read_design(path) for path in paths])


def stacked(names, grids):
    """One layer's grid, or ``(layers, rows, cols)`` of several stacked, the first on top.

    Raises:
        FullwaveError: Layers of different grids (the message names both by ``names``).
    """
    import numpy as np

    from ..physics.fullwave import FullwaveError

    for name, grid in zip(names[1:], grids[1:], strict=True):
        if grid.shape != grids[0].shape:
            raise FullwaveError(
                f"the layers stacked must have one grid: {names[0]} is "
                f"{grids[0].shape[0]}x{grids[0].shape[1]} cells, {name} "
                f"{grid.shape[0]}x{grid.shape[1]}"
            )
    return grids[0] if len(grids) == 1 else np.stack(grids)


def stack_text(design, pillar: str, background: str, substrate: str) -> str:
    """The stack in words, for a pattern file's description: ``pitch 1 µm, 0.6 µm of Si3N4 in
    vacuum on SiO2, monitor 2.4 µm deep`` (layers stacked: each thickness from the top, and
    their spacer)."""
    thick = design.thicknesses
    if len(thick) == 1:
        layers = f"{thick[0]:g} µm of {pillar}"
    else:
        apart = f", {design.spacer:g} µm apart" if design.spacer else ", touching"
        each = " / ".join(f"{t:g}" for t in thick)
        layers = f"{len(thick)} layers of {pillar} ({each} µm{apart})"
    return (
        f"pitch {design.pitch:g} µm, {layers} in {background} on {substrate}, monitor "
        f"{design.depth:g} µm deep"
    )


def file_stem(name: str) -> str:
    """A pattern's name as the stem of the files written for it (safe in any file system)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "router"


def wavelengths_of(text: str) -> list[float]:
    """``400:700:10`` or ``450,540,650`` as a list of nm."""
    try:
        if ":" in text:
            first, last, step = (float(v) for v in text.split(":"))
            if step <= 0 or last < first:
                raise ValueError
            count = int(round((last - first) / step)) + 1
            return [first + i * step for i in range(count)]
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(
            f"--wavelengths: expected FIRST:LAST:STEP or A,B,C in nm, got {text!r}"
        ) from None


def run(args: argparse.Namespace) -> int:
    import numpy as np
    import torch

    from ..patterns.files import save_transmission
    from ..patterns.spectral import SpectralPattern
    from ..physics.fullwave import check_solver, quadrant_spectra

    check_solver(args.solver)  # a missing extra, before anything is read or shown
    lams = wavelengths_of(args.wavelengths)
    design = stack_of(args, read_layers(args.design))
    name = args.name or Path(args.design[0]).stem
    stem = file_stem(name)
    # The pattern's checks (wavelength range) before minutes of solving.
    SpectralPattern.from_transmission(name, lams, np.zeros((2, 2, len(lams))))
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder")
    if args.threads:
        torch.set_num_threads(args.threads)
    directions, where = _incidence(args)
    log = out / f"{stem}-solves.jsonl"
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=len(lams), desc=f"rcwa {args.solver}", unit="wavelength")
    result = quadrant_spectra(
        design,
        lams,
        order=args.order,
        directions=directions,
        solver=args.solver,
        terms=args.terms,
        progress=(lambda n: bar.update(n - bar.n)) if bar else None,
        cache=log,
        workers=args.workers,
    )
    if bar:
        bar.close()
    cost = result["cost"]
    if cost["reused"]:
        print(f"{cost['reused']} of {cost['solves']} solves taken from {log} (an earlier run)")
    t = _checked_transmission(args, result, out, stem, lams)
    info = {
        "provenance": f"full-wave (RCWA, {_solved_by(args, result['terms'])}, {where})",
        "description": f"metasurface router {', '.join(Path(d).name for d in args.design)}: "
        f"{stack_text(design, args.pillar, args.background, args.substrate)}; {where}",
        "reference": "splitcam optics rcwa",
    }
    out.mkdir(parents=True, exist_ok=True)
    pattern_file = save_transmission(out / f"{stem}.toml", name, lams, t, **info)
    spectra = _write_spectra(out, stem, lams, {**result, "transmission": t})
    chart = _say_roles(
        lams, t, result["reflection"], out / f"{stem}-spectra.png", f"{name}: {where}"
    )
    print(
        f"wrote {spectra}, {chart} and {pattern_file} ({cost['solves']} solves, "
        f"{cost['seconds']:.0f} s of solving)"
    )
    return 0


def _checked_transmission(
    args: argparse.Namespace, result: dict, out: Path, stem: str, lams: list[float]
):
    """The transmission, refused (the spectra written for a look) where a solve is not a
    number or clearly not converged; rounding errors below zero set to zero."""
    import numpy as np

    t = result["transmission"]
    # A quadrant that receives almost nothing can come out a rounding error below zero; a
    # clearly negative net flux means the solve is not converged (raise --order).
    if not np.all(np.isfinite(t)):
        li = int(np.argwhere(~np.isfinite(t))[0][2])
        written = _write_spectra(out, stem, lams, result)
        raise ValueError(f"the solve at {lams[li]:g} nm is not a number; {written} written")
    lowest = float(t.min())
    if lowest < -1e-3:
        i, j, li = np.unravel_index(int(t.argmin()), t.shape)
        written = _write_spectra(out, stem, lams, result)
        raise ValueError(
            f"quadrant ({i}, {j}) at {lams[li]:g} nm transmits {lowest:.4f} < 0: not converged "
            f"with {_solved_by(args, result['terms'])}; raise --order or --terms ({written} "
            "written for a look)"
        )
    t = np.clip(t, 0.0, None)
    return t


def _incidence(args: argparse.Namespace) -> tuple[list, str]:
    """The directions of the light (:func:`~splitcam.physics.fullwave.cone_directions`;
    checked before any work) and their description for the pattern's provenance."""
    from ..physics.fullwave import cone_directions

    # 0 is refused with the other impossible f-numbers (it once meant normal incidence).
    directions = cone_directions(
        args.f_number, math.radians(args.chief_ray), math.radians(args.chief_ray_azimuth)
    )
    where = (
        f"{len(directions)} directions of an f/{args.f_number:g} cone"
        if args.f_number is not None
        else "normal incidence"
    )
    if args.chief_ray:
        where = (
            f"{where.replace('normal incidence', 'collimated light')}, chief ray "
            f"{args.chief_ray:g} degrees off the normal towards azimuth "
            f"{args.chief_ray_azimuth:g} degrees"
        )
    return directions, where


def _say_roles(lams, t, reflection, chart: Path, title: str) -> Path:
    """Print which pixel collects which colour and the band efficiencies (or, where blue and
    red peak in one pixel, say so with the numbers), and draw the chart accordingly."""
    from ..physics.fullwave import FullwaveError, band_efficiencies

    try:
        eff = band_efficiencies(t, lams)
    except FullwaveError as exc:
        print(f"warning: {exc}", file=sys.stderr)
        _chart(lams, t, reflection, None, chart, title)
        return chart
    _chart(lams, t, reflection, eff["quadrants"], chart, title)
    print(
        f"blue peaks in quadrant (row, col) {divmod(eff['quadrants']['blue'], 2)}, red in "
        f"{divmod(eff['quadrants']['red'], 2)}; band efficiency blue {eff['blue']:.3f}, "
        f"green {eff['green']:.3f}, red {eff['red']:.3f}; reflection {reflection.mean():.3f}"
    )
    return chart


def _write_spectra(out: Path, stem: str, lams, result: dict) -> Path:
    """``STEM-spectra.csv``: the mean of the polarisations, each polarisation, and the
    reflection; its path."""
    import numpy as np

    from ..io import write_text

    out.mkdir(parents=True, exist_ok=True)
    header = ["wavelength_nm"]
    columns = [np.asarray(lams)]
    for label, values in (
        ("", result["transmission"]),
        ("x_", result["by_polarisation"][0]),
        ("y_", result["by_polarisation"][1]),
    ):
        for i in range(2):
            for j in range(2):
                header.append(f"{label}T_row{i}_col{j}")
                columns.append(values[i, j])
    header.append("reflection")
    columns.append(result["reflection"])
    rows = [",".join(header)]
    rows += [",".join(f"{v:.6g}" for v in row) for row in np.stack(columns, axis=1)]
    path = out / f"{stem}-spectra.csv"
    write_text(path, "\n".join(rows) + "\n")
    return path


def _solved_by(args: argparse.Namespace, terms: int) -> str:
    """``order 9`` for torcwa (the provenance the shipped files carry), ``fmmax-jones, 997
    terms`` for fmmax."""
    return f"order {args.order}" if args.solver == "torcwa" else f"{args.solver}, {terms} terms"


def _chart(lams, t, reflection, roles: dict[str, int] | None, path: Path, title: str) -> None:
    """The spectra, each pixel in the colour it collects (``roles``: the blue and red
    quadrants of :func:`~splitcam.physics.fullwave.band_efficiencies`; None: the design has no
    such roles, and each pixel gets a neutral colour)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..viz._save import save_figure

    # Blue where the shortest wavelength peaks, red where the longest peaks, green the other two
    # (dashed for the second).
    if roles is None:
        neutral = ("black", "dimgray", "darkgray", "silver")
        styles = {q: (neutral[q], "-", "no colour role") for q in range(4)}
    else:
        styles = {
            roles["blue"]: ("tab:blue", "-", "blue"),
            roles["red"]: ("tab:red", "-", "red"),
        }
        greens = [q for q in range(4) if q not in styles]
        for k, q in enumerate(greens):
            styles[q] = ("tab:green", "-" if k == 0 else "--", "green")
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for q in range(4):
        i, j = divmod(q, 2)
        colour, line, role = styles[q]
        label = f"pixel row {i}, col {j} ({role})"
        ax.plot(lams, t[i, j], line, color=colour, marker=".", label=label)
    ax.plot(lams, reflection, "k:", label="reflected")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("share of the light on the period")
    ax.set_ylim(0, max(1e-3, float(t.max())) * 1.1)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save_figure(fig, path)
