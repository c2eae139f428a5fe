"""The answer in a designer's units across illuminants and pixel pitches: each router's crossover
against the arrays (with its 90 % interval over images), converted to scene lux for D65
daylight, CIE A tungsten and a white LED, at pixel pitches of 0.6, 0.8 and 1.0 µm, f/2,
1/30 s, a white scene (splitcam.physics.radiometry).

    python studies/exposure/lux_sweep.py [docs/results/exposure/measured/rn2]
        [--out docs/results/exposure/lux]

Only the conversion changes between columns: the crossovers themselves come from one study
whose scenes are D65-lit (a tungsten-lit scene is redder, which would move N itself; that needs
the study run again under that light). Two significant figures, as the study's tables.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path

from splitcam.evaluation.tables import markdown_table
from splitcam.io import write_text
from splitcam.physics.radiometry import Camera

ROUTERS = [
    "router-best-fullwave",
    "router-best-fullwave-f2",
    "router-zou-fullwave",
    "router-zou-fullwave-f2",
]
REFERENCES = ["rgbw-d5100", "bayer-d5100"]
ILLUMINANTS = {"D65": "D65 daylight", "A": "CIE A tungsten", "LED": "white LED (LED-B3)"}
PITCHES = (0.6, 0.8, 1.0)
METHOD = "net-universal-photon-"


def _sig(x: float) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if math.isinf(x):
        return ">range" if x > 0 else "<range"
    return f"{float(f'{x:.2g}'):g}"


def crossovers(study: Path) -> dict[tuple[str, str], dict]:
    data = json.loads((study / "exposure.json").read_text(encoding="utf-8"))
    out = {}
    for row in data["crossovers"]:
        if row["metric"] != "psnr" or row["scene_set"] != "all":
            continue
        cand, ref = row["candidate"], row["reference"]
        if cand.startswith(METHOD) and ref.startswith(METHOD):
            out[(cand.removeprefix(METHOD), ref.removeprefix(METHOD))] = row
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", nargs="?", default="docs/results/exposure/measured/rn2")
    parser.add_argument("--out", default="docs/results/exposure/lux")
    args = parser.parse_args()
    found = crossovers(Path(args.study))
    cameras = {
        (ill, pitch): Camera(pitch_um=pitch, f_number=2.0, illuminant=ill)
        for ill in ILLUMINANTS
        for pitch in PITCHES
    }
    header = ["router", "against", "N [90 %]"] + [
        f"{ill} {pitch:g} µm" for ill in ILLUMINANTS for pitch in PITCHES
    ]
    rows = []
    for router in ROUTERS:
        for ref in REFERENCES:
            row = found.get((router, ref))
            if row is None or row["crossover"] is None or math.isinf(row["crossover"]):
                continue
            n, low, high = row["crossover"], row["low"], row["high"]
            cells = [router, ref, f"{_sig(n)} [{_sig(low)}, {_sig(high)}]"]
            for key in cameras:
                cam = cameras[key]
                cells.append(f"{_sig(cam.lux(n))} [{_sig(cam.lux(low))}, {_sig(cam.lux(high))}]")
            rows.append(cells)
    link = os.path.relpath(Path(args.study) / "exposure.md", args.out)
    per_lux = {f"{ill} {p:g} µm": cameras[(ill, p)].electrons_per_lux for ill, p in cameras}
    lines = [
        "# The answer in lux: illuminants and pixel pitches",
        "",
        "Each router beats the array below this scene illuminance (lux; 90 % interval over the "
        f"images in brackets), at f/2, 1/30 s, a white scene, a lossless pixel; the crossovers in "
        f"N are those of [`{args.study}`]({link}) (network "
        "`universal-photon` for every sensor, read noise 2 e⁻, 48 images).",
        "",
        *markdown_table(header, rows),
        "",
        "N per lux of each column: "
        + ", ".join(f"{k} {v:.3g}" for k, v in per_lux.items())
        + ". Only the conversion differs between columns: the scenes of the study are lit by "
        "D65 (a scene under tungsten light is redder, which would move N itself). A smaller "
        "pixel collects fewer photons per lux, so the same N needs more light: at 0.6 µm every "
        "figure is 2.8 times the 1 µm one.",
        "",
        f"`python studies/exposure/lux_sweep.py {args.study} --out {args.out}`",
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "README.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
