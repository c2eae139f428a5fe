"""``splitcam optics rcwa-kernels``: a router's spatial kernels computed from its fields
(:mod:`splitcam.physics.bloch`), written as a spectral pattern beside the nearest-copy rule's on
the same totals."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from .rcwa import add_stack_options, file_stem, read_layers, stack_of, stack_text, wavelengths_of

__all__ = ["register"]


def register(optics_sub: argparse._SubParsersAction) -> None:
    p = optics_sub.add_parser(
        "rcwa-kernels",
        help="where a router sends the light arriving on each pixel, from its fields",
        description="Computes a 2x2 router's spatial kernels from its full-wave fields behind a "
        "lens (splitcam.physics.bloch, docs/model.md section 20; fmmax, the optional extra "
        "splitcam[fmmax]): the lens's focused spots across each pixel, solved by "
        "Brillouin-zone integration over CELLS x CELLS Bloch wavevectors, the lens's own blur "
        "fitted out. Writes to --out NAME-kernels.json (the pattern, (2 CELLS + 1)^2 kernels), "
        "NAME-kernels-5x5.json where those are larger (the outer rings dropped, counted as "
        "lost: for networks that take kernels up to 5 x 5) and NAME-nearest.toml (the same "
        "totals spread by the nearest-copy rule, to compare). Cost: CELLS^2 solves per "
        "wavelength. Every wavelength is kept in NAME-kernels-solves.jsonl as it finishes: the "
        "same command run again continues where it stopped.",
    )
    p.add_argument(
        "design",
        nargs="+",
        help="CSV grid of 0/1 or densities in [0, 1], rows along y; several: layers stacked, "
        "the top one first",
    )
    p.add_argument("--out", required=True, help="folder for the pattern files")
    p.add_argument("--name", help="the pattern's name (default: the design file's stem)")
    add_stack_options(p, wavelengths="410:690:20", order=4, solvers=("fmmax-jones", "fmmax-fft"))
    p.add_argument("--f-number", type=float, default=2.0, help="of the lens, > 0.5 (default 2)")
    p.add_argument(
        "--chief-ray", type=float, default=0.0, help="degrees off the normal (default 0)"
    )
    p.add_argument(
        "--chief-ray-azimuth",
        type=float,
        default=0.0,
        help="degrees, the direction of the tilt (0 along the columns, 45 the diagonal)",
    )
    p.add_argument(
        "--cells", type=int, default=3, help="Bloch wavevectors per axis, >= 2 (default 3)"
    )
    p.add_argument(
        "--positions", type=int, default=2, help="spot centres per pixel and axis (default 2)"
    )
    p.add_argument(
        "--samples", type=int, default=16, help="flux grid points per pixel and axis (default 16)"
    )
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..physics.fullwave import check_solver

    check_solver("fmmax-jones")  # a missing extra, before anything is read or shown
    lams = wavelengths_of(args.wavelengths)
    design = stack_of(args, read_layers(args.design))
    name = args.name or Path(args.design[0]).stem
    out = Path(args.out)
    result = _solve(args, design, lams, name, out)
    written = _write_patterns(args, design, result, lams, name, out)
    cost = result["cost"]
    print(
        f"wrote {', '.join(str(p) for p in written)}: misfit "
        f"{result['misfit'].min():.3f}-{result['misfit'].max():.3f}, reflection "
        f"{result['reflection'].mean():.3f} ({cost['solves']} Bloch solves, {cost['reused']} "
        f"reused, {cost['seconds']:.0f} s of solving)"
    )
    return 0


def _solve(args: argparse.Namespace, design, lams: list[float], name: str, out: Path) -> dict:
    """The settings checked (nothing solved or written before), then the kernels, resumable
    through the solve log in ``out``."""
    import numpy as np

    from ..patterns.spectral import SpectralPattern
    from ..physics.bloch import pixel_kernels

    SpectralPattern.from_transmission(name, lams, np.zeros((2, 2, len(lams))))  # the range
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder")
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=len(lams), desc="rcwa-kernels", unit="wavelength")
    result = pixel_kernels(
        design,
        lams,
        f_number=args.f_number,
        chief_ray=math.radians(args.chief_ray),
        azimuth=math.radians(args.chief_ray_azimuth),
        cells=args.cells,
        positions=args.positions,
        terms=args.terms or (2 * args.order + 1) ** 2,
        formulation="JONES_DIRECT" if args.solver == "fmmax-jones" else "FFT",
        samples=args.samples,
        progress=(lambda n: bar.update(n - bar.n)) if bar else None,
        cache=out / f"{file_stem(name)}-kernels-solves.jsonl",
    )
    if bar:
        bar.close()
    return result


def _write_patterns(
    args: argparse.Namespace, design, result: dict, lams: list[float], name: str, out: Path
) -> list[Path]:
    """The computed pattern, its 5 x 5 cut where the kernels are larger, and the nearest-copy
    pattern on the same totals."""
    import numpy as np

    from ..patterns.files import save_spectral_kernels, save_transmission
    from ..physics.bloch import quadrant_sums

    stem = file_stem(name)
    where = f"f/{args.f_number:g}, chief ray {args.chief_ray:g}°"
    solved = f"{args.solver}, {result['terms']} terms, {args.cells}x{args.cells} Bloch"
    info = {
        "provenance": f"full-wave ({solved}), {where}",
        "reference": "splitcam optics rcwa-kernels",
    }
    what = (
        f"metasurface router {', '.join(Path(d).name for d in args.design)}: "
        f"{stack_text(design, args.pillar, args.background, args.substrate)}; {where}"
    )
    kernels = result["kernels"]
    written = [
        save_spectral_kernels(
            out / f"{stem}-kernels.json",
            f"{name}-kernels",
            lams,
            [[0, 1], [2, 3]],
            kernels,
            description=f"{what}; kernels computed from the fields",
            **info,
        )
    ]
    if kernels.shape[-1] > 5:
        cut = (kernels.shape[-1] - 5) // 2
        small = kernels[..., cut:-cut, cut:-cut]
        dropped = float((kernels.sum(axis=(-2, -1)) - small.sum(axis=(-2, -1))).max())
        written.append(
            save_spectral_kernels(
                out / f"{stem}-kernels-5x5.json",
                f"{name}-kernels-5x5",
                lams,
                [[0, 1], [2, 3]],
                small,
                description=f"{what}; kernels computed from the fields, cut to 5 x 5 (at "
                f"most {dropped:.3f} dropped)",
                **info,
            )
        )
    written.append(
        save_transmission(
            out / f"{stem}-nearest.toml",
            f"{name}-nearest",
            lams,
            np.clip(quadrant_sums(kernels), 0.0, None),
            description=f"{what}; the computed kernels' totals spread by the nearest-copy rule",
            **info,
        )
    )
    return written
