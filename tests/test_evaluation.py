"""The evaluation protocol: same noise for every method, reproducible numbers, result files."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import torch
from PIL import Image

from splitcam import patterns
from splitcam.cli import main
from splitcam.evaluation import evaluate, summarise
from splitcam.evaluation.metrics import psnr
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.registry import build_method
from splitcam.training import TrainConfig, train
from splitcam.viz.zoom import detail_region, zoom_figure


class Spy:
    """Records the raw image it is given and returns a fixed guess."""

    def __init__(self, name: str, pattern: str = "D") -> None:
        self.name = name
        self.pattern = patterns.get(pattern)
        self.seen: list[torch.Tensor] = []

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        self.seen.append(raw.clone())
        return raw.expand(-1, 3, -1, -1) / 4


class Oracle:
    """Knows the answer: PSNR is infinite."""

    def __init__(self, images) -> None:
        self.name = "oracle"
        self.pattern = patterns.get("A")
        self._answers = iter([img[None] for _, img in images for _ in range(2)])

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        return next(self._answers)


def _images(n=2, size=(20, 24)):
    gen = torch.Generator().manual_seed(0)
    return [(f"img{i}", torch.rand(3, *size, generator=gen)) for i in range(n)]


def test_every_method_sees_the_same_noise():
    images = _images()
    a, b, c = Spy("a"), Spy("b"), Spy("c", pattern="A")
    evaluate([a, b, c], [("set", images)], [0, 10], progress=False)
    assert len(a.seen) == 4
    for x, y in zip(a.seen, b.seen, strict=True):
        assert torch.equal(x, y)
    # Another pattern: different raw image, identical noise on top of it.
    for k, (_, img) in enumerate(images):
        for j in range(2):
            i = 2 * k + j
            noise_d = a.seen[i] - SplitterSensor("D")(img[None].double()).float()
            noise_a = c.seen[i] - SplitterSensor("A")(img[None].double()).float()
            torch.testing.assert_close(noise_d, noise_a, rtol=0, atol=1e-6)
    assert torch.equal(a.seen[0], SplitterSensor("D")(images[0][1][None].double()).float())
    assert a.seen[1].std() > 0


def test_results_files_and_infinite_psnr(tmp_path):
    images = _images()
    rows = evaluate(
        [Oracle(images), Spy("spy")], [("set", images)], [0, 5], tmp_path, progress=False
    )
    assert all(r.psnr == float("inf") for r in rows if r.method == "oracle")
    summary = json.loads((tmp_path / "summary.json").read_text())
    oracle = summary["oracle"]["all"]["5"]
    assert oracle["n_infinite"] == 2 and oracle["n_images"] == 2 and oracle["ssim"] == 1.0
    with open(tmp_path / "per_image.csv") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == 8
    spy = [r for r in table if r["method"] == "spy" and r["sigma"] == "5"]
    mean = np.mean([float(r["psnr"]) for r in spy])
    assert summary["spy"]["set"]["5"]["psnr"] == pytest.approx(mean, abs=1e-3)
    md = (tmp_path / "table.md").read_text()
    assert "| oracle | A | inf / 1.0000 | inf / 1.0000 |" in md


def test_psnr_in_rows_is_the_metric_of_the_clamped_output():
    images = _images(1)
    spy = Spy("spy")
    rows = evaluate([spy], [("set", images)], [0], progress=False)
    guess = (spy.seen[0].expand(-1, 3, -1, -1) / 4)[0].clamp(0, 1)
    assert rows[0].psnr == pytest.approx(psnr(guess, images[0][1]))
    cropped = evaluate([spy], [("set", images)], [0], crop=3, progress=False)
    assert cropped[0].psnr == pytest.approx(psnr(guess, images[0][1], crop=3))
    assert cropped[0].psnr != pytest.approx(rows[0].psnr)


def test_tiny_checkpoint_evaluates_reproducibly(tmp_path):
    folder = tmp_path / "train"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(4):
        img = np.kron(rng.random((5, 5, 3)), np.ones((8, 8, 1)))
        Image.fromarray((img * 255).astype(np.uint8)).save(folder / f"t{i}.png")
    cfg = TrainConfig().override(
        {
            "data.train": str(folder),
            "data.patch_size": 16,
            "data.batch_size": 2,
            "network.features": 4,
            "network.blocks": 1,
            "optim.steps": 2,
            "run.out": str(tmp_path / "run"),
            "run.threads": 1,
        }
    )
    train(cfg, progress=False)
    images = _images(2, size=(16, 18))
    first = evaluate(
        [build_method(tmp_path / "run")], [("s", images)], [0, 10], tmp_path / "e1", progress=False
    )
    second = evaluate(
        [build_method(tmp_path / "run")], [("s", images)], [0, 10], tmp_path / "e2", progress=False
    )
    assert first == second
    assert (tmp_path / "e1/summary.json").read_text() == (tmp_path / "e2/summary.json").read_text()
    assert summarise(first)["run"]["pattern"] == "D"


def test_detail_region_finds_the_textured_part():
    img = torch.zeros(3, 100, 120)
    img[:, 60:90, 10:40] = torch.rand(3, 30, 30, generator=torch.Generator().manual_seed(1))
    top, left, h, w = detail_region(img, size=30)
    assert (h, w) == (30, 30) and abs(top - 60) <= 1 and abs(left - 10) <= 1


def test_zoom_figure_wraps_many_methods_onto_rows_of_whole_crops(tmp_path):
    """18 cells (scene, truth, 16 methods) in rows of 6 make a figure of 3 rows of 6 cells, not
    one strip of 18; two methods stay on one row of 4 cells."""
    from PIL import Image

    rgb = torch.full((3, 40, 40), 0.5)
    rgb[:, 10:30, 10:30] = torch.rand(3, 20, 20, generator=torch.Generator().manual_seed(1))
    outputs = {f"m{i}": (torch.full((3, 40, 40), i / 16), None) for i in range(16)}
    path = zoom_figure(rgb, outputs, tmp_path / "z.png", region=(0, 0, 40), columns=6)
    width, height = Image.open(path).size
    assert (width, height) == (round(2.6 * 6 * 130), round(3.1 * 3 * 130))
    few = zoom_figure(rgb, dict(list(outputs.items())[:2]), tmp_path / "few.png")
    assert Image.open(few).size == (round(2.6 * 4 * 130), round(3.1 * 130))


def test_evaluate_cli_with_images_and_zoom(tmp_path, capsys):
    folder = tmp_path / "photos"
    folder.mkdir()
    for name, img in _images(2, size=(40, 44)):
        Image.fromarray((img.permute(1, 2, 0).numpy() * 255).astype(np.uint8)).save(
            folder / f"{name}.png"
        )
    out = tmp_path / "out"
    assert (
        main(
            [
                "evaluate",
                "--method",
                "bilinear",
                "--method",
                "lmmse",
                "--patterns",
                "D",
                "--datasets",
                str(folder),
                "--sigmas",
                "0",
                "10",
                "--out",
                str(out),
                "--save-images",
                "--quiet",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "| bayer+bilinear | bayer |" in printed and "| lmmse-D | D |" in printed
    assert (out / "images/lmmse-D/photos/img0_sigma10.png").is_file()
    assert (out / "zoom/photos_img0_sigma0.png").is_file()
    assert (
        main(
            [
                "evaluate",
                "--method",
                "bilinear",
                "--datasets",
                str(folder),
                "--sigmas",
                "0",
                "--out",
                str(tmp_path / "o2"),
                "--save-images",
                "--zoom",
                "img1:4,6,20",
                "--quiet",
            ]
        )
        == 0
    )
    assert (tmp_path / "o2/zoom/photos_img1_sigma0.png").is_file()
    assert not (tmp_path / "o2/zoom/photos_img0_sigma0.png").exists()
    # A zoom with its own noise level (the paper's kodim05 at sigma 10, kodim24 at sigma 5):
    # drawn at that level only, each image at its own.
    assert (
        main(
            [
                "evaluate",
                "--method",
                "bilinear",
                "--datasets",
                str(folder),
                "--sigmas",
                "0",
                "5",
                "10",
                "--out",
                str(tmp_path / "o4"),
                "--save-images",
                "--zoom",
                "img0@10",
                "--zoom",
                "img1:4,6,20@5",
                "--quiet",
            ]
        )
        == 0
    )
    drawn = sorted(p.name for p in (tmp_path / "o4/zoom").glob("*.png"))
    assert drawn == ["photos_img0_sigma10.png", "photos_img1_sigma5.png"]
    assert (
        main(
            [
                "evaluate",
                "--method",
                "bilinear",
                "--datasets",
                str(folder),
                "--sigmas",
                "0",
                "--out",
                str(tmp_path / "o5"),
                "--save-images",
                "--zoom",
                "img1@x",
            ]
        )
        == 1
    )
    assert "expected a zoom as IMAGE[:TOP,LEFT,SIZE][@SIGMA]" in capsys.readouterr().err
    assert (
        main(
            [
                "evaluate",
                "--method",
                "bilinear",
                "--datasets",
                str(folder),
                "--sigmas",
                "0",
                "--out",
                str(tmp_path / "o3"),
                "--save-images",
                "--zoom",
                "img1:4,x",
            ]
        )
        == 1
    )
    assert "expected a zoom as IMAGE[:TOP,LEFT,SIZE][@SIGMA]" in capsys.readouterr().err
    assert main(["evaluate", "--method", "nonsense", "--datasets", str(folder)]) == 1
    assert "unknown method 'nonsense'" in capsys.readouterr().err


def test_report_puts_results_beside_the_paper(tmp_path, capsys):
    from splitcam.evaluation.report import make_report
    from splitcam.physics.sensor import LearnableSplitterSensor

    learned = Spy("learned")
    learned.pattern = LearnableSplitterSensor("A", init="random").to_pattern("A-opt")
    images = _images(24)
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


def _interrupting(name: str, stop_at: int) -> Spy:
    """A Spy that is interrupted (Ctrl-C) on its ``stop_at``-th reconstruction."""
    spy = Spy(name)
    plain = spy.reconstruct

    def reconstruct(raw, sigma):
        if len(spy.seen) + 1 == stop_at:
            raise KeyboardInterrupt
        return plain(raw, sigma)

    spy.reconstruct = reconstruct
    return spy


def test_interrupted_evaluation_keeps_its_rows_and_resumes(tmp_path):
    images = _images(3)
    whole = evaluate(
        [Spy("a"), Spy("b")], [("set", images)], [0, 10], tmp_path / "whole", progress=False
    )
    out = tmp_path / "part"
    a, b = Spy("a"), _interrupting("b", stop_at=4)
    with pytest.raises(KeyboardInterrupt):
        evaluate([a, b], [("set", images)], [0, 10], out, progress=False)
    with open(out / "per_image.csv") as fh:
        kept = list(csv.DictReader(fh))
    assert len(kept) == len(a.seen) + len(b.seen) == 7  # every finished result is on disk
    a2, b2 = Spy("a"), Spy("b")
    rows = evaluate([a2, b2], [("set", images)], [0, 10], out, progress=False)
    assert len(a2.seen) + len(b2.seen) == 12 - 7  # only the missing ones are computed
    assert sorted(rows, key=lambda r: r.key) == sorted(whole, key=lambda r: r.key)
    assert (out / "summary.json").read_text() == (tmp_path / "whole/summary.json").read_text()
    # Another pattern under the same method name is a different method: recomputed.
    c = Spy("a", pattern="A")
    evaluate([c], [("set", images)], [0], out, progress=False)
    assert len(c.seen) == 3
    # --restart recomputes everything.
    d = Spy("a", pattern="A")
    evaluate([d], [("set", images)], [0], out, progress=False, resume=False)
    assert len(d.seen) == 3


def test_zoom_arguments_are_checked_before_any_work(tmp_path):
    images = _images(2)
    spy = Spy("a")
    with pytest.raises(ValueError, match="not among the images evaluated"):
        evaluate(
            [spy],
            [("set", images)],
            [0],
            tmp_path,
            save_images=True,
            zoom_images=["kodim05"],
            progress=False,
        )
    with pytest.raises(ValueError, match="lies outside"):
        evaluate(
            [spy],
            [("set", images)],
            [0],
            tmp_path,
            save_images=True,
            zoom_images=["img1:30,2,8"],
            progress=False,
        )
    with pytest.raises(ValueError, match="finite sigma"):
        evaluate([spy], [("set", images)], [0, float("nan")], tmp_path, progress=False)
    assert spy.seen == []


def _write_photos(folder, n=2, size=(40, 44)):
    folder.mkdir()
    for name, img in _images(n, size=size):
        Image.fromarray((img.permute(1, 2, 0).numpy() * 255).astype(np.uint8)).save(
            folder / f"{name}.png"
        )


def test_pattern_file_named_like_a_builtin_is_not_the_builtin(tmp_path, capsys):
    """`patterns export D` writes a file whose pattern is called D; edited, it is another
    pattern: the LMMSE must use its kernels and the label must say it is the file."""
    photos = tmp_path / "photos"
    _write_photos(photos, size=(60, 64))
    mine = tmp_path / "mine.toml"
    assert main(["patterns", "export", "D", "--out", str(mine)]) == 0
    same = build_method("lmmse", pattern=mine)
    assert same.name == "lmmse-mine.toml" and same.pattern.equals(patterns.get("D"))
    edited = patterns.get("D")
    kernels = edited.kernels.copy()
    kernels[1, 0] = kernels[0, 0]  # the red deflector no longer deflects
    import dataclasses

    patterns.save(dataclasses.replace(edited, kernels=kernels), mine)
    # No shipped fit applies to the edited kernels: the filters are solved for them in closed form.
    closed = build_method("lmmse", pattern=mine)
    assert closed.name == "lmmse-mine.toml"
    assert np.array_equal(closed.statistics.pattern.kernels, kernels)
    from splitcam.recon.closed_form import closed_form_filters

    w_edited, _ = closed_form_filters(patterns.get(mine), 0.0)
    w_builtin, _ = closed_form_filters("D", 0.0)
    torch.testing.assert_close(closed.statistics.filters(0.0)[0], w_edited)
    assert not torch.allclose(w_edited, w_builtin, atol=1e-3)
    capsys.readouterr()
    assert (
        main(
            [
                "evaluate",
                "--method",
                "lmmse",
                "--patterns",
                str(mine),
                "--datasets",
                str(photos),
                "--sigmas",
                "0",
                "--out",
                str(tmp_path / "o"),
                "--quiet",
            ]
        )
        == 0
    )
    fitted = build_method("lmmse", pattern=mine, lmmse_train=photos)
    assert fitted.name == "lmmse-mine.toml"
    assert np.array_equal(fitted.pattern.kernels, kernels)
    assert np.array_equal(fitted.statistics.pattern.kernels, kernels)
    builtin = build_method("lmmse", pattern="D", lmmse_train=photos)
    assert builtin.name == "lmmse-D"
    rows = evaluate([fitted, builtin], [("p", _images(1, (40, 44)))], [0], progress=False)
    assert rows[0].psnr != pytest.approx(rows[1].psnr)


def test_validation_psnr_equals_what_evaluate_reports(tmp_path):
    """Training validation and `splitcam evaluate` are one protocol: the PSNR a run logs for its
    checkpoint is the PSNR evaluate reports for that checkpoint on the same images and sigmas."""
    train_dir, val_dir = tmp_path / "train", tmp_path / "val"
    _write_photos(train_dir, n=3, size=(32, 32))
    _write_photos(val_dir, n=2, size=(36, 40))
    cfg = TrainConfig().override(
        {
            "data.train": str(train_dir),
            "data.val": str(val_dir),
            "data.val_crop": None,
            "data.val_sigmas": [0.0, 15.0],
            "data.patch_size": 16,
            "data.batch_size": 2,
            "network.features": 4,
            "network.blocks": 1,
            "optim.steps": 3,
            "run.val_every": 3,
            "run.out": str(tmp_path / "run"),
            "run.threads": 1,
        }
    )
    train(cfg, progress=False)
    logged = [
        json.loads(line) for line in (tmp_path / "run/metrics.jsonl").read_text().splitlines()
    ]
    last = [r for r in logged if "val_psnr_0" in r][-1]
    assert last["step"] == 3
    assert (
        main(
            [
                "evaluate",
                "--checkpoint",
                str(tmp_path / "run"),
                "--datasets",
                str(val_dir),
                "--sigmas",
                "0",
                "15",
                "--out",
                str(tmp_path / "ev"),
                "--quiet",
            ]
        )
        == 0
    )
    summary = json.loads((tmp_path / "ev/summary.json").read_text())["run"]["all"]
    assert summary["0"]["psnr"] == pytest.approx(last["val_psnr_0"], abs=1e-9)
    assert summary["15"]["psnr"] == pytest.approx(last["val_psnr_15"], abs=1e-9)


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
