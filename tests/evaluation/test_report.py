"""Reports (splitcam.evaluation.report): results beside the paper, Table 1 checks, the sections of
``reproduce.md``, learned patterns drawn apart."""

from __future__ import annotations

import json

import torch
from conftest import Spy, random_images

from splitcam.cli import main
from splitcam.evaluation import evaluate


def test_report_puts_results_beside_the_paper(tmp_path, capsys):
    from splitcam.evaluation.report import make_report
    from splitcam.physics.sensor import LearnableSplitterSensor

    learned = Spy("learned")
    learned.pattern = LearnableSplitterSensor("A", init="random").to_pattern("A-opt")
    images = random_images(24)
    evaluate(
        [Spy("plain-D"), learned, Spy("bayerish", pattern="bayer")],
        [("kodak24", images), ("mcmaster", images[:18])],  # the paper's test sets' sizes
        [10, 0],
        tmp_path / "res",
        progress=False,
    )
    # The same methods on another set: the paper's numbers are not set beside these.
    evaluate([Spy("plain-D")], [("set", images[:2])], [0], tmp_path / "other", progress=False)
    other = make_report([tmp_path / "other"], tmp_path / "rep-other").read_text()
    assert "(40.35" not in other
    report = make_report([tmp_path / "res"], tmp_path / "rep").read_text()
    assert report.index("σ=0") < report.index("σ=10")  # levels in order
    summary = json.loads((tmp_path / "res/summary.json").read_text())
    ours = summary["plain-D"]["all"]["0"]["psnr"]
    assert f"{ours:.2f} / " in report and f"(40.35, {ours - 40.35:+.2f})" in report
    assert "(40.33, " in report  # a pattern learned from A is compared with "A optimised"
    assert (tmp_path / "rep/patterns/A-opt.png").is_file()
    assert (tmp_path / "rep/patterns/D.png").is_file()
    assert (tmp_path / "rep/sigma_curves.png").stat().st_size > 10_000
    assert main(["report", str(tmp_path / "nothing"), "--out", str(tmp_path / "r2")]) == 1
    assert "no summary.json" in capsys.readouterr().err


def _table1_summary(psnr: dict[str, list[float]], sigmas: list[str]) -> dict:
    return {
        k: {"all": {s: {"psnr": v} for s, v in zip(sigmas, vals, strict=True)}}
        for k, vals in psnr.items()
    }


def test_table1_checks_rank_b_and_c_among_the_patterns_evaluated():
    """'B and C last' ranks among the patterns there are (E may not be trained yet), and fails
    when either is ahead of another pattern at one sigma, or when E is there and behind them."""
    from splitcam.evaluation.report import checks

    sigmas = ["0", "20"]
    rows = {k: k for k in "ABCDE"}

    def verdicts(psnr):
        return {stmt: ok for stmt, ok, _ in checks(_table1_summary(psnr, sigmas), rows, sigmas)}

    four = {"A": [40, 33], "B": [34, 32], "C": [33, 31.5], "D": [41, 34]}
    got = verdicts(four)
    last4 = "B and C last at every σ (among A, B, C, D)"
    assert got[last4] is True
    assert got["B and C nearly flat in σ (drop smaller than A's and D's)"] is True  # 2, 1.5 < 7
    assert verdicts({**four, "B": [34, 33.5]})[last4] is False
    assert (
        verdicts({**four, "C": [39, 31.5]})[
            "B and C nearly flat in σ (drop smaller than A's and D's)"
        ]
        is False
    )  # C drops 7.5 > 7
    assert verdicts({**four, "E": [35, 32.5]})["B and C last at every σ"] is True
    assert verdicts({**four, "E": [33.5, 31]})["B and C last at every σ"] is False
    assert not any("B and C" in s for s in verdicts({"A": [40, 33], "D": [41, 34]}))


def test_paper_tables_writes_every_section_beside_the_paper(tmp_path):
    """reproduce.md from a summary with every row, LMMSE baselines, Malvar, learned patterns and
    zooms: the cells, gains and ranks are the hand-computed ones, the sections in order."""
    from splitcam.evaluation.report import paper_tables
    from splitcam.physics.sensor import LearnableSplitterSensor

    # PSNR, SSIM and CIEDE2000 at sigma 0 and 20.
    ours = {
        "A": [(39.0, 0.97, 1.0), (33.0, 0.90, 2.0)],
        "B": [(32.0, 0.91, 1.0), (31.0, 0.88, 2.0)],
        "C": [(31.0, 0.90, 1.0), (30.5, 0.87, 2.0)],
        "D": [(40.0, 0.975, 1.0), (33.5, 0.91, 2.0)],
        "E": [(35.0, 0.96, 1.0), (32.0, 0.90, 2.0)],
        "bayer": [(38.0, 0.96, 1.5), (32.5, 0.89, 3.0)],
        "A optimised": [(39.5, 0.972, 1.0), (33.6, 0.905, 2.0)],
        "D optimised": [(40.5, 0.978, 0.9), (34.0, 0.915, 1.8)],
        "D optimised (random init.)": [(40.4, 0.977, 0.95), (34.1, 0.916, 1.85)],
        "lmmse-A": [(36.0, 0.95, 2.0), (31.0, 0.85, 4.0)],
        "lmmse-D": [(37.0, 0.955, 2.0), (31.5, 0.86, 4.0)],
        "bayer+malvar2004": [(35.0, 0.94, 2.5), (30.0, 0.80, 5.0)],
    }
    summary = {
        name: {
            "pattern": "D",
            "domain": "srgb",
            "all": {
                s: {"psnr": p, "ssim": q, "ciede2000": c, "n_images": 42, "n_infinite": 0}
                for s, (p, q, c) in zip(["0", "20"], values, strict=True)
            },
        }
        for name, values in ours.items()
    }
    # Each set's own means for two rows: Kodak24 one dB above the pooled mean, McMaster
    # 24/18 dB below, so that the pool of 24 + 18 images keeps its mean.
    for name in ("D", "lmmse-D"):
        pooled = summary[name]["all"]
        summary[name]["kodak24"] = {s: {**v, "psnr": v["psnr"] + 1} for s, v in pooled.items()}
        summary[name]["mcmaster"] = {
            s: {**v, "psnr": v["psnr"] - 24 / 18} for s, v in pooled.items()
        }
    rows = {r: r for r in ours if not r.startswith(("lmmse", "bayer+"))}
    learned = {"A optimised": LearnableSplitterSensor("A").to_pattern("A-opt")}
    report = paper_tables(
        summary,
        rows,
        tmp_path,
        budgets={r: f"{r} budget" for r in rows if r != "E"},
        learned=learned,
        zooms=["zoom/x.png"],
        baselines={"A": "lmmse-A", "D": "lmmse-D", "B": "not evaluated"},
    ).read_text()
    headings = [line for line in report.splitlines() if line.startswith("## ")]
    assert headings == [
        "## Budget of each model",
        "## Table 1: every pattern, fixed",
        "## Table 2: A against A optimised",
        "## Table 3: D against D optimised",
        "## Fig. 9: bayer, D, D optimised and D optimised from random",
        "## The paper's conclusions at our budget",
        "## Each test set apart",
        "## Without training: the LMMSE of every pattern",
        "## Learned patterns (Fig. 6)",
        "## Zoomed crops (Figs. 4, 5, 7, 8)",
    ]
    lines = report.splitlines()
    expected = [
        "Ours: mean over 42 images; cells are",
        "- **A** (`A`): A budget",
        "- **E** (`E`): unknown",
        "| pattern | σ=0 | σ=20 |",
        "| A | 39.00 / 0.9700 (40.02, -1.02) | 33.00 / 0.9000 (33.47, -0.47) |",
        "| bayer | 38.00 / 0.9600 | 32.50 / 0.8900 |",
        "| A | 2 (2) | 2 (2) |",
        "| C | 5 (5) | 5 (5) |",
        "| A optimised | 39.50 / 0.9720 (40.33, -0.83) | 33.60 / 0.9050 (34.25, -0.65) |",
        "| gain (paper) | +0.50 (+0.31) | +0.60 (+0.78) |",  # Table 2
        "| gain (paper) | +0.50 (+0.68) | +0.50 (+0.32) |",  # Table 3
        "| pattern | CIEDE2000 σ=0 | CIEDE2000 σ=20 |",
        "| bayer | 1.500 | 3.000 |",
        "![Fig. 9](fig9_sigma_curves.png)",
        "- holds: D ahead of A at every σ (D − A: +1.00, +0.50 dB)",
        "- holds: A optimised ahead of A at every σ (+0.50, +0.60 dB)",
        "| method | σ=0 | σ=20 |",
        "| D | 41.00 / 38.67 (2.33) | 34.50 / 32.17 (2.33) |",
        "| D, LMMSE | 38.00 / 35.67 (2.33) | 32.50 / 30.17 (2.33) |",
        "| A | 36.00 / 0.9500 (net +3.00) | 31.00 / 0.8500 (net +2.00) |",
        "| D | 37.00 / 0.9550 (net +3.00) | 31.50 / 0.8600 (net +2.00) |",
        "| bayer, Malvar 2004 | 35.00 / 0.9400 | 30.00 / 0.8000 |",
        "Ranks by LMMSE PSNR among A–E: σ=0: D A; σ=20: D A",
        "- LMMSE, holds: D ahead of A at every σ (D − A: +1.00, +0.50 dB)",
        "![A optimised](patterns/A_optimised.png)",
        "![zoom](zoom/x.png)",
    ]
    positions = []
    for want in expected:
        found = [i for i, line in enumerate(lines) if line.startswith(want)]
        assert found, want
        positions.append(found[0] if "gain" not in want else found[-1 if "0.68" in want else 0])
    assert positions == sorted(positions)
    assert not any(line.startswith("| B | ") and "net" in line for line in lines)
    assert (tmp_path / "patterns/A_optimised.png").is_file()
    assert (tmp_path / "fig9_sigma_curves.png").is_file()


def test_report_draws_two_learned_patterns_of_one_name_apart(tmp_path):
    from splitcam.evaluation import evaluate
    from splitcam.evaluation.report import make_report
    from splitcam.physics.sensor import LearnableSplitterSensor

    class Fixed:
        def __init__(self, name, pattern):
            self.name, self.pattern = name, pattern

        def reconstruct(self, raw, sigma):
            return raw.expand(-1, 3, -1, -1) / 4

    gen = torch.Generator().manual_seed(0)
    images = [("a", torch.rand(3, 16, 16, generator=gen))]
    for i, folder in enumerate(("one", "two")):
        g = torch.Generator().manual_seed(i)
        learned = LearnableSplitterSensor("D", init="random", generator=g).to_pattern()
        evaluate([Fixed("net", learned)], [("s", images)], [0], tmp_path / folder, progress=False)
    report = make_report([tmp_path / "one", tmp_path / "two"], tmp_path / "rep").read_text()
    assert "patterns/D-learned.png" in report and "patterns/D-learned-2.png" in report
    assert (tmp_path / "rep" / "patterns" / "D-learned-2.png").is_file()
