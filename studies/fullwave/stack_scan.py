"""The stack around a fixed layout: what the layer's thickness, the monitor's depth (the spacer
between the metasurface and the photodiodes) and the pillars' index are worth to the image,
before any cell moves.

    OMP_NUM_THREADS=1 python studies/fullwave/stack_scan.py [--part K/N] [VARIANT ...]
    python studies/fullwave/stack_scan.py --table        # scan.md from every part's rows

A variant changes the design runs' stack (``thickness=0.6``, ``depth=2.0``, ``pillar=2.4``,
joined by commas: ``pillar=2.4,thickness=0.52``; a pillar is a material name or an index) and
keeps everything else of ``best-n30-fab-f2``'s setting: the leaderboard design's layout, fmmax
Jones-direct at 357 terms, the f/2 cone's seven directions, six wavelengths, every pixel behind
silicon and the D5100's IR cut. Each variant is 42 forward solves (about 2.5 minutes of one
thread); its spectra and the closed-form LMMSE PSNR at N = 10, 30, 100, 300 and 1000 (read noise
2 e-) are appended to ``scan.jsonl`` in docs/results/fullwave/scan/ (``scan-KofN.jsonl`` with
``--part``), and a variant already there is not solved again, so a stopped scan continues.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from verify_design import psnr_at  # noqa: E402  (the verification's own PSNR)

from splitcam.design.fullwave import FullwaveDesign
from splitcam.io import appending, read_json_lines, write_text
from splitcam.physics.fullwave import band_efficiencies, material_of, read_design

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "results" / "fullwave" / "scan"
SETTING = ROOT / "docs" / "results" / "fullwave" / "design" / "best-n30-fab-f2" / "state.json"
EXPOSURES = (10.0, 30.0, 100.0, 300.0, 1000.0)
STACK = ("pitch", "thickness", "depth", "pillar", "background", "substrate")
#: The leaderboard stack first (the reference every row is read against), then one change at a
#: time: the layer thinner and thicker, the spacer shallower and deeper, and pillars of a higher
#: index at the thickness that keeps the pillars' optical path over the background.
VARIANTS = (
    "",
    "thickness=0.5",
    "thickness=0.6",
    "thickness=0.65",
    "thickness=0.75",
    "thickness=0.8",
    "thickness=0.9",
    "depth=1.6",
    "depth=2.0",
    "depth=2.4",
    "depth=3.2",
    "depth=3.6",
    "pillar=2.4,thickness=0.51",
    "pillar=2.4,thickness=0.6",
    "pillar=2.6,thickness=0.45",
)


def parse_variant(text: str) -> dict[str, float | str]:
    """``"pillar=2.4,thickness=0.51"`` → ``{"pillar": 2.4, "thickness": 0.51}``; ``""`` → ``{}``.

    Raises:
        ValueError: A part that is not ``name=value`` for a name of the stack, or a length that
            is not a number.
    """
    changes: dict[str, float | str] = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        name, sep, value = part.partition("=")
        if not sep or name not in STACK:
            raise ValueError(f"variant part {part!r}: expected NAME=VALUE, NAME one of {STACK}")
        if name in ("pillar", "background", "substrate"):
            changes[name] = material_of(value)
        else:
            try:
                changes[name] = float(value)
            except ValueError:
                raise ValueError(f"variant part {part!r}: {name} is a length in µm") from None
    return changes


def settings_of(base: dict, changes: dict) -> dict:
    """``base`` (a design run's settings) with its stack changed as ``changes`` says."""
    stack = dict(zip(STACK, base["stack"], strict=True))
    stack.update(changes)
    return {**base, "stack": [stack[k] for k in STACK]}


def _label(changes: dict) -> str:
    return ",".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in changes.items()
    )


def _solve(design: FullwaveDesign, layout: np.ndarray) -> dict:
    start = time.monotonic()
    with torch.no_grad():
        t, reflection = design.transmission(torch.from_numpy(layout))
    t = t.clamp_min(0.0)
    values = psnr_at(design.wavelengths, t.numpy(), EXPOSURES, design.read_noise, design.optics)
    psnr = {f"{n:g}": round(p, 4) for n, p in zip(EXPOSURES, values, strict=True)}
    wl = np.asarray(design.wavelengths)
    eff = band_efficiencies(t.numpy(), wl, {"blue": 0, "red": 3})  # the bare pixel's
    return {
        "psnr": psnr,
        "efficiency": {k: round(float(eff[k]), 4) for k in ("blue", "green", "red")},
        "reflection": round(float(reflection.mean()), 4),
        "transmission": t.numpy().round(6).tolist(),
        "seconds": round(time.monotonic() - start, 1),
    }


def rows() -> list[dict]:
    """Every variant solved so far, from the whole scan's and every part's file, once each."""
    found: dict[str, dict] = {}
    for path in sorted(OUT.glob("scan*.jsonl")):
        for _, _, row in read_json_lines(path)[0]:
            found.setdefault(row["variant"], row)
    return list(found.values())


def _order(row: dict) -> tuple:
    """The leaderboard stack first, then by what a variant changes and by how much."""
    changes = parse_variant(row["variant"])
    values = tuple(v if isinstance(v, float) else math.inf for v in changes.values())
    return (bool(changes), tuple(changes), values)


def table(found: list[dict]) -> str:
    """The scan as a Markdown table, each row against the leaderboard stack's."""
    ref = next((r for r in found if r["variant"] == ""), None)
    head = "| stack (change from the leaderboard's) | blue / green / red efficiency | reflection |"
    head += "".join(f" N = {n:g} |" for n in EXPOSURES)
    lines = [head, "|" + "---|" * (3 + len(EXPOSURES))]
    for r in sorted(found, key=_order):
        e = r["efficiency"]
        cells = []
        for n in EXPOSURES:
            p = r["psnr"][f"{n:g}"]
            d = "" if ref is None or r is ref else f" ({p - ref['psnr'][f'{n:g}']:+.2f})"
            cells.append(f" {p:.2f}{d} |")
        name = r["variant"] or "leaderboard: thickness 0.699, depth 2.8, Si3N4"
        lines.append(
            f"| {name} | {e['blue']:.3f} / {e['green']:.3f} / {e['red']:.3f} "
            f"| {r['reflection']:.3f} |" + "".join(cells)
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("variants", nargs="*", default=list(VARIANTS))
    parser.add_argument("--part", default="1/1", help="K/N: every N-th variant from the K-th")
    parser.add_argument("--table", action="store_true", help="write scan.md and stop")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    if args.table:
        write_text(OUT / "scan.md", table(rows()))
        print((OUT / "scan.md").read_text(encoding="utf-8"))
        return
    try:
        k, n = (int(x) for x in args.part.split("/"))
        variants = [parse_variant(v) for v in args.variants]
    except ValueError as exc:
        parser.error(str(exc) if "variant" in str(exc) else f"--part {args.part}: expected K/N")
    if not 1 <= k <= n:
        parser.error(f"--part {args.part}: expected K/N with 1 <= K <= N")
    mine = variants[k - 1 :: n]
    base = json.loads(SETTING.read_text(encoding="utf-8"))["settings"]
    layout = read_design(ROOT / base["start"])
    log = OUT / ("scan.jsonl" if n == 1 else f"scan-{k}of{n}.jsonl")
    done = {r["variant"] for r in rows()}
    for changes in mine:
        label = _label(changes)
        if label in done:
            continue
        settings = settings_of(base, changes)
        design = FullwaveDesign.from_settings(layout, settings)
        row = {"variant": label, "stack": settings["stack"], **_solve(design, layout)}
        with appending(log) as fh:
            fh.write(json.dumps(row) + "\n")
        print(
            json.dumps({key: row[key] for key in ("variant", "psnr", "efficiency", "seconds")}),
            flush=True,
        )


if __name__ == "__main__":
    main()
