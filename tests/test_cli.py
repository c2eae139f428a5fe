"""The command line: patterns, simulate, and one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from splitcam import patterns
from splitcam.cli import main
from splitcam.data.imageio import read_raw
from splitcam.physics.noise import evaluation_noise
from splitcam.physics.sensor import SplitterSensor


def test_patterns_table_lists_every_pattern(capsys):
    assert main(["patterns"]) == 0
    out = capsys.readouterr().out
    for name in patterns.names():
        assert f"| {name} " in out
    assert "yes, 4-pixel unit" in out and "0.25/0.50/0.25" in out


def test_patterns_show_and_export(tmp_path, capsys):
    png = tmp_path / "d.png"
    assert main(["patterns", "show", "D", "--out", str(png)]) == 0
    with Image.open(png) as im:
        assert im.size[0] > 300 and im.size[1] > 200
    toml = tmp_path / "d.toml"
    assert main(["patterns", "export", "d", "--out", str(toml)]) == 0
    assert patterns.load(toml).equals(patterns.get("D"))
    assert main(["patterns", "show", str(toml), "--out", str(tmp_path / "e.png")]) == 0


def test_simulate_writes_the_raw_image(photo, tmp_path):
    path, arr = photo
    out = tmp_path / "raw.npy"
    assert main(["simulate", str(path), "--pattern", "A", "--sigma", "10", "--out", str(out)]) == 0
    rgb = torch.from_numpy(arr).permute(2, 0, 1)[None].double() / 255
    expected = SplitterSensor("A").double()(rgb) + evaluation_noise(
        (1, 1, 10, 12), "photo", 10, dtype=torch.float64
    )
    np.testing.assert_allclose(read_raw(out), expected[0, 0].numpy(), atol=1e-6)
    assert (tmp_path / "raw_preview.png").is_file()
    png = tmp_path / "raw.png"
    assert main(["simulate", str(path), "--pattern", "D", "--out", str(png)]) == 0
    clean = SplitterSensor("D").double()(rgb)[0, 0].numpy()
    np.testing.assert_allclose(read_raw(png), clean, atol=4 / 65535)


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


def test_reconstruct_goes_through_the_registry_and_the_protocol(tmp_path, capsys):
    """`reconstruct --method lmmse` builds the method `evaluate` builds and simulates like it:
    its output scores exactly what `evaluate` reports for that image."""
    import json

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
    }
    for key, flag in flags.items():
        path = tmp_path / f"rec-{key}.png"
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
        outs[key] = read_image(path)
    difference = np.abs(outs["fp32"] - outs["bf16"])
    assert 0 < difference.max() <= 4 / 255  # bfloat16 moves 8-bit values by a few levels at most
    np.testing.assert_array_equal(outs["fast"], outs["bf16"])  # --fast: the old spelling
    # The default follows the hardware: bfloat16 where it is native, float32 elsewhere.
    native = fast_precision("auto", "cpu")
    np.testing.assert_array_equal(outs["auto"], outs["bf16" if native else "fp32"])


def test_evaluate_draws_the_sigma_chart(tmp_path):
    from splitcam.cli import main

    out = tmp_path / "e"
    args = [
        "evaluate",
        "--method",
        "malvar2004",
        "--max-images",
        "1",
        "--sigmas",
        "0",
        "10",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(args) == 0
    assert (out / "sigma_curves.png").stat().st_size > 0
    assert not (out / "zoom").exists()  # a named method draws crops only with --save-images


def test_max_size_scores_the_centre_of_each_image(tmp_path):
    """--max-size cuts every image to its centre (even sizes, whole 2x2 periods); the scores are
    those of the cropped image itself, and the dataset name keeps them apart from whole images."""
    import csv

    from splitcam.data.testsets import centre_crop, default_images, load_datasets

    rgb = torch.arange(3 * 7 * 9, dtype=torch.float32).reshape(3, 7, 9)
    assert torch.equal(centre_crop(rgb, 4), rgb[:, 1:5, 2:6])
    assert torch.equal(centre_crop(rgb, 100), rgb[:, :6, :8])  # at most the image, even sizes
    ((name, images),) = load_datasets("default", 1, 64)
    assert name == "skimage-64px" and images[0][1].shape == (3, 64, 64)
    whole = default_images()[0][1]
    h, w = whole.shape[-2:]
    top, left = (h - 64) // 2, (w - 64) // 2
    assert torch.equal(images[0][1], whole[:, top : top + 64, left : left + 64])

    out = tmp_path / "e"
    args = [
        "evaluate",
        "--method",
        "bilinear",
        "--max-images",
        "1",
        "--max-size",
        "64",
        "--sigmas",
        "0",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(args) == 0
    rows = list(csv.DictReader((out / "per_image.csv").open()))
    assert {r["dataset"] for r in rows} == {"skimage-64px"}
    with pytest.raises(ValueError, match="at least 2"):
        load_datasets("default", 1, 1)


def test_parsing_every_command_imports_no_torch():
    """`splitcam --help` and each command's --help build the parsers only: no torch, numpy or
    matplotlib is imported (checked in a fresh interpreter, where nothing is imported yet)."""
    import subprocess
    import sys

    from splitcam.cli import COMMANDS

    code = (
        "import sys, contextlib, io\n"
        "from splitcam.cli import build_parser\n"
        "parser = build_parser()\n"
        f"for argv in [['--help'], *[[c, '--help'] for c in {list(COMMANDS)!r}]]:\n"
        "    with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "        try:\n"
        "            parser.parse_args(argv)\n"
        "        except SystemExit:\n"
        "            pass\n"
        "    assert 'usage: splitcam' in out.getvalue(), argv\n"
        "print(sorted(m for m in ('torch', 'numpy', 'matplotlib') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_moved_names_say_where_they_went():
    import splitcam.cli

    with pytest.raises(AttributeError, match="splitcam.data.testsets.load_datasets"):
        splitcam.cli.load_datasets  # noqa: B018
    with pytest.raises(ImportError, match="splitcam.physics.optics"):
        import splitcam.optics  # noqa: F401
