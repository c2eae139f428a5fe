"""The answer in a designer's units across illuminants and pixel pitches: each router's crossover
against the arrays (with its 90 % interval over images), from one study per illuminant whose
scenes that illuminant lights (``splitcam study exposure --illuminant``: D65 daylight, CIE A
tungsten, a white LED), converted to scene lux at pixel pitches of 0.6, 0.8 and 1.0 µm, f/2,
1/30 s, a white scene (splitcam.physics.radiometry).

    python studies/exposure/lux_sweep.py [--study D65=docs/results/exposure/answer/rn2
        --study A=DIR --study LED=DIR] [--out docs/results/exposure/lux]

(the default: ``answer/rn2``, ``answer/rn2-A`` and ``answer/rn2-LED``); the rows are the
routers every study has.

The routers are solved at a 1 µm pitch; the other pitches convert the same crossover in N, as
if the router kept its kernels when scaled (it would need designing again). Two significant
figures, as the study's tables.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path

from splitcam.evaluation.exposure import two_figures
from splitcam.evaluation.tables import markdown_table
from splitcam.io import write_text
from splitcam.physics.radiometry import Camera

REFERENCES = ["rgbw-d5100", "bayer-d5100"]
ILLUMINANTS = {"D65": "D65 daylight", "A": "CIE A tungsten", "LED": "white LED (LED-B3)"}
PITCHES = (0.6, 0.8, 1.0)
METHOD = "net-universal-photon-"
ANSWER = "docs/results/exposure/answer/rn2"
DEFAULT_STUDIES = [f"D65={ANSWER}", f"A={ANSWER}-A", f"LED={ANSWER}-LED"]


def crossovers(study: Path) -> tuple[dict[tuple[str, str], dict], dict]:
    """The pooled PSNR crossovers of the network's rows (each with the study's exposures under
    ``range``), and the study's camera as it recorded it."""
    data = json.loads((study / "exposure.json").read_text(encoding="utf-8"))
    out = {}
    for row in data["crossovers"]:
        if row["metric"] != "psnr" or row["scene_set"] != "all":
            continue
        cand, ref = row["candidate"], row["reference"]
        if cand.startswith(METHOD) and ref.startswith(METHOD):
            photons = [float(n) for n in data["results"][cand]]
            row = {**row, "range": (min(photons), max(photons))}
            out[(cand.removeprefix(METHOD), ref.removeprefix(METHOD))] = row
    return out, data["camera"]


def _cameras(illuminant: str, recorded: dict, folder: str) -> dict[float, Camera]:
    """The camera at each pitch, with the share of N a white scene gives that the study recorded
    for its light; the study itself must be the one at 1 µm."""
    white = recorded.get("white", 1.0)
    cameras = {pitch: Camera(pitch, 2.0, illuminant=illuminant, white=white) for pitch in PITCHES}
    if not math.isclose(
        recorded["electrons_per_lux"], cameras[1.0].electrons_per_lux, rel_tol=1e-9
    ):
        raise SystemExit(f"{folder}: not a study at 1 µm, f/2, 1/30 s under {illuminant}")
    return cameras


def _cells(row: dict | None, cameras: dict[float, Camera]) -> list[str]:
    """N and lux at each pitch; an interval's end outside the exposures studied is written as
    the study writes it (``<`` the lowest, ``>`` the highest)."""
    if row is None or row["crossover"] is None or math.isinf(row["crossover"]):
        return ["–"] * (1 + len(PITCHES))
    n, low, high = row["crossover"], row["low"], row["high"]
    lowest, highest = row["range"]

    def interval(convert) -> str:
        lo = f"<{two_figures(convert(lowest))}" if low == 0.0 else two_figures(convert(low))
        hi = f">{two_figures(convert(highest))}" if math.isinf(high) else two_figures(convert(high))
        return f"{two_figures(convert(n))} [{lo}, {hi}]"

    return [interval(lambda x: x)] + [interval(cameras[pitch].lux) for pitch in PITCHES]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", action="append", help="ILLUMINANT=DIR, one per illuminant")
    parser.add_argument("--out", default="docs/results/exposure/lux")
    args = parser.parse_args()
    studies = dict(s.split("=", 1) for s in args.study or DEFAULT_STUDIES)
    found, cameras, whites = {}, {}, {}
    for ill, folder in studies.items():
        if ill not in ILLUMINANTS:
            raise SystemExit(
                f"unknown illuminant {ill!r}; expected one of {', '.join(ILLUMINANTS)}"
            )
        found[ill], recorded = crossovers(Path(folder))
        cameras[ill] = _cameras(ill, recorded, folder)
        whites[ill] = recorded.get("white", 1.0)
    routers = sorted(
        set.intersection(
            *(
                {c for c, r in table if c not in REFERENCES and r in REFERENCES}
                for table in found.values()
            )
        )
    )
    header = ["router", "against"] + [
        f"{ill} {what}" for ill in studies for what in ["N", *(f"{p:g} µm" for p in PITCHES)]
    ]
    rows = []
    for router in routers:
        for ref in REFERENCES:
            cells = [
                c for ill in studies for c in _cells(found[ill].get((router, ref)), cameras[ill])
            ]
            rows.append([router, ref, *cells])
    links = ", ".join(
        f"[{ill}]({os.path.relpath(Path(folder) / 'exposure.md', args.out)})"
        for ill, folder in studies.items()
    )
    per_lux = {
        f"{ill} {p:g} µm": cameras[ill][p].electrons_per_lux for ill in studies for p in PITCHES
    }
    lines = [
        "# The answer in lux: illuminants and pixel pitches",
        "",
        "Each router beats the array below this exposure N and scene illuminance (lux; 90 % "
        "interval over the images in brackets), at f/2, 1/30 s, a white scene; one study per "
        f"illuminant, whose scenes it lights ({links}: network `universal-photon` for every "
        "sensor, read noise 2 e⁻, every pixel behind the same stack, 48 images). "
        "N is in the model's units: "
        + "".join(
            f"under {ill} a white scene gives a bare pixel {whites[ill]:.2f} N; "
            for ill in studies
            if whites[ill] != 1
        )
        + "under D65, N (model.md section 19).",
        "",
        *markdown_table(header, rows),
        "",
        "N per lux of each column: "
        + ", ".join(f"{k} {v:.3g}" for k, v in per_lux.items())
        + ". The routers are solved at a 1 µm pitch: the 0.6 and 0.8 µm columns convert the "
        "same N, as if a router kept its kernels when scaled (it would need designing again). "
        "A smaller pixel collects fewer photons per lux, so the same N needs more light: at "
        "0.6 µm every figure is 2.8 times the 1 µm one.",
        "",
        "`python studies/exposure/lux_sweep.py "
        + " ".join(f"--study {ill}={folder}" for ill, folder in studies.items())
        + f" --out {args.out}`",
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "README.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
