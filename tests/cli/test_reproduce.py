"""``splitcam reproduce``: the paper's tables from shipped models (exported here from a tiny
run)."""

from __future__ import annotations

import json

from splitcam.cli import main
from splitcam.io import weights as io_weights
from splitcam.training.models import export_model


def test_reproduce_writes_the_paper_tables_from_shipped_models(
    trained_run, run_images, tmp_path, monkeypatch, capsys
):
    """The mechanics of `splitcam reproduce` (tables, ranks, checks, Fig. 9, learned patterns),
    on models exported from one tiny run under the paper's names."""
    shipped = tmp_path / "shipped"
    monkeypatch.setattr(io_weights, "MODELS_DIR", shipped)
    for name in ("A", "B", "C", "D", "E", "bayer", "D-opt"):
        export_model(trained_run, shipped / name, name=name)
    out = tmp_path / "rep"
    assert (
        main(
            [
                "reproduce",
                "--datasets",
                str(run_images),
                "--max-images",
                "2",
                "--sigmas",
                "0",
                "10",
                "--out",
                str(out),
                "--no-baselines",
                "--quiet",
            ]
        )
        == 0
    )
    text = (out / "reproduce.md").read_text()
    assert "## Table 1" in text and "## Table 3: D against D optimised" in text
    assert "| D | " in text and "(40.35, " in text  # the paper's D at sigma 0 beside ours
    assert "Ranks by PSNR" in text and "## Table 2" not in text  # no A-opt shipped
    assert "D optimised ahead of D at every σ" in text
    assert (out / "fig9_sigma_curves.png").is_file()
    assert "4 steps of batch 4" in text
    summary = json.loads((out / "evaluation" / "summary.json").read_text())
    assert set(summary) == {f"net-{n}" for n in ("A", "B", "C", "D", "E", "bayer", "D-opt")}


def test_reproduce_tables_the_lmmse_of_every_pattern_beside_the_networks(
    trained_run, run_images, tmp_path, monkeypatch
):
    """With baselines, `reproduce` tables the training-free LMMSE of all six patterns (so patterns
    without a shipped network are still compared) and each shipped network's gain over it; the
    gain printed equals the difference of the two methods' means in summary.json."""
    shipped = tmp_path / "shipped"
    monkeypatch.setattr(io_weights, "MODELS_DIR", shipped)
    export_model(trained_run, shipped / "D", name="D")
    out = tmp_path / "rep"
    args = ["reproduce", "--datasets", str(run_images), "--max-images", "2"]
    assert main([*args, "--sigmas", "0", "10", "--out", str(out), "--quiet"]) == 0
    text = (out / "reproduce.md").read_text()
    summary = json.loads((out / "evaluation" / "summary.json").read_text())
    assert {f"lmmse-{p}" for p in ("A", "B", "C", "D", "E", "bayer")} <= set(summary)
    section = text.split("## Without training: the LMMSE of every pattern")[1]
    lines = [line for line in section.splitlines() if line.startswith("| ")]
    rows = {line.split(" | ")[0][2:]: line for line in lines}
    assert {"A", "B", "C", "D", "E", "bayer", "bayer, Malvar 2004"} <= set(rows)
    for s in ("0", "10"):
        gain = summary["net-D"]["all"][s]["psnr"] - summary["lmmse-D"]["all"][s]["psnr"]
        assert f"{summary['lmmse-D']['all'][s]['psnr']:.2f} / " in rows["D"]
        assert f"(net {gain:+.2f})" in rows["D"]
    assert "(net " not in rows["A"]  # no network for A shipped here
    assert "LMMSE, holds: D ahead of A" in section or "LMMSE, **does not hold**: D ahead" in section
    lmmse = {p: summary[f"lmmse-{p}"]["all"] for p in ("A", "D")}
    d_ahead = all(lmmse["D"][s]["psnr"] > lmmse["A"][s]["psnr"] for s in ("0", "10"))
    verdict = "holds" if d_ahead else "**does not hold**"
    assert f"- LMMSE, {verdict}: D ahead of A at every σ" in section
    assert "Ranks by LMMSE PSNR among A–E: σ=0: " in section
