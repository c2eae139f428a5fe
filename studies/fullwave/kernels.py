"""Both routers' spatial kernels computed from their fields (splitcam.physics.bloch) beside the
nearest-copy rule applied to the same totals: what the rule assumes, measured.

    OMP_NUM_THREADS=1 python studies/fullwave/kernels.py [--designs zou,best] [--terms 97]
        [--out docs/results/fullwave/kernels]

``--designs`` names the published routers (``zou``, ``best``) or, as ``NAME=DESIGN.csv``, a design
of ``splitcam optics rcwa-design``, whose stack is read from the run's ``state.json`` beside it.

For each design, behind an f/2 lens at the centre of the field, over 410-690 nm every 20 nm:
fmmax Jones-direct at ``--terms``, a 3 x 3 Bloch grid (a 6 x 6-pixel supercell), 2 x 2 spot
positions per pixel. Writes, per design, the pattern with the computed kernels
(``NAME-f2-computed-7x7.json``, and ``NAME-f2-computed.json`` with the outer ring dropped for
networks that take kernels up to 5 x 5), the pattern of the nearest-copy rule on the same totals
(the computed kernels' sums over the period, ``NAME-f2-nearest.toml``), ``kernels.md`` (the
shares kept, sent to the nearest neighbours and farther, per band, and the fit's misfit) and
``NAME-kernels.png``. The solves are kept in ``solves.jsonl``: a stopped run continues.

``--part K/N`` solves only every N-th wavelength from the K-th, into ``solves-KofN.jsonl``, and
writes nothing else: N such processes side by side share the solving (one core each), then the
same command without ``--part`` takes their solves into ``solves.jsonl`` and writes the files.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from splitcam.io import write_text
from splitcam.patterns.files import save_spectral_kernels, save_transmission
from splitcam.physics.bloch import pixel_kernels, quadrant_sums
from splitcam.physics.fullwave import RouterDesign, read_design

DESIGNS = Path(__file__).resolve().parents[2] / "experiments" / "fullwave" / "designs"
ROUTERS = {
    "zou": ("zou2022-16x16.csv", {}, "Zou et al. 2022"),
    "best": ("best-240325.csv", {"thickness": 0.699, "depth": 2.8}, "the leaderboard's best"),
}
WAVELENGTHS = [float(v) for v in range(410, 691, 20)]
BANDS = {"blue": (400, 500), "green": (500, 600), "red": (600, 700)}


def _rings(kernel: np.ndarray) -> tuple[float, float, float]:
    """Shares kept, sent to the 8 nearest neighbours, sent farther."""
    half = kernel.shape[-1] // 2
    kept = kernel[..., half, half]
    near = kernel[..., half - 1 : half + 2, half - 1 : half + 2].sum(axis=(-2, -1)) - kept
    return float(kept), float(near), float(kernel.sum() - kept - near)


def _router(spec: str) -> tuple[str, str, RouterDesign, str]:
    """``(key, file name, design, words)`` of a published router's key or ``NAME=DESIGN.csv``
    (a design run's CSV, its stack from the run's ``state.json``)."""
    import json

    if "=" not in spec:
        csv, stack, words = ROUTERS[spec]
        return spec, csv, RouterDesign(read_design(DESIGNS / csv), **stack), words
    key, path = spec.split("=", 1)
    path = Path(path)
    state = path.parent / "state.json"
    if not state.exists():
        raise SystemExit(f"{path}: no state.json beside it to read the design's stack from")
    pitch, thickness, depth, pillar, background, substrate = json.loads(state.read_text())[
        "settings"
    ]["stack"]
    design = RouterDesign(read_design(path), pitch, thickness, depth, pillar, background, substrate)
    return key, path.name, design, f"designed by splitcam optics rcwa-design, {path.parent.name}"


def _nearest_kernels(transmission: np.ndarray) -> np.ndarray:
    from splitcam.patterns.spectral import SpectralPattern

    return SpectralPattern.from_transmission("rule", WAVELENGTHS, transmission).kernels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--designs", default="zou,best")
    parser.add_argument("--terms", type=int, default=97)
    parser.add_argument("--out", type=Path, default=Path("docs/results/fullwave/kernels"))
    parser.add_argument("--part", help="K/N: solve every N-th wavelength from the K-th, only")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.part:
        _solve_part(args)
        return
    _take_parts(args.out)
    lines = [
        "# Kernels computed from the fields, beside the nearest-copy rule",
        "",
        f"f/2, centre of the field; fmmax Jones-direct, about {args.terms} terms; 3 x 3 Bloch "
        "wavevectors, 2 x 2 spots per pixel; 410-690 nm every 20 nm. Per band and source "
        "pixel (the pixel whose colour the band is, or the mean over the others): the share "
        "kept, sent to the eight nearest pixels, sent farther.",
        "",
        "| router | band | source | computed: kept / near / farther | nearest-copy rule: kept / "
        "near / farther |",
        "|---|---|---|---|---|",
    ]
    misfits = []
    for spec in args.designs.split(","):
        key, csv, design, words = _router(spec)
        result = _solved(design, WAVELENGTHS, args.terms, args.out / "solves.jsonl", key)
        kernels = result["kernels"]
        totals = quadrant_sums(kernels)
        rule = _nearest_kernels(totals)
        info = {
            "provenance": f"full-wave (fmmax, JONES_DIRECT, {result['terms']} terms), f/2 lens",
            "reference": "studies/fullwave/kernels.py",
        }
        # The 7 x 7 kernels, and 5 x 5 (the outer ring dropped: counted as lost, against the
        # router) for the networks that take kernels up to 5 x 5.
        dropped = kernels.sum(axis=(-2, -1)) - kernels[..., 1:-1, 1:-1].sum(axis=(-2, -1))
        for suffix, k, note in (
            ("-7x7", kernels, ""),
            ("", kernels[..., 1:-1, 1:-1], f"; 5 x 5 (at most {dropped.max():.3f} dropped)"),
        ):
            save_spectral_kernels(
                args.out / f"{key}-f2-computed{suffix}.json",
                f"{key}-f2-computed{suffix}",
                WAVELENGTHS,
                [[0, 1], [2, 3]],
                k,
                description=f"metasurface router ({words}, {csv}) behind an f/2 lens: kernels "
                f"computed from the fields (splitcam.physics.bloch){note}",
                **info,
            )
        save_transmission(
            args.out / f"{key}-f2-nearest.toml",
            f"{key}-f2-nearest",
            WAVELENGTHS,
            totals,
            description=f"metasurface router ({words}, {csv}) behind an f/2 lens: the computed "
            "kernels' totals, spread by the nearest-copy rule",
            **info,
        )
        lam = np.asarray(WAVELENGTHS)
        for band, (lo, hi) in BANDS.items():
            inside = (lam >= lo) & (lam <= hi)
            home = int(np.argmax(totals.reshape(4, -1)[:, inside].mean(axis=1)))
            for label, sources in (
                ("its own", [home]),
                ("others", [s for s in range(4) if s != home]),
            ):
                ours = np.mean(
                    [_rings(kernels[s, li]) for s in sources for li in np.where(inside)[0]], axis=0
                )
                theirs = np.mean(
                    [_rings(rule[s, li]) for s in sources for li in np.where(inside)[0]], axis=0
                )
                lines.append(
                    f"| {key} | {band} | {label} | "
                    + " / ".join(f"{v:.3f}" for v in ours)
                    + " | "
                    + " / ".join(f"{v:.3f}" for v in theirs)
                    + " |"
                )
        misfits.append(
            f"- {key}: misfit {result['misfit'].min():.3f}-{result['misfit'].max():.3f}, "
            f"reflection {result['reflection'].mean():.3f}, outer ring (dropped in the 5 x 5 "
            f"pattern) at most {dropped.max():.3f}, {result['cost']['seconds'] / 60:.1f} "
            f"min of solving ({result['cost']['solves']} Bloch solves)"
        )
        _figure(args.out / f"{key}-kernels.png", kernels, rule, key)
    lines += [
        "",
        "The fit (relative residual of the intensity kernels against the coherent spots):",
        "",
    ]
    lines += misfits
    write_text(args.out / "kernels.md", "\n".join(lines) + "\n")
    print((args.out / "kernels.md").read_text(encoding="utf-8"))


def _solved(design: RouterDesign, lams: list[float], terms: int, cache: Path, label: str) -> dict:
    """The design's kernels behind f/2 at the centre of the field, its solves kept in
    ``cache``, progress printed under ``label``."""
    return pixel_kernels(
        design,
        lams,
        f_number=2.0,
        terms=terms,
        cache=cache,
        progress=lambda done: print(f"{label}: {done}/{len(lams)}", flush=True),
    )


def _solve_part(args) -> None:
    """Solve one part's wavelengths into its own file (appends from two processes to one
    file could interleave)."""
    import re

    found = re.fullmatch(r"(\d+)/(\d+)", args.part)
    if not found or not 1 <= int(found[1]) <= int(found[2]):
        raise SystemExit(f"--part is K/N with 1 <= K <= N, got {args.part!r}")
    k, n = int(found[1]), int(found[2])
    lams = WAVELENGTHS[k - 1 :: n]
    for spec in args.designs.split(","):
        key, _, design, _ = _router(spec)
        _solved(
            design, lams, args.terms, args.out / f"solves-{k}of{n}.jsonl", f"{key} part {k}/{n}"
        )


def _take_parts(out: Path) -> None:
    """The parts' solves appended to ``solves.jsonl`` (the lines it does not hold yet), each
    part's file removed once its lines are in."""
    parts = sorted(out.glob("solves-*of*.jsonl"))
    if not parts:
        return
    whole = out / "solves.jsonl"
    text = whole.read_text(encoding="utf-8") if whole.exists() else ""
    held = set(text.splitlines())
    with whole.open("a", encoding="utf-8") as f:
        if text and not text.endswith("\n"):
            f.write("\n")  # a line a stopped run cut short stays apart
        for part in parts:
            for line in part.read_text(encoding="utf-8").splitlines():
                if line.strip() and line not in held:
                    f.write(line + "\n")
                    held.add(line)
    for part in parts:
        part.unlink()


def _figure(path: Path, kernels: np.ndarray, rule: np.ndarray, key: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picks = [WAVELENGTHS.index(v) for v in (450.0, 550.0, 650.0)]
    fig, axes = plt.subplots(2, 6, figsize=(13, 4.6))
    for column, li in enumerate(picks):
        for row, (what, k) in enumerate((("computed", kernels), ("nearest-copy", rule))):
            for s in (0, 2):  # a green and a red/blue pixel of the period
                ax = axes[row, 2 * column + s // 2]
                pad = (kernels.shape[-1] - k.shape[-1]) // 2  # the rule's 3 x 3 at full size
                ax.imshow(np.pad(k[s, li], pad), vmin=0, vmax=1, cmap="magma")
                ax.set_title(f"{what}\n{WAVELENGTHS[li]:g} nm, pixel {divmod(s, 2)}", fontsize=8)
                ax.set_xticks([])
                ax.set_yticks([])
    fig.suptitle(
        f"{key}: where the light arriving on one pixel (the centre) lands, f/2; "
        "share 0 (black) to 1",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
