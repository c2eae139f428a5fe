"""Write docs/models.md, the model zoo: one row per shipped model.

    python docs/models.py

Pattern, noise model and light domain, and budget come from each model's JSON header
(:func:`splitcam.training.models.model_summary`); the scores on Kodak24 + McMaster (the mean
over the 42 whole images at σ 0 and 15, PSNR dB) from the committed evaluation of
``splitcam reproduce`` (docs/results/reproduce/evaluation/table.md), beside the paper's Table 1-3
numbers (:data:`splitcam.evaluation.report.PAPER`); the recipe that trains each again from
experiments/recipes/.
"""

from __future__ import annotations

import re
from pathlib import Path

from splitcam.evaluation.report import PAPER, PAPER_DATASETS, PAPER_MODELS
from splitcam.recon.loading import load_model, model_names
from splitcam.training.models import model_summary
from splitcam.training.recipe import read_recipe

DOCS = Path(__file__).resolve().parent
TABLE = DOCS / "results" / "reproduce" / "evaluation" / "table.md"

#: Where the models not in the paper's tables are scored.
ELSEWHERE = {
    "universal": "held-out photos: [universal](results/universal/heldout.md)",
    "universal-photon": "photons, linear light: "
    "[universal-photon](results/exposure/universal-photon.md)",
}


def scores() -> tuple[dict[str, tuple[float, float]], dict[str, dict[str, float]]]:
    """``{method: (σ 0, σ 15)}``: the 42-image mean PSNR of each ``net-X`` row; and
    ``{method: {set: σ 0}}``, each test set's own mean at σ 0."""
    sums: dict[str, list[float]] = {}
    per_set: dict[str, dict[str, float]] = {}
    section = None
    for line in TABLE.read_text(encoding="utf-8").splitlines():
        heading = re.match(r"### (\w+) \(\d+ images\): PSNR", line)
        if heading:
            section = heading.group(1)
            continue
        if line.startswith("### "):
            section = None
        if section in PAPER_DATASETS and line.startswith("| net-"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            psnr0, psnr15 = (float(cells[i].split(" / ")[0]) for i in (2, 5))
            n = PAPER_DATASETS[section]
            per_set.setdefault(cells[0][len("net-") :], {})[section] = psnr0
            acc = sums.setdefault(cells[0][len("net-") :], [0.0, 0.0, 0])
            acc[0] += n * psnr0
            acc[1] += n * psnr15
            acc[2] += n
    total = sum(PAPER_DATASETS.values())
    return {m: (a / n, b / n) for m, (a, b, n) in sums.items() if n == total}, per_set


def main() -> None:
    ours, per_set = scores()
    paper = {model: PAPER.get(row) for row, model in PAPER_MODELS.items()}
    lines = [
        "# Shipped models",
        "",
        "One row per model that ships with splitcam (`splitcam models` prints the same budget "
        "columns). Budget: the training of every stage, CPU and GPU minutes, steps and batch "
        "(`8/64`: batch 8 on CPUs, 64 on a GPU). Scores: PSNR dB on Kodak24 + McMaster (the "
        "mean over 42 whole images, weighted from the per-set means) at σ 0 / 15, from "
        "`splitcam reproduce` "
        "([table](results/reproduce/evaluation/table.md)), beside the paper's after 10⁶ GPU "
        "steps ([model.md](model.md) section 8). `splitcam train --recipe MODEL --data DIR` "
        "trains a model again end to end, stage by stage (`experiments/recipes/`). The last "
        "column is each set's own mean at σ 0 and Kodak24 minus McMaster: how much a network "
        "loses on saturated colour (demosaicnet, a GPU-trained Bayer network, on the same whole "
        "images: 41.84 / 39.14, 2.70; [colour](results/colour/README.md)).",
        "",
        "| model | pattern | trained on | steps | batch | training | stages | σ 0 / 15 | paper "
        "| σ 0 Kodak24 / McMaster (drop) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in model_names():
        row = model_summary(name, load_model(name).meta)
        stages = len(read_recipe(name).stages)
        if name in ours:
            score = "{:.2f} / {:.2f}".format(*ours[name])
        else:
            score = ELSEWHERE.get(
                name, "photons, linear light: [exposure](results/exposure/README.md)"
            )
        ref = paper.get(name)
        ref_text = f"{ref[0][0]:.2f} / {ref[3][0]:.2f}" if ref else "–"
        sets = per_set.get(name, {})
        drop = (
            f"{sets['kodak24']:.2f} / {sets['mcmaster']:.2f} "
            f"({sets['kodak24'] - sets['mcmaster']:.2f})"
            if {"kodak24", "mcmaster"} <= set(sets)
            else "–"
        )
        lines.append(
            f"| {name} | {row['pattern']} | {row['trained on']} | {row['steps']} | {row['batch']} "
            f"| {row['train time']} | {stages} | {score} | {ref_text} | {drop} |"
        )
    lines += [
        "",
        "Regenerate with `python docs/models.py` after a model ships.",
    ]
    (DOCS / "models.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("wrote", DOCS / "models.md")


if __name__ == "__main__":
    main()
