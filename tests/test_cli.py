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


@pytest.fixture
def photo(tmp_path):
    rng = np.random.default_rng(0)
    arr = rng.integers(0, 256, size=(10, 12, 3), dtype=np.uint8)
    path = tmp_path / "photo.png"
    Image.fromarray(arr).save(path)
    return path, arr


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
        (["simulate", "{photo}", "--pattern", "Z", "--out", "{tmp}/r.png"],
         "unknown pattern 'Z'; valid names"),
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
