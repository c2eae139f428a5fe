"""``splitcam reconstruct``: the registry's methods through the protocol's sensor, raw files and
what they record, output formats, a model for any pattern."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from PIL import Image

from splitcam import patterns
from splitcam.cli import main
from splitcam.data.imageio import read_raw
from splitcam.patterns.random import random_pattern


def test_reconstruct_goes_through_the_registry_and_the_protocol(tmp_path, capsys):
    """`reconstruct --method lmmse` builds the method `evaluate` builds and simulates like it:
    its output scores exactly what `evaluate` reports for that image."""

    from splitcam.data.imageio import read_image
    from splitcam.evaluation.metrics import psnr

    rng = np.random.default_rng(1)
    folder = tmp_path / "photos"
    folder.mkdir()
    Image.fromarray((rng.random((40, 48, 3)) * 255).astype(np.uint8)).save(folder / "im.png")
    out = tmp_path / "rec.png"
    assert (
        main(
            [
                "reconstruct",
                "--method",
                "lmmse",
                "--pattern",
                "D",
                "--image",
                str(folder / "im.png"),
                "--sigma",
                "10",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert "lmmse-D: wrote" in capsys.readouterr().out
    ours = psnr(
        torch.from_numpy(read_image(out)).permute(2, 0, 1),
        torch.from_numpy(read_image(folder / "im.png")).permute(2, 0, 1),
    )
    assert (
        main(
            [
                "evaluate",
                "--method",
                "lmmse",
                "--patterns",
                "D",
                "--datasets",
                str(folder),
                "--sigmas",
                "10",
                "--out",
                str(tmp_path / "ev"),
                "--quiet",
            ]
        )
        == 0
    )
    summary = json.loads((tmp_path / "ev/summary.json").read_text())
    assert summary["lmmse-D"]["all"]["10"]["psnr"] == pytest.approx(ours, abs=1e-9)
    assert (
        main(
            [
                "reconstruct",
                "--method",
                "lmmse",
                "--image",
                str(folder / "im.png"),
                "--out",
                str(out),
            ]
        )
        == 1
    )
    assert "needs a pattern" in capsys.readouterr().err
    assert (
        main(
            [
                "reconstruct",
                "--method",
                "malvar2004",
                "--pattern",
                "D",
                "--image",
                str(folder / "im.png"),
                "--out",
                str(out),
            ]
        )
        == 1
    )
    assert "differs from the pattern" in capsys.readouterr().err


def test_reconstruct_fast_matches_float32(tmp_path):
    from splitcam.data.imageio import read_image
    from splitcam.training import TrainConfig, train

    rng = np.random.default_rng(2)
    folder = tmp_path / "photos"
    folder.mkdir()
    for i in range(3):
        Image.fromarray((rng.random((32, 32, 3)) * 255).astype(np.uint8)).save(folder / f"p{i}.png")
    train(
        TrainConfig().override(
            {
                "data.train": str(folder),
                "data.val_split": 0,
                "data.patch_size": 16,
                "data.batch_size": 2,
                "network.features": 8,
                "network.blocks": 1,
                "optim.steps": 2,
                "run.out": str(tmp_path / "run"),
                "run.threads": 1,
            }
        ),
        progress=False,
    )
    from splitcam.recon.base import fast_precision

    outs = {}
    flags = {
        "fp32": ["--precision", "fp32"],
        "bf16": ["--precision", "bf16"],
        "fast": ["--fast"],
        "auto": [],
        # Unclipped float32 too: bfloat16 must change the values even where the 2-step
        # network's correction is too small to move an 8-bit level (as on some GPUs).
        "fp32.npy": ["--precision", "fp32"],
        "bf16.npy": ["--precision", "bf16"],
    }
    for key, flag in flags.items():
        path = tmp_path / (f"rec-{key}" if key.endswith(".npy") else f"rec-{key}.png")
        assert (
            main(
                [
                    "reconstruct",
                    "--checkpoint",
                    str(tmp_path / "run"),
                    "--image",
                    str(folder / "p0.png"),
                    "--out",
                    str(path),
                    "--quiet",
                    *flag,
                ]
            )
            == 0
        )
        outs[key] = np.load(path) if key.endswith(".npy") else read_image(path)
    # bfloat16 moves the values, by a few 8-bit levels at most.
    assert 0 < np.abs(outs["fp32.npy"] - outs["bf16.npy"]).max() <= 4 / 255
    assert np.abs(outs["fp32"] - outs["bf16"]).max() <= 4 / 255
    np.testing.assert_array_equal(outs["fast"], outs["bf16"])  # --fast: the old spelling
    # The default follows the hardware: bfloat16 where it is native, float32 elsewhere.
    native = fast_precision("auto", "cpu")
    np.testing.assert_array_equal(outs["auto"], outs["bf16" if native else "fp32"])


def test_cli_reconstruct_and_evaluate_with_a_universal_model(tiny_universal, tmp_path, capsys):
    from PIL import Image

    from splitcam.cli import main

    model, data = tiny_universal
    photo = next(data.iterdir())
    out = tmp_path / "rec.png"
    args = ["reconstruct", "--model", str(model), "--image", str(photo), "--out", str(out)]
    assert main([*args, "--pattern", "E", "--sigma", "5", "--quiet"]) == 0
    with Image.open(out) as im:
        assert im.size == (48, 48)
    assert main([*args, "--pattern", str(tmp_path / "nope.toml")]) == 1
    assert "nope.toml" in capsys.readouterr().err
    mine = tmp_path / "mine.toml"
    patterns.save(random_pattern(np.random.default_rng(4)), mine)
    ev = ["evaluate", "--model", str(model), "--patterns", f"D,{mine}", "--datasets", str(data)]
    assert main([*ev, "--sigmas", "0", "--out", str(tmp_path / "ev"), "--quiet"]) == 0
    table = capsys.readouterr().out
    # Labelled by the pattern's own name (random_pattern calls it "random").
    assert "net-uni-D" in table and "net-uni-random" in table


@pytest.mark.parametrize("suffix", [".png", ".npy"])
def test_raw_files_record_how_they_were_made(photo, tmp_path, capsys, suffix):
    """`simulate` records the pattern and noise; `reconstruct --raw` uses them and refuses a
    contradiction; a raw file without the record needs --sigma and --pattern."""
    import numpy as np

    from splitcam.data.imageio import read_raw_meta, write_raw

    path, _ = photo
    raw = tmp_path / f"raw{suffix}"
    assert main(["simulate", str(path), "--pattern", "D", "--sigma", "15", "--out", str(raw)]) == 0
    made = read_raw_meta(raw)
    assert made["sigma"] == 15.0 and made["noise"] == "gaussian"
    assert made["pattern"]["name"] == "D"
    rec = ["reconstruct", "--raw", str(raw), "--out", str(tmp_path / "r.png"), "--quiet"]
    # The recorded sigma and pattern are used: the same result as saying them.
    assert main([*rec, "--method", "lmmse"]) == 0
    with Image.open(tmp_path / "r.png") as im:
        implied = np.asarray(im)
    assert main([*rec, "--method", "lmmse", "--pattern", "D", "--sigma", "15"]) == 0
    with Image.open(tmp_path / "r.png") as im:
        assert np.array_equal(np.asarray(im), implied)
    capsys.readouterr()
    # Contradictions.
    assert main([*rec, "--method", "lmmse", "--sigma", "0"]) == 1
    assert "contradicts the noise level" in capsys.readouterr().err
    assert main([*rec, "--method", "lmmse", "--pattern", "A"]) == 1
    assert "contradicts the pattern" in capsys.readouterr().err
    assert main([*rec, "--model", "E"]) == 1  # a network of another pattern (1x3 period)
    assert "reconstructs the raw images of pattern E only, not of D" in capsys.readouterr().err
    # Without a record: both must be given.
    bare = tmp_path / f"bare{suffix}"
    write_raw(bare, read_raw(raw))
    assert read_raw_meta(bare) is None
    bare_rec = ["reconstruct", "--raw", str(bare), "--out", str(tmp_path / "b.png")]
    assert main([*bare_rec, "--method", "lmmse", "--pattern", "D"]) == 1
    assert "--sigma" in capsys.readouterr().err
    assert main([*bare_rec, "--method", "lmmse", "--pattern", "D", "--sigma", "15"]) == 0


def test_reconstruct_writes_16_bit_and_float_outputs(photo, tmp_path):
    path, _ = photo
    args = ["reconstruct", "--method", "lmmse", "--pattern", "D", "--image", str(path), "--quiet"]
    assert main([*args, "--out", str(tmp_path / "r.png"), "--bits", "16"]) == 0
    assert (tmp_path / "r.png").read_bytes()[24] == 16  # PNG bit depth
    assert main([*args, "--out", str(tmp_path / "r.tif"), "--bits", "16"]) == 0
    assert main([*args, "--out", str(tmp_path / "r.npy")]) == 0
    rec = np.load(tmp_path / "r.npy")
    assert rec.shape == (10, 12, 3) and rec.dtype == np.float32
    with Image.open(tmp_path / "r.png") as im:
        assert im.size == (12, 10)


def test_a_16_bit_jpeg_is_refused_before_any_work(photo, tmp_path, capsys, monkeypatch):
    from splitcam.recon import registry

    path, _ = photo
    monkeypatch.setattr(registry, "build_method", lambda *a, **k: pytest.fail("worked first"))
    args = ["reconstruct", "--method", "lmmse", "--pattern", "D", "--image", str(path)]
    assert main([*args, "--out", str(tmp_path / "r.jpg"), "--bits", "16", "--quiet"]) == 1
    assert "--bits 16 writes .png or .tif files, not .jpg" in capsys.readouterr().err
    assert not (tmp_path / "r.jpg").exists()


@pytest.mark.parametrize("method", ["lmmse", "D", "malvar2004"])
def test_the_pattern_named_is_read_once(tmp_path, monkeypatch, method):
    """``--pattern D`` becomes a Pattern once per command, whatever the method (the library's
    functions below the CLI take it as read)."""
    made = []
    factory = patterns.NAMES["d"]
    monkeypatch.setitem(patterns.NAMES, "d", lambda: made.append(1) or factory())
    image = tmp_path / "x.png"
    Image.fromarray(np.full((21, 30, 3), 120, np.uint8)).save(image)
    args = ["reconstruct", "--image", str(image), "--pattern", "D", "--method", method]
    main([*args, "--out", str(tmp_path / "y.png"), "--quiet"])
    assert len(made) == 1
