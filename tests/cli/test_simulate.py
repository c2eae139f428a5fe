"""``splitcam simulate``: the raw image and preview it writes, and the light domain it records."""

from __future__ import annotations

import numpy as np
import torch
from PIL import Image

from splitcam.cli import main
from splitcam.data.imageio import read_raw
from splitcam.physics.noise import evaluation_noise
from splitcam.physics.sensor import SplitterSensor


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


def _decode_np(u: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1, written out in numpy."""
    return np.where(u <= 0.04045, u / 12.92, ((u + 0.055) / 1.055) ** 2.4)


def test_simulate_records_the_domain_and_reconstruct_reads_it(tmp_path, capsys) -> None:

    gen = torch.Generator().manual_seed(5)
    smooth = torch.nn.functional.interpolate(
        torch.rand(1, 3, 4, 5, generator=gen), size=(24, 30), mode="bilinear"
    )[0]
    codes = (smooth * 255).round().numpy()
    Image.fromarray(codes.transpose(1, 2, 0).astype(np.uint8)).save(tmp_path / "im.png")
    raw = tmp_path / "raw.png"
    assert (
        main(
            ["simulate", str(tmp_path / "im.png"), "--pattern", "bayer"]
            + ["--domain", "linear", "--out", str(raw)]
        )
        == 0
    )
    from splitcam.data.imageio import read_raw, read_raw_meta

    assert read_raw_meta(raw)["domain"] == "linear"
    lin = _decode_np(codes / 255)
    np.testing.assert_allclose(read_raw(raw)[0::2, 0::2], lin[0, 0::2, 0::2], atol=2e-4)
    out = tmp_path / "rec.npy"
    rec = ["reconstruct", "--raw", str(raw), "--method", "lmmse", "--out", str(out), "--quiet"]
    assert main(rec) == 0
    assert "(linear domain)" in capsys.readouterr().out
    from_raw = np.load(out)
    image = ["reconstruct", "--image", str(tmp_path / "im.png"), "--method", "lmmse"]
    image += ["--pattern", "bayer", "--domain", "linear", "--out", str(tmp_path / "i.npy")]
    assert main([*image, "--quiet"]) == 0
    np.testing.assert_allclose(np.load(tmp_path / "i.npy"), from_raw, atol=1e-3)
    # Display values out: close to the image, not to its linear radiance.
    error = np.abs(from_raw.transpose(2, 0, 1) - codes / 255).mean()
    assert error < 0.05 < np.abs(from_raw.transpose(2, 0, 1) - lin).mean()
    assert main([*rec, "--domain", "srgb"]) == 1
    assert "contradicts the light domain" in capsys.readouterr().err
    # Files written without the field are of srgb.
    assert main(["simulate", str(tmp_path / "im.png"), "--out", str(tmp_path / "s.png")]) == 0
    assert read_raw_meta(tmp_path / "s.png")["domain"] == "srgb"
