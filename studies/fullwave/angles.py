"""Both published routers at one solver setting: how many Fourier terms they need, and what a
lens's cone and the chief ray at the edge of the field take from them.

    OMP_NUM_THREADS=1 python studies/fullwave/angles.py [--stage convergence|angles|all]
        [--out docs/results/fullwave/angles]

One solver and formulation for both designs: fmmax, Jones-direct (the invrs-gym leaderboard's;
``pip install 'splitcam[fmmax]'``), both polarisations averaged, the six leaderboard wavelengths
(433, 467, 533, 567, 633 and 667 nm: two per band), band efficiency = the mean transmission of a
band into its own pixels (:func:`splitcam.physics.fullwave.band_efficiencies`).

1. **convergence**: normal incidence at about 121, 221, 357, 621 and 997 terms (circular
   truncation). The reference is 997 terms, the leaderboard's setting (the best design lands
   within 0.003 of the leaderboard's published numbers there). The setting used for the angles
   is the cheapest whose band efficiencies lie within 0.02 of the reference for both designs;
   its largest error is stated.
2. **angles**: at that setting, the cone of an f/2 and an f/1.4 lens (7 directions each,
   :func:`splitcam.physics.fullwave.cone_directions`) with its chief ray at 0, 15 and 25
   degrees (the centre, middle and corner of a phone camera's field), tilted along the
   design's diagonal (towards a corner), and the collimated chief ray alone.

Every solve (one wavelength, one direction, both polarisations) is appended to
``OUT/solves.jsonl`` the moment it finishes, with its seconds; a run interrupted at any point
continues from there when started again, and the summary (``OUT/angles.json``,
``OUT/angles.md``) is rewritten after every finished setting, so partial results can be
read while the rest runs.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import numpy as np

from splitcam.io import write_text
from splitcam.physics.fullwave import (
    RouterDesign,
    band_efficiencies,
    cone_directions,
    quadrant_spectra,
    read_design,
)

ROOT = Path(__file__).resolve().parents[2]
DESIGNS = ROOT / "experiments" / "fullwave" / "designs"
WAVELENGTHS = (433.0, 467.0, 533.0, 567.0, 633.0, 667.0)
TERMS = (121, 221, 357, 621, 797, 997)
REFERENCE = 997
TOLERANCE = 0.02
#: (f-number or None for the chief ray alone, chief-ray angle in degrees), in the order run:
#: the centre and the corner first.
LENSES = [(2.0, 0), (2.0, 25), (1.4, 0), (1.4, 25), (2.0, 15), (1.4, 15), (None, 25), (None, 15)]
AZIMUTH = math.pi / 4  # along the diagonal, towards a corner of the field


def designs() -> dict[str, RouterDesign]:
    return {
        "zou": RouterDesign(read_design(DESIGNS / "zou2022-16x16.csv")),
        "best": RouterDesign(read_design(DESIGNS / "best-240325.csv"), thickness=0.699, depth=2.8),
    }


def solve(design, terms, directions, cache, quadrants=None) -> dict:
    out = quadrant_spectra(
        design,
        list(WAVELENGTHS),
        solver="fmmax-jones",
        terms=terms,
        directions=directions,
        cache=cache,
    )
    bands = band_efficiencies(out["transmission"], WAVELENGTHS, quadrants)
    return {
        "terms": out["terms"],
        "quadrants": bands["quadrants"],
        "blue": bands["blue"],
        "green": bands["green"],
        "red": bands["red"],
        "reflection": float(out["reflection"].mean()),
        "seconds": round(out["cost"]["seconds"], 1),
        "solves": out["cost"]["solves"],
        "transmission": out["transmission"].tolist(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stage", choices=["convergence", "angles", "all"], default="all")
    parser.add_argument("--out", type=Path, default=ROOT / "docs/results/fullwave/angles")
    parser.add_argument("--terms", type=int, help="the setting of the angles (default: chosen)")
    parser.add_argument(
        "--designs",
        nargs="+",
        choices=["zou", "best"],
        default=["zou", "best"],
        help="solve these designs (two runs, one design each, can share the folder)",
    )
    parser.add_argument(
        "--lenses",
        nargs="+",
        type=_lens,
        help="the settings to solve, F:ANGLE each (F an f-number or none for the chief ray "
        "alone, ANGLE the chief ray's in degrees; default every one of LENSES, in its order): "
        "two runs of one design can share the settings out",
    )
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    args.out.mkdir(parents=True, exist_ok=True)
    cache = args.out / "solves.jsonl"
    summary_path = args.out / "angles.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    summary.setdefault("convergence", {})
    summary.setdefault("angles", {})
    routers = {k: v for k, v in designs().items() if k in args.designs}

    def save() -> None:
        # Several runs (--designs) may share the folder: keep what the others wrote since.
        if summary_path.exists():
            theirs = json.loads(summary_path.read_text())
            for part in ("convergence", "angles"):
                summary[part] = {**theirs.get(part, {}), **summary[part]}
        write_text(summary_path, json.dumps(summary, indent=1) + "\n")
        write_text(args.out / "angles.md", tables(summary))

    if args.stage in ("convergence", "all"):
        if "best/997" not in summary["convergence"]:
            summary["convergence"]["best/997"] = earlier_best()
        # The reference first, so that the cheaper settings can be judged as they come.
        for terms in (REFERENCE, *TERMS[:-1]):
            for name, design in routers.items():
                key = f"{name}/{terms}"
                if key in summary["convergence"]:
                    continue
                start = time.perf_counter()
                summary["convergence"][key] = solve(design, terms, [(0.0, 0.0, 1.0)], cache)
                print(
                    f"{key}: {fmt(summary['convergence'][key])} "
                    f"({time.perf_counter() - start:.0f} s)",
                    flush=True,
                )
                save()
        summary["chosen"] = choose(summary["convergence"])
        save()
    if args.stage in ("angles", "all"):
        terms = args.terms or summary.get("chosen", {}).get("terms")
        if terms is None:
            sys.exit("run --stage convergence first, or give --terms")
        for f_number, chief in args.lenses or LENSES:
            directions = cone_directions(f_number, math.radians(chief), AZIMUTH)
            for name, design in routers.items():
                key = f"{name}/{terms}/f{f_number or 'none'}/cra{chief}"
                if key in summary["angles"]:
                    continue
                # Efficiencies into the pixels the design sorts to at normal incidence (its
                # solve is in the log already): oblique light may sort worse, or not at all.
                normal = solve(design, terms, [(0.0, 0.0, 1.0)], cache)
                start = time.perf_counter()
                summary["angles"][key] = solve(
                    design, terms, directions, cache, normal["quadrants"]
                )
                print(
                    f"{key}: {fmt(summary['angles'][key])} ({time.perf_counter() - start:.0f} s)",
                    flush=True,
                )
                save()


def _lens(text: str) -> tuple[float | None, int]:
    """``2:15`` -> (2.0, 15); ``none:25`` -> (None, 25); only the settings of LENSES."""
    f_number, _, chief = text.partition(":")
    try:
        lens = (None if f_number == "none" else float(f_number), int(chief))
    except ValueError:
        lens = None
    if lens not in LENSES:
        known = " ".join(f"{f or 'none'}:{c}" for f, c in LENSES)
        raise argparse.ArgumentTypeError(f"{text!r} is not one of {known}")
    return lens


def earlier_best() -> dict:
    """The best design at the reference setting, as solved by studies/fullwave/leaderboard.py
    (the same function, solver, terms and wavelengths; docs/results/fullwave/best-fmmax/), so
    its 22 minutes are not spent again."""
    quads, seconds = {}, 0.0
    for path in sorted((ROOT / "docs/results/fullwave/best-fmmax").glob("check-*.json")):
        run = json.loads(path.read_text())
        terms = run["terms"]
        quads.update({float(k): np.array(v) for k, v in run["quadrants"].items()})
        seconds += sum(run["seconds"].values())
    t = np.stack([quads[lam] for lam in WAVELENGTHS], axis=-1)
    bands = band_efficiencies(t, WAVELENGTHS)
    return {
        "terms": terms,
        "blue": bands["blue"],
        "green": bands["green"],
        "red": bands["red"],
        "reflection": None,
        "seconds": round(seconds, 1),
        "solves": len(WAVELENGTHS),
        "transmission": t.tolist(),
        "from": "docs/results/fullwave/best-fmmax/",
    }


def fmt(r: dict) -> str:
    return f"{r['blue']:.3f} / {r['green']:.3f} / {r['red']:.3f} ({r['terms']} terms)"


def choose(convergence: dict) -> dict:
    """The cheapest term count whose band efficiencies lie within TOLERANCE of the reference's
    for every design solved at both."""
    names = sorted({k.split("/")[0] for k in convergence})
    for terms in TERMS:
        errors = []
        for name in names:
            ours, ref = convergence.get(f"{name}/{terms}"), convergence.get(f"{name}/{REFERENCE}")
            if ours is None or ref is None:
                break
            errors += [abs(ours[c] - ref[c]) for c in ("blue", "green", "red")]
        else:
            if errors and max(errors) <= TOLERANCE:
                return {"terms": terms, "largest_error": round(max(errors), 4)}
    return {"terms": REFERENCE, "largest_error": 0.0}


def refl(r: dict) -> str:
    return "–" if r.get("reflection") is None else f"{r['reflection']:.3f}"


def tables(summary: dict) -> str:
    lines = [
        "## Convergence (normal incidence, fmmax Jones-direct)",
        "",
        "| design | terms | blue | green | red | reflection | seconds (6 wavelengths) |",
        "|---|---|---|---|---|---|---|",
    ]
    for key, r in sorted(
        summary["convergence"].items(),
        key=lambda kv: (kv[0].split("/")[0], int(kv[0].split("/")[1])),
    ):
        lines.append(
            f"| {key.split('/')[0]} | {r['terms']} | {r['blue']:.3f} | {r['green']:.3f} "
            f"| {r['red']:.3f} | {refl(r)} | {r['seconds']:.0f} |"
        )
    chosen = summary.get("chosen")
    if chosen:
        lines += [
            "",
            f"Chosen: {chosen['terms']} terms (largest band error against "
            f"{REFERENCE} terms: {chosen['largest_error']:.3f}).",
        ]
    lines += [
        "",
        "## Angles",
        "",
        "| design | lens | chief ray | blue | green | red | seconds |",
        "|---|---|---|---|---|---|---|",
    ]
    for key, r in summary["angles"].items():
        name, _, lens, cra = key.split("/")
        lens = "collimated" if lens == "fnone" else lens.replace("f", "f/")
        lines.append(
            f"| {name} | {lens} | {cra[3:]}° | {r['blue']:.3f} | {r['green']:.3f} | "
            f"{r['red']:.3f} | {r['seconds']:.0f} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
