"""One-line errors, never tracebacks, for mistakes a user can make (each names what is wrong)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from PIL import Image

from splitcam import patterns
from splitcam.cli import main


@pytest.fixture()
def photos(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        Image.fromarray((rng.random((64, 64, 3)) * 255).astype(np.uint8)).save(folder / f"p{i}.png")
    return folder


def test_lmmse_of_a_pattern_that_collects_no_light(tmp_path, photos, capsys):
    dark = dataclasses.replace(
        patterns.get("D"), name="dark", kernels=np.zeros_like(patterns.get("D").kernels)
    )
    patterns.save(dark, tmp_path / "dark.toml")
    assert (
        main(
            [
                "evaluate",
                "--method",
                "lmmse",
                "--patterns",
                str(tmp_path / "dark.toml"),
                "--lmmse-train",
                str(photos),
                "--datasets",
                str(photos),
                "--sigmas",
                "0",
                "--out",
                str(tmp_path / "o"),
                "--quiet",
            ]
        )
        == 1
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "receive no light" in err and "'dark'" in err


def test_plot_skips_damaged_metrics_lines_and_names_them(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.jsonl").write_text(
        '{"step": 1, "loss": 0.1, "train_psnr": 10.0}\n5\n{"step": "x"}\n'
        '{"step": 2, "loss": "NaN?", "train_psnr": 11}\n{"step": 3, "loss": 0.05, '
        '"train_psnr": 13.0}\n{"step": 4, "lo'
    )
    with pytest.warns(UserWarning, match=r"skipped 4 damaged line\(s\): 2, 3, 4, 6"):
        assert main(["plot", str(run)]) == 0
    assert (run / "curves.png").stat().st_size > 1000
    (run / "metrics.jsonl").write_text("garbage\n")
    with pytest.warns(UserWarning):
        assert main(["plot", str(run)]) == 1
    assert "holds no logged steps" in capsys.readouterr().err


def test_report_on_damaged_summary_names_the_file(tmp_path, capsys):
    res = tmp_path / "res"
    res.mkdir()
    (res / "summary.json").write_text("{bad")
    assert main(["report", str(res), "--out", str(tmp_path / "rep")]) == 1
    err = capsys.readouterr().err
    assert "summary.json" in err and "damaged" in err and err.count("\n") == 1
    (res / "summary.json").write_text(json.dumps([1, 2]))
    assert main(["report", str(res), "--out", str(tmp_path / "rep")]) == 1
    assert "damaged" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["simulate", "reconstruct"])
def test_nan_sigma_is_blamed_on_sigma(tmp_path, photos, capsys, command):
    args = {
        "simulate": ["simulate", str(photos / "p0.png"), "--out", str(tmp_path / "r.png")],
        "reconstruct": [
            "reconstruct",
            "--method",
            "malvar2004",
            "--image",
            str(photos / "p0.png"),
            "--out",
            str(tmp_path / "r.png"),
        ],
    }[command]
    assert main([*args, "--sigma", "nan"]) == 1
    err = capsys.readouterr().err
    assert "finite sigma" in err and "image" not in err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["simulate", "{tmp}/missing.png", "--out", "{tmp}/r.png"], "file not found"),
        (["simulate", "{tmp}/text.png", "--out", "{tmp}/r.png"], "not an image file"),
        (
            ["simulate", "{photo}", "--pattern", "Z", "--out", "{tmp}/r.png"],
            "unknown pattern 'Z'; valid names",
        ),
        (["simulate", "{photo}", "--out", "{tmp}/r.jpg"], "--out must end in .png or .npy"),
        (["patterns", "show", "Q"], "unknown pattern 'Q'"),
    ],
)
def test_errors_are_one_line(photo, tmp_path, capsys, argv, message):
    (tmp_path / "text.png").write_text("not an image")
    argv = [a.format(tmp=tmp_path, photo=photo[0]) for a in argv]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and err.count("\n") == 1
