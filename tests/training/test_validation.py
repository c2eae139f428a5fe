"""Validation during training (splitcam.training.validation): the held-out split, and the PSNR it
logs equal to what evaluate reports."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from conftest import blocky_images, tiny_config, write_photos
from PIL import Image

from splitcam.cli import main
from splitcam.training import TrainConfig, train
from splitcam.training.config import ConfigError


def test_validation_psnr_equals_what_evaluate_reports(tmp_path):
    """Training validation and `splitcam evaluate` are one protocol: the PSNR a run logs for its
    checkpoint is the PSNR evaluate reports for that checkpoint on the same images and sigmas."""
    train_dir, val_dir = tmp_path / "train", tmp_path / "val"
    write_photos(train_dir, n=3, size=(32, 32))
    write_photos(val_dir, n=2, size=(36, 40))
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


def test_validation_at_half_size_scores_the_halved_photos(tmp_path):
    """data.val_scale 0.5 (the ship gate's size): the PSNR a run logs is what evaluate reports on
    the validation photos halved by Pillow's antialiased bicubic (odd sides: 73x81 -> 36x40)."""
    train_dir, val_dir, halved = tmp_path / "train", tmp_path / "val", tmp_path / "halved"
    write_photos(train_dir, n=3, size=(32, 32))
    write_photos(val_dir, n=2, size=(73, 81))
    halved.mkdir()
    for path in sorted(val_dir.iterdir()):
        with Image.open(path) as im:
            small = im.resize((round(im.width / 2), round(im.height / 2)), Image.BICUBIC)
            small.save(halved / path.name)
    settings = {
        "data.train": str(train_dir),
        "data.val": str(val_dir),
        "data.val_crop": None,
        "data.val_scale": 0.5,
        "data.val_sigmas": [0.0],
        "data.patch_size": 16,
        "data.batch_size": 2,
        "network.features": 4,
        "network.blocks": 1,
        "optim.steps": 2,
        "run.val_every": 2,
        "run.out": str(tmp_path / "run"),
        "run.threads": 1,
    }
    train(TrainConfig().override(settings), progress=False)
    logged = [
        json.loads(line) for line in (tmp_path / "run/metrics.jsonl").read_text().splitlines()
    ]
    last = [r for r in logged if "val_psnr_0" in r][-1]
    out = tmp_path / "ev"
    args = ["evaluate", "--checkpoint", str(tmp_path / "run"), "--datasets", str(halved)]
    assert main([*args, "--sigmas", "0", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())["run"]["all"]
    # Pillow and torch's antialiased bicubic may round a few values apart.
    assert summary["0"]["psnr"] == pytest.approx(last["val_psnr_0"], abs=0.05)
    with pytest.raises(ConfigError, match="val_scale must be in"):
        TrainConfig().override({"data.val_scale": 0.0}).validate()


def test_validation_is_on_by_default_on_a_held_out_split(image_folder, tmp_path):
    from splitcam.training.validation import train_source, val_split

    config = tiny_config(image_folder, tmp_path / "v", **{"data.val_split": None})
    assert val_split(config) == 1  # 8 images: max(1, 8 // 10)
    held_out = {p.name for p in train_source(config)}
    assert "im7.png" not in held_out and len(held_out) == 7
    train(config, progress=False)
    rows = [json.loads(x) for x in (tmp_path / "v/metrics.jsonl").read_text().splitlines()]
    assert any("val_psnr" in r for r in rows)
    assert val_split(tiny_config(image_folder, tmp_path / "w", **{"data.val_split": 0})) == 0


def test_validation_never_uses_an_image_smaller_than_its_crop(tmp_path, caplog):
    """A 16x16 image sorting last would have been the whole validation set."""

    from splitcam.training import train
    from splitcam.training.validation import held_out

    data = blocky_images(tmp_path / "img", 5)
    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(data / "zz_tiny.png")
    config = tiny_config(data, tmp_path / "run", **{"data.val_crop": 32, "data.val_split": 1})
    chosen = held_out(config)
    assert [p.name for p in chosen] == ["im4.png"]
    caplog.set_level(logging.INFO, logger="splitcam")
    train(config, progress=True)
    assert "validation: 1 of the last 1 images" in caplog.text and "training: im4" in caplog.text
    # The tiny image is trained on, not lost: the training set is the rest.
    from splitcam.training.validation import train_source

    assert {p.name for p in train_source(config)} == {f"im{i}.png" for i in range(4)} | {
        "zz_tiny.png"
    }
    # Images all smaller than the crop: the largest ones, never the tiny one.
    big = tiny_config(data, tmp_path / "r2", **{"data.val_crop": 64, "data.val_split": 2})
    assert [p.name for p in held_out(big)] == ["im3.png", "im4.png"]
