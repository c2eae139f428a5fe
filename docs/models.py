"""Write docs/models.md, the model zoo: one row per shipped model.

    python docs/models.py                   # the page
    python docs/models.py --heldout DIR     # first score the models on DIR's held-out photos

Pattern, noise model and light domain, and budget come from each model's JSON header
(:func:`splitcam.training.models.model_summary`); the scores on Kodak24 + McMaster (the mean
over the 42 whole images at σ 0 and 15, PSNR dB) from the committed evaluation of
``splitcam reproduce`` (docs/results/reproduce/evaluation/table.md), beside the paper's Table 1-3
numbers (:data:`splitcam.evaluation.report.PAPER`); each model's mean on the held-out training
photos the gate scores (the run's validation photos and the last 12 of the folder, at half
size, at the model's cleanest and noisiest validation level;
:func:`splitcam.training.gate.held_out_score`),
kept in docs/results/heldout/scores.json; the number of stages of the recipe that
trains each again (its own header; splitcam.training.recipe). A score measured on other weights
than the model ships now (its fingerprint in the evaluation's ``evaluation.json`` differs) is
marked as such, so the page never passes an older model's score for the current one.
``tests/docs/test_models_page.py`` checks that the page is what this script writes.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from splitcam.evaluation.protocol import method_fingerprint
from splitcam.evaluation.report import PAPER, PAPER_DATASETS, PAPER_MODELS
from splitcam.io.domains import LINEAR
from splitcam.recon.loading import load_model, model_names
from splitcam.recon.registry import trained_domain
from splitcam.training.models import model_summary
from splitcam.training.recipe import read_recipe

DOCS = Path(__file__).resolve().parent
EVALUATION = DOCS / "results" / "reproduce" / "evaluation"
HELDOUT = DOCS / "results" / "heldout" / "scores.json"
TABLE = EVALUATION / "table.md"

#: Where the models not in the paper's tables are scored.
ELSEWHERE = {
    "universal": "held-out photos: [universal](results/universal/heldout.md)",
    "universal-photon": "photons, linear light: "
    "[universal-photon](results/exposure/universal-photon.md)",
}


def scores() -> tuple[dict[str, tuple[float, float]], dict[str, dict[str, float]]]:
    """``{method: (σ 0, σ 15)}``: the 42-image mean PSNR of each ``net-X`` row; and
    ``{method: {set: σ 0}}``, each test set's own mean at σ 0, with ``"drop"`` the table's own
    Kodak24-minus-McMaster at σ 0 (from the unrounded means, so it matches that table rather
    than the difference of two rounded cells)."""
    sums: dict[str, list[float]] = {}
    per_set: dict[str, dict[str, float]] = {}
    section = None
    for line in TABLE.read_text(encoding="utf-8").splitlines():
        heading = re.match(r"### (\w+) \(\d+ images\): PSNR", line)
        if heading:
            section = heading.group(1)
            continue
        if line.startswith("### "):
            section = "drop" if line.startswith("### kodak24 minus mcmaster") else None
            continue
        if section == "drop" and line.startswith("| net-"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            per_set.setdefault(cells[0][len("net-") :], {})["drop"] = float(cells[1])
            continue
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


def scored_other_weights(names: list[str]) -> set[str]:
    """The models among ``names`` whose committed scores were measured on other weights than
    the ones shipped now."""
    from splitcam.recon.registry import build_method

    recorded = json.loads((EVALUATION / "evaluation.json").read_text())
    crop = recorded.get("crop", 0)
    stale = set()
    for name in names:
        now = method_fingerprint(build_method(name, precision="fp32"), crop)
        if recorded["fingerprints"].get(f"net-{name}") != now:
            stale.add(name)
    return stale


def score_heldout(data: Path) -> None:
    """Score every shipped model whose weights have no score yet in :data:`HELDOUT` (kept after
    each model, so an interrupted run continues)."""
    from splitcam.training.gate import held_out_score

    scores = json.loads(HELDOUT.read_text()) if HELDOUT.exists() else {}
    for name in model_names():
        if _current(scores.get(name, {}), load_model(name).meta):
            continue
        scores[name] = held_out_score(name, data)
        HELDOUT.parent.mkdir(parents=True, exist_ok=True)
        HELDOUT.write_text(json.dumps(scores, indent=1, sort_keys=True) + "\n")
        print(name, scores[name]["levels"], [round(v, 2) for v in scores[name]["psnr"]])


def _current(entry: dict, meta: dict) -> bool:
    """Whether a held-out score is of the weights the header ``meta`` names, at the size the
    gate scores photos at now (scores before the size was recorded are of whole photos)."""
    from splitcam.training.gate import SCALE

    return entry.get("sha256") == meta.get("sha256") and entry.get("scale", 1.0) == SCALE


def heldout_cell(name: str, meta: dict, scores: dict) -> str:
    """A model's held-out mean at its cleanest and noisiest level, marked where it was measured
    on other weights than its header ``meta`` names or under the gate's earlier rule."""
    entry = scores.get(name)
    if entry is None:
        return "–"
    cells = " / ".join(f"{v:.2f}" for v in entry["psnr"])
    levels = " / ".join(entry["levels"])
    return f"{cells} ({levels})" + ("" if _current(entry, meta) else " *earlier weights or rule*")


def unscored_cell(meta: dict) -> str:
    """The score cell of a model (header ``meta``) with no row of its own in the evaluation: a
    network of linear light is scored by the exposure study; any other has not been evaluated
    yet (or is being evaluated now), which the cell says rather than passing for a score kept
    elsewhere."""
    if trained_domain(meta.get("config")) == LINEAR:
        return "photons, linear light: [exposure](results/exposure/README.md)"
    return "*not in the evaluation: run `splitcam reproduce`*"


def render() -> str:
    """The page's text."""
    ours, per_set = scores()
    stale = scored_other_weights(sorted(ours))
    heldout = json.loads(HELDOUT.read_text()) if HELDOUT.exists() else {}
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
        "trains a model again end to end, stage by stage, from the stages its own header "
        "records; a model whose weights are a blend of two (`splitcam models blend`; stages: "
        "its runs + its blends, a run two ends share counted once) is made again by training "
        "each end and blending them. The last "
        "column is each set's own mean at σ 0 and Kodak24 minus McMaster: how much a network "
        "loses on saturated colour (demosaicnet, a GPU-trained Bayer network, on the same whole "
        "images: 41.84 / 39.14, 2.70; [colour](results/colour/half-size.md)). Held-out photos: the "
        "mean PSNR on the 20 training photos the gate scores, which no run trains on (at half "
        "size, where their chroma is as fine as their luma, odd sides; `splitcam models gate`), "
        "at the model's cleanest / noisiest validation level (σ, or N photo-electrons in "
        "linear light; `python docs/models.py --heldout DIR` scores them). A score marked "
        "*earlier weights or rule* was measured before the model's last stage shipped or on "
        "whole photos: run `splitcam reproduce` (or `--heldout`) again and this page after it.",
        "",
        "| model | pattern | trained on | steps | batch | training | stages | σ 0 / 15 | paper "
        "| σ 0 Kodak24 / McMaster (drop) | held-out photos |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in model_names():
        meta = load_model(name).meta
        row = model_summary(name, meta)
        runs, blends = read_recipe(name).count()
        stages = f"{runs} + {blends} blends" if blends else str(runs)
        note = " *earlier weights*" if name in stale else ""
        if name in ours:
            score = "{:.2f} / {:.2f}".format(*ours[name]) + note
        else:
            score = ELSEWHERE.get(name) or unscored_cell(meta)
        ref = paper.get(name)
        ref_text = f"{ref[0][0]:.2f} / {ref[3][0]:.2f}" if ref else "–"
        sets = per_set.get(name, {})
        drop = (
            f"{sets['kodak24']:.2f} / {sets['mcmaster']:.2f} ({sets['drop']:.2f})"
            if {"kodak24", "mcmaster", "drop"} <= set(sets)
            else "–"
        ) + (note if sets else "")
        lines.append(
            f"| {name} | {row['pattern']} | {row['trained on']} | {row['steps']} | {row['batch']} "
            f"| {row['train time']} | {stages} | {score} | {ref_text} | {drop} "
            f"| {heldout_cell(name, meta, heldout)} |"
        )
    lines += [
        "",
        "Regenerate with `python docs/models.py` after a model ships.",
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--heldout", metavar="DIR", help="score on DIR's held-out photos first")
    args = parser.parse_args()
    if args.heldout:
        score_heldout(Path(args.heldout))
    (DOCS / "models.md").write_text(render(), encoding="utf-8")
    print("wrote", DOCS / "models.md")


if __name__ == "__main__":
    main()
