"""The exposure answer with every sensor's network fine-tuned by one rule, behind the same stack:
what the fine-tunes gain on their validation photos and on the test images, and the crossovers
against the D5100's arrays with them (each network against the reference's network of the same
kind: fine-tuned against fine-tuned, ``universal-photon`` against ``universal-photon``).

    python studies/exposure/fine_tuned_answer.py [--folder DIR] [--out DIR/README.md]

Reads ``DIR/exposure.json`` (a study holding both kinds of rows, ``net-universal-photon-S`` and
``net-S-ft``) and the fine-tunes' logs ``DIR/logs/net-S-ft.jsonl``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from splitcam.evaluation.tables import markdown_table
from splitcam.io import read_json_lines, write_text

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ROOT / "docs" / "results" / "exposure" / "answer" / "rn2-fine-tuned"
REFERENCES = ("rgbw-d5100", "bayer-d5100")
#: The sensors fine-tuned (names or files; the study's patterns).
K = "docs/results/fullwave/kernels-793"
SENSORS = (
    "rgbw-d5100",
    "bayer-d5100",
    "router-best-fullwave-f2",
    "router-best-n30-fullwave-f2",
    "router-best-n300-fullwave-f2",
    f"{K}/best-f2-computed.json",
    f"{K}/zou-f2-computed.json",
)
#: A fine-tune pays where its validation PSNR rose by at least this (dB), as in
#: ``measured/fine-tuned/``.
MIN_GAIN = 0.1

HEADER = """# The exposure answer with every sensor's network fine-tuned behind the stack

The answer's setting (every pixel behind silicon and the D5100's IR cut, routers under an f/2
cone, read noise 2 e⁻, full well 6000 e⁻, Kodak24 + McMaster + six held-out training photos at
192 px) with each sensor's network fine-tuned from `universal-photon` by one rule: 720 steps,
batch 8 of 64x64 patches, photons 1 to 10⁴, on the sensor behind the same stack and full well
(`splitcam train --stack`), one thread each (10-14 minutes a run on a 2-core AMD EPYC, two
runs side by side). Each run's network is the one of its best validation step, so a run that
never gained on the held-out photos keeps `universal-photon`'s weights. A fine-tuned network is
compared only with the reference's fine-tuned network: both sides of every crossover went
through the same rule.

```bash
export SPLITCAM_DATA=DIR
for S in {specs}; do
    splitcam train --pattern $S --init-from universal-photon --noise photon --photons 1 10000 \\
        --val-photons 3 300 --domain linear --data $SPLITCAM_DATA/train --threads 1 --steps 720 \\
        --val-every 240 --full-well 6000 --stack silicon,ir-cut \\
        --out runs/ftstack/net-$(basename ${{S%.*}})-ft
done
PATTERNS={specs_csv} OUT=docs/results/exposure/answer/rn2-fine-tuned \\
    bash studies/exposure/answer.sh --checkpoint runs/ftstack/net-NAME-ft ...   # one per sensor
python studies/exposure/fine_tuned_answer.py
```

Full tables and chart: [exposure.md](exposure.md); the runs' logs: [`logs/`](logs/)."""


def validation(log: Path) -> tuple[float, float]:
    """Validation PSNR (mean over the validated exposures) at the first and the last step."""
    rows, _ = read_json_lines(log)
    vals = [r["val_psnr"] for _, _, r in rows if "val_psnr" in r]
    return vals[0], vals[-1]


def crossover_text(crossovers: list[dict], candidate: str, reference: str) -> str:
    """The PSNR crossover of ``candidate`` against ``reference`` over every image, as the study
    wrote it (with its interval)."""
    for c in crossovers:
        if (c["candidate"], c["reference"], c["metric"], c["scene_set"]) == (
            candidate,
            reference,
            "psnr",
            "all",
        ):
            return c["text"]
    return "—"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--folder", type=Path, default=FOLDER)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    study = json.loads((args.folder / "exposure.json").read_text(encoding="utf-8"))
    results, crossovers = study["results"], study["crossovers"]
    sensors = [
        k[len("net-") : -len("-ft")] for k in results if k.startswith("net-") and k.endswith("-ft")
    ]
    sensors = [r for r in REFERENCES if r in sensors] + [s for s in sensors if s not in REFERENCES]
    gains = {s: validation(args.folder / "logs" / f"net-{s}-ft.jsonl") for s in sensors}
    lines = [HEADER.format(specs=" ".join(SENSORS), specs_csv=",".join(SENSORS))]
    photons = sorted(float(n) for n in results[f"net-{sensors[0]}-ft"])
    shown = [n for n in photons if n in (3.0, 10.0, 30.0, 100.0, 1000.0, 10000.0)]

    def psnr(label: str, n: float) -> float:
        return results[label][f"{n:g}"]["psnr"]

    lines += ["", "## What the fine-tunes gain", ""]
    lines += [
        "Validation: 8 training photos held out of every run, 256-px crops, mean PSNR at N = 3 "
        f"and 300 (a fine-tune pays where it rises by {MIN_GAIN} dB or more). Test: PSNR of the "
        "fine-tuned network minus `universal-photon`'s on the study's images.",
        "",
    ]
    lines += markdown_table(
        ["sensor", "validation: start → end", "pays", *(f"test, N={n:g}" for n in shown)],
        (
            [
                s,
                f"{gains[s][0]:.2f} → {gains[s][1]:.2f} ({gains[s][1] - gains[s][0]:+.2f})",
                "yes" if gains[s][1] - gains[s][0] >= MIN_GAIN else "no",
                *(
                    f"{psnr(f'net-{s}-ft', n) - psnr(f'net-universal-photon-{s}', n):+.2f}"
                    for n in shown
                ),
            ]
            for s in sensors
        ),
    )
    lines += ["", "## The crossovers: the exposure below which the router's image wins, PSNR", ""]
    lines += [
        "With the 90 % interval over the images (the study's bootstrap).",
        "",
    ]
    head = ["router"]
    for ref in REFERENCES:
        head += [f"vs {ref}, universal-photon", f"vs {ref}, fine-tuned (both)"]
    rows = []
    for s in (s for s in sensors if s not in REFERENCES):
        row = [s]
        for ref in REFERENCES:
            row.append(
                crossover_text(
                    crossovers, f"net-universal-photon-{s}", f"net-universal-photon-{ref}"
                )
            )
            row.append(crossover_text(crossovers, f"net-{s}-ft", f"net-{ref}-ft"))
        rows.append(row)
    rows.append(
        [
            "rgbw-d5100 (against bayer-d5100)",
            "",
            "",
            crossover_text(
                crossovers, "net-universal-photon-rgbw-d5100", "net-universal-photon-bayer-d5100"
            ),
            crossover_text(crossovers, "net-rgbw-d5100-ft", "net-bayer-d5100-ft"),
        ]
    )
    lines += markdown_table(head, rows)
    text = "\n".join(lines) + "\n"
    print(text)
    write_text(args.out or args.folder / "README.md", text)


if __name__ == "__main__":
    main()
