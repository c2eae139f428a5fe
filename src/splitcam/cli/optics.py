"""`splitcam optics`: the pattern a metasurface makes, or design one."""

from __future__ import annotations

import argparse
from pathlib import Path

from .design import add_search_options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "optics",
        help="the pattern a metasurface makes (scalar wave optics), or design one",
        description="Computes the splitter kernels that a metasurface height map makes above "
        "the sensor (angular spectrum propagation, spectral integration; "
        "splitcam.physics.optics) and writes the pattern file, its figure and the height map "
        "(.npy). With --design, optimises the height map from --profile for the closed-form "
        "LMMSE first.",
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
    p.add_argument("--out", help="pattern file (.toml or .json); required")
    p.add_argument("--quiet", action="store_true")
    add_search_options(
        p,
        "--max-height, --distance, --index, --lr, --profile (random, lens), --seed and "
        "--objective, for two scores at once (closed-form LMMSE PSNR and light collected; "
        "--out: the front's trial of highest PSNR)",
    )
    p.set_defaults(handler=run)
    # `splitcam optics rcwa DESIGN.csv` (the full-wave solver), `optics rcwa-design` (a layer
    # designed through it) and `optics rcwa-kernels` (its spatial kernels), each in its module.
    from . import rcwa, rcwa_design, rcwa_kernels

    sub = p.add_subparsers(dest="optics_command", metavar="{rcwa,rcwa-design,rcwa-kernels}")
    rcwa.register(sub)
    rcwa_design.register(sub)
    rcwa_kernels.register(sub)


#: The settings a metasurface search draws: setting -> (option attribute, default).
_SEARCHED = {
    "max_height": ("max_height", 1.2),
    "distance": ("distance", 2.0),
    "index": ("index", 2.0),
    "lr": ("lr", 0.1),
    "init": ("profile", "lens"),
    "seed": ("seed", 0),
    "objective": ("objective", "lmmse"),
}


def _search(args: argparse.Namespace, period: tuple[int, int], optics, out: Path) -> int:
    """``optics --search N``: the two-score search, its front, the figure and the best
    pattern."""
    from ..design.search import search_metasurfaces
    from .design import fixed_settings, search_error

    space = fixed_settings(args, _SEARCHED)
    if space.get("init", "random") != "random":
        raise ValueError("--search starts from random or lens profiles: --profile random or lens")
    if args.search < 1:
        raise ValueError(f"--search needs a number of trials >= 1, got {args.search}")
    try:
        search = search_metasurfaces(
            period,
            optics,
            trials=args.search,
            folder=args.study,
            steps=args.steps,
            space=space,
            seed=args.search_seed,
            progress=not args.quiet,
        )
    except ModuleNotFoundError as exc:
        return search_error("optics", exc)
    _print_front(search, space)
    return _write_front(search, out)


def _print_front(search, space: dict) -> None:
    """The state of the study and its Pareto front."""
    from ._common import table
    from .design import fmt

    trials = search.study.trials
    fixed = ", ".join(f"{k} {fmt(v)}" for k, v in space.items()) or "none"
    print(
        f"search in {search.folder}: {len(trials)} trial{'s' * (len(trials) != 1)}, "
        f"{len(search.finished())} finished "
        f"(fixed: {fixed})"
    )
    rows = []
    for t in search.best():
        row = {"trial": str(t.number), "PSNR (dB)": f"{t.values[0]:.3f}"}
        row["light"] = f"{t.values[1]:.1%}"
        row.update({k: fmt(t.params.get(k, "-")) for k in _SEARCHED})
        row["default"] = "yes" if t.user_attrs.get("baseline") else ""
        row["pattern"] = str(search.pattern_file(t.number))
        rows.append(row)
    if rows:
        print("Pareto front (closed-form LMMSE PSNR against light collected), by PSNR:")
        print(table(rows))


def _write_front(search, out: Path) -> int:
    """Draw the front; design its trial of highest PSNR again and write it to ``out``."""
    import dataclasses

    import numpy as np

    from .. import patterns
    from ..io import atomic_path
    from ..viz.patterns import draw_pattern
    from ..viz.search import draw_front

    front = search.best()
    if not front:
        print("no finished trial yet")
        return 1
    finished = search.finished()
    front_png = search.folder / "front.png"
    draw_front(
        [(100 * t.values[1], t.values[0]) for t in finished],
        [(100 * t.values[1], t.values[0]) for t in front],
        front_png,
        xlabel="light collected (%)",
        labels=[str(t.number) for t in front],
        baselines=[
            (100 * t.values[1], t.values[0]) for t in finished if t.user_attrs.get("baseline")
        ],
        title=f"metasurface search: {len(finished)} trials",
    )
    best = front[0]
    result, values = search.reproduce(best.number)
    same = all(abs(a - b) < 1e-9 for a, b in zip(values, best.values, strict=True))
    print(
        f"trial {best.number} designed again: {values[0]:.4f} dB, {values[1]:.2%} light"
        + ("" if same else " (differs: not reproduced)")
    )
    metadata = {**result.pattern.metadata, "search": str(search.folder), "trial": best.number}
    pattern = dataclasses.replace(result.pattern, name=out.stem, metadata=metadata)
    out.parent.mkdir(parents=True, exist_ok=True)
    patterns.save(pattern, out)
    with atomic_path(out.with_suffix(".npy")) as tmp:
        np.save(tmp, result.height.cpu().numpy())
    draw_pattern(pattern, out.with_suffix(".png"))
    print(
        f"wrote {out}, {out.with_suffix('.npy')} (height map, µm), {out.with_suffix('.png')} "
        f"and {front_png}"
    )
    return 0


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import patterns
    from ..io import atomic_path
    from ..physics.optics import Optics, bayer_collection, pattern_of, profile
    from ..viz.patterns import draw_height_maps, draw_pattern

    if not args.out:
        raise ValueError("splitcam optics: --out FILE is required (or: splitcam optics rcwa ...)")
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
    if args.search is not None:
        return _search(args, period, optics, out)
    height = profile(args.profile, period, optics, args.seed)
    if args.design:
        from ..design import design_metasurface

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
