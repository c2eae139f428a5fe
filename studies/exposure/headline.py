"""The answer at a glance: PSNR of each full-wave router minus each measured filter array, against
scene illuminance, with the 90 % band over the images and each crossover with its interval.

    python studies/exposure/headline.py [STUDY_FOLDER] [--out docs/results/exposure/headline.png]
        [--routers NAME[=LABEL],...] [--where "..."] [--stack "..."]
        [--pitch 1 --f-number 2 --exposure-time 0.0333]

STUDY_FOLDER holds ``exposure.json`` of ``splitcam study exposure`` run with per-image scores
(default ``docs/results/exposure/answer/rn2``). Every sensor is reconstructed by the same
network for any pattern (``universal-photon``): no sensor's network is fine-tuned. Exposures
are converted to lux by the study's own camera (its pitch, lens, time and the light its scenes
are lit by), or by :class:`splitcam.physics.radiometry.Camera` with the pitch, f-number and
time given here under the study's light.
"""

from __future__ import annotations

import argparse
import copy
import json
from pathlib import Path

from splitcam.evaluation.exposure import difference_curves
from splitcam.physics.radiometry import Camera
from splitcam.viz.charts import difference_chart

ROOT = Path(__file__).resolve().parents[2]
NET = "net-universal-photon-"
#: The answer's candidates (``study label=legend label``): both routers behind an f/2 lens at the
#: centre of the field with the kernels computed from their fields, the fabricable design made
#: for N = 30 (docs/results/fullwave/) the same way, and both routers at the corner (chief ray 25
#: degrees; six wavelengths, the nearest-copy rule).
ROUTERS = (
    "best-f2-computed=leaderboard design, centre",
    "zou-f2-computed=Zou, centre",
    "best-n30-fab-f2-computed=designed for N = 30 (80 nm rule), centre",
    "best-f2-corner-6wl=leaderboard design, corner (25°)",
    "zou-f2-corner-6wl=Zou, corner (25°)",
)
ARRAYS = ("rgbw-d5100", "bayer-d5100")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "study", nargs="?", type=Path, default=ROOT / "docs/results/exposure/answer/rn2"
    )
    parser.add_argument("--out", type=Path, default=ROOT / "docs/results/exposure/headline.png")
    parser.add_argument("--pitch", type=float, help="µm (default: the study's camera)")
    parser.add_argument("--f-number", type=float, help="(default: the study's camera)")
    parser.add_argument("--exposure-time", type=float, help="s (default: the study's camera)")
    parser.add_argument("--read-noise", type=float, default=2.0, help="the study's, for the title")
    parser.add_argument(
        "--routers",
        type=lambda text: [r for r in text.split(",") if r],
        default=list(ROUTERS),
        help="the candidates drawn, as the study labels them, each optionally =LEGEND LABEL "
        "(default: the answer's)",
    )
    parser.add_argument("--where", default="f/2 lens, centre and corner of the field")
    parser.add_argument(
        "--stack",
        default="every pixel behind silicon (3 µm) and the D5100's IR cut, full well 6000 e-",
        help="the study's optical stack in words, for the title",
    )
    parser.add_argument("--legend", default="lower left", help="matplotlib's loc")
    args = parser.parse_args()
    data = json.loads((args.study / "exposure.json").read_text())
    per_lux, settings = _camera(args, data["camera"])
    results = {label: {float(n): v for n, v in r.items()} for label, r in data["results"].items()}
    names = dict(spec.split("=", 1) if "=" in spec else (spec, spec) for spec in args.routers)
    pairs = [(NET + r, NET + a) for a in ARRAYS for r in names]
    curves = difference_curves(results, pairs)
    lux = []
    for c in curves:
        c = copy.deepcopy(c)
        c["candidate"] = names[c["candidate"].removeprefix(NET)]
        c["reference"] = c["reference"].removeprefix(NET)
        c["photons"] = [n / per_lux for n in c["photons"]]
        cross = c["crossover"]
        for key in ("crossover", "low", "high"):
            v = cross[key]
            if v is not None and v not in (0.0, float("inf")):
                cross[key] = v / per_lux
        lux.append(c)
        print(
            f"{c['candidate']} against {c['reference']}: crossover {cross['crossover']} lux, "
            f"90 % interval [{cross['low']}, {cross['high']}]"
        )
    difference_chart(
        lux,
        args.out,
        title=f"Full-wave routers against measured filter arrays, one network for every sensor "
        f"(universal-photon), read noise {args.read_noise:g} e-, {args.where}\n"
        f"{settings}{chr(10) + args.stack if args.stack else ''}; bands and bars: "
        "90 % intervals over the images",
        xlabel="scene illuminance (lux)",
        unit="lux",
        legend=args.legend,
    )
    print(f"wrote {args.out}")


def _camera(args: argparse.Namespace, recorded: dict) -> tuple[float, str]:
    """N per lux and the camera in words: the study's own, or one with the pitch, f-number and
    time given (each defaulting to 1 µm, f/2, 1/30 s) under the study's light."""
    if args.pitch is None and args.f_number is None and args.exposure_time is None:
        return recorded["electrons_per_lux"], recorded["settings"]
    camera = Camera(
        args.pitch or 1.0,
        args.f_number or 2.0,
        args.exposure_time or 1 / 30,
        recorded.get("illuminant", "D65"),
        white=recorded.get("white", 1.0),
    )
    return camera.electrons_per_lux, camera.describe()


if __name__ == "__main__":
    main()
