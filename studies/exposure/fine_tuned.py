"""The exposure study with each sensor's network fine-tuned where that pays: what a 10-minute
fine-tune of ``universal-photon`` gains on each sensor, and the crossovers redone with it.

    python studies/exposure/fine_tuned.py [--read-noise 2 5] [--out FILE.md]

Reads two exposure studies per read noise, both in ``docs/results/exposure/measured/``:
``rnX/`` (``universal-photon`` on every sensor, rows ``net-universal-photon-S``) and
``fine-tuned/rnX/`` (the fine-tuned runs, rows ``net-S-ft``). Which sensors are fine-tuned was
decided before either was run, on the runs' validation photos (held out of training, never a
test image): a fine-tune counts where its validation PSNR rose by at least ``--min-gain`` dB.
Each router's best network is then compared with each reference array's (the fine-tuned one
where that paid, else ``universal-photon``), PSNR, the exposure below which the router wins
(:func:`splitcam.evaluation.exposure.describe_crossover`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from splitcam.evaluation.exposure import describe_crossover
from splitcam.evaluation.tables import markdown_table
from splitcam.io import read_json_lines, write_text

ROOT = Path(__file__).resolve().parents[2]
MEASURED = ROOT / "docs" / "results" / "exposure" / "measured"
SENSORS = ["rgbw", "rgbw-d5100", "router-zou-fullwave", "router-best-fullwave"]
REFERENCES = ["rgbw", "rgbw-d5100"]
#: The fine-tunes' logs (``metrics.jsonl`` of each run), kept beside the results.
LOGS = MEASURED / "fine-tuned" / "logs"


HEADER = """# The exposure study with networks fine-tuned where that pays

Each sensor's network fine-tuned from `universal-photon` for 720 steps (the 10-minute budget of
a 2-core AMD EPYC, one thread; batch 8 of 64x64 patches, photons 1 to 10⁴, read noise 2 e⁻,
linear light), two runs side by side:

```bash
splitcam train --pattern S --init-from universal-photon --noise photon --photons 1 10000 \\
    --val-photons 3 300 --domain linear --data DIR --threads 1 --steps 720 \\
    --val-every 240 --out runs/expft/net-S-ft
splitcam study exposure --datasets kodak24,mcmaster --crop 192 \\
    --patterns rgbw,rgbw-d5100,router-zou-fullwave,router-best-fullwave \\
    --photons 1 2.15 4.64 10 21.5 46.4 100 215 464 1000 2150 4640 10000 --read-noise 2 \\
    --checkpoint runs/expft/net-S-ft ... --reference rgbw,rgbw-d5100 \\
    --out docs/results/exposure/measured/fine-tuned/rn2      # and rn5 with --read-noise 5
python studies/exposure/fine_tuned.py \\
    --out docs/results/exposure/measured/fine-tuned/README.md
```

The runs' validation logs are in [`logs/`](logs/). A fine-tune pays where its validation PSNR
(8 training photos held out of training, 256-px crops, N = 3 and 300) rose by at least
{min_gain:g} dB: {gains}. Full tables: [read noise 2](rn2/exposure.md), [5](rn5/exposure.md)."""


def validation_gain(sensor: str) -> float:
    """Validation PSNR (mean over the validated exposures) at the last step minus the first."""
    rows, _ = read_json_lines(LOGS / f"net-{sensor}-ft.jsonl")
    vals = [r["val_psnr"] for _, _, r in rows if "val_psnr" in r]
    return vals[-1] - vals[0]


def curves(path: Path) -> dict[str, dict[float, float]]:
    results = json.loads(path.read_text(encoding="utf-8"))["results"]
    return {k: {float(n): v["psnr"] for n, v in r.items()} for k, r in results.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--read-noise", type=int, nargs="+", default=[2, 5])
    parser.add_argument("--min-gain", type=float, default=0.1)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    pays = {s: validation_gain(s) >= args.min_gain for s in SENSORS}
    gains = ", ".join(f"{s} {validation_gain(s):+.2f} dB" for s in SENSORS)
    lines = [HEADER.format(min_gain=args.min_gain, gains=gains)]
    for rn in args.read_noise:
        plain = curves(MEASURED / f"rn{rn}" / "exposure.json")
        tuned = curves(MEASURED / "fine-tuned" / f"rn{rn}" / "exposure.json")

        best = {
            s: tuned[f"net-{s}-ft"] if pays[s] else plain[f"net-universal-photon-{s}"]
            for s in SENSORS
        }
        photons = sorted(plain["rgbw"])
        shown = [n for n in photons if n in (10, 100, 1000, 10000)]
        lines += [
            "",
            f"Read noise {rn} e⁻: test PSNR of the fine-tuned network minus `universal-photon`",
            "",
        ]
        lines += markdown_table(
            ["sensor", "pays (validation)", *(f"N={n:g}" for n in shown)],
            (
                [
                    s,
                    "yes" if pays[s] else "no",
                    *(
                        f"{tuned[f'net-{s}-ft'][n] - plain[f'net-universal-photon-{s}'][n]:+.2f}"
                        for n in shown
                    ),
                ]
                for s in SENSORS
            ),
        )
        lines += ["", f"Read noise {rn} e⁻: the exposure below which the router wins, PSNR", ""]
        head = ["router"]
        for ref in REFERENCES:
            head += [f"vs {ref}, universal-photon", f"vs {ref}, fine-tuned where it pays"]
        rows = []
        for router in (s for s in SENSORS if s not in REFERENCES):
            row = [router]
            for ref in REFERENCES:
                universal = [plain[f"net-universal-photon-{s}"] for s in (router, ref)]
                row.append(describe_crossover(*universal))
                row.append(describe_crossover(best[router], best[ref]))
            rows.append(row)
        lines += markdown_table(head, rows)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        write_text(args.out, text)


if __name__ == "__main__":
    main()
