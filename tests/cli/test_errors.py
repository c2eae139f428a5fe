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
    """A pattern file whose kernels record no light passed the validator, then the LMMSE
    raised LinAlgError (or said so late); now loading the file refuses it, naming the pixel,
    before any work."""
    data = patterns.get("D").to_dict()
    data["name"] = "dark"
    data["kernels"] = np.zeros_like(patterns.get("D").kernels).tolist()
    (tmp_path / "dark.json").write_text(json.dumps(data))
    with pytest.raises(patterns.PatternError, match=r"pixel \(0, 0\) of the period records no"):
        dataclasses.replace(patterns.get("D"), kernels=np.zeros_like(patterns.get("D").kernels))
    assert (
        main(
            [
                "evaluate",
                "--method",
                "lmmse",
                "--patterns",
                str(tmp_path / "dark.json"),
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
    assert err.count("\n") == 1 and "records no light" in err and "dark.json" in err
    assert not (tmp_path / "o").exists()


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


@pytest.mark.parametrize(
    "argv, message",
    [
        (["train", "--steps", "0"], "optim.steps must be >= 1"),
        (["train", "--time-limit", "-1"], "run.time_limit must be > 0"),
        (["train", "--threads", "0"], "run.threads must be >= 1"),
        (["train", "--patch-size", "3"], "data.patch_size must be >= 8"),
        (["evaluate", "--method", "lmmse", "--patterns", "D", "--max-images", "0"], "--max-images"),
        (["evaluate", "--method", "lmmse", "--patterns", "D", "--zoom", "x"], "--save-images"),
    ],
)
def test_nonsense_settings_are_refused_in_one_line(tmp_path, capsys, argv, message) -> None:
    """Settings that mean nothing (no steps, a negative time, no threads, a patch smaller than
    two periods, zero images, a zoom that would not be drawn) are refused before any work, in
    one line, and leave no folder behind."""
    from splitcam.cli import main

    out = tmp_path / "out"
    extra = ["--data", str(tmp_path)] if argv[0] == "train" else []
    assert main([*argv, *extra, "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_a_model_of_one_pattern_refuses_another_pattern_in_the_api() -> None:
    """build_method("D", pattern="A") used to ignore the pattern and reconstruct as D."""
    from splitcam.recon.registry import build_method

    assert build_method("D", pattern="D").pattern.name == "D"
    with pytest.raises(ValueError, match="pattern D only, not of A"):
        build_method("D", pattern="A")


@pytest.mark.slow
def test_messages_that_help(tmp_path, capsys) -> None:
    """After a time-limit stop the run says to raise --time-limit, and so does --resume; a
    corrupt file among good photos is skipped by name in one line and training goes on; an
    OS error names the user's path, not a temporary one."""
    import shutil

    from conftest import blocky_images

    photos = blocky_images(tmp_path / "photos", 4)
    (photos / "zz_corrupt.png").write_bytes(b"\x89PNG broken")
    run = tmp_path / "run"
    args = [
        "train",
        "--data",
        str(photos),
        "--out",
        str(run),
        "--patch-size",
        "16",
        "--features",
        "8",
        "--blocks",
        "1",
        "--threads",
        "1",
        "--time-limit",
        "0.002",
    ]
    # As a user sees it (a subprocess: the test runner records warnings itself).
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "splitcam", *args], capture_output=True, text=True, check=True
    )
    assert "larger --time-limit" in done.stdout
    assert "warning: skipped 1 of" in done.stderr and "zz_corrupt.png" in done.stderr
    assert "UserWarning" not in done.stderr and "warnings.warn" not in done.stderr
    assert main([*args, "--resume"]) == 0
    assert "larger --time-limit" in capsys.readouterr().out
    shutil.rmtree(run)
    (tmp_path / "afile").write_text("")
    photo = photos / "im0.png"
    out = tmp_path / "afile" / "x.png"
    command = ["reconstruct", "--method", "lmmse", "--pattern", "D"]
    assert main([*command, "--image", str(photo), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert str(out) in err and ".tmp-" not in err and len(err.strip().splitlines()) == 1
