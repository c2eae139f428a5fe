"""Raw sensor images (splitcam.data.raw): exact ``.npy``, scaled 16-bit PNG, and refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from splitcam.data.images import (
    ImageReadError,
    write_image,
)
from splitcam.data.raw import RAW_OFFSET_KEY, RAW_SCALE_KEY, read_raw, write_raw


def _rgb8(height: int = 13, width: int = 17, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def _assert_names_file(exc_info: pytest.ExceptionInfo[ImageReadError], path: Path) -> None:
    message = str(exc_info.value)
    assert str(path) in message
    assert "\n" not in message
    assert isinstance(exc_info.value, ValueError)


def _raw(seed: int = 10) -> np.ndarray:
    raw = np.random.default_rng(seed).random((11, 14)) * 3.3
    raw[0, 0] = 3.3  # the maximum, above 1, so the default scale is 4
    raw[0, 1] = 0.0
    return raw


def test_raw_npy_exact_including_negative(tmp_path: Path) -> None:
    raw = _raw()
    raw[1, 1] = -0.25  # noise can push values below zero
    assert write_raw(tmp_path / "r.npy", raw) == 1.0
    got = read_raw(tmp_path / "r.npy")
    assert got.dtype == np.float32 and got.shape == raw.shape
    assert np.array_equal(got, raw.astype(np.float32))


def test_raw_png_within_half_step_with_scale_chunk(tmp_path: Path) -> None:
    raw = _raw()
    path = tmp_path / "r.png"
    scale = write_raw(path, raw)
    assert scale == 4.0
    with Image.open(path) as im:
        im.load()
        assert float(im.info[RAW_SCALE_KEY]) == 4.0
        assert np.asarray(im).dtype == np.uint16
    got = read_raw(path)
    assert got.shape == raw.shape and got.dtype == np.float32
    assert np.abs(got - raw).max() <= scale / 65535 / 2 * (1 + 1e-6)
    assert got.max() > 3.29  # values above 1 survive


def test_raw_png_scale_choices_and_clipping(tmp_path: Path) -> None:
    small = np.full((3, 3), 0.3)
    assert write_raw(tmp_path / "s.png", small) == 1.0
    assert write_raw(tmp_path / "e.png", np.full((3, 3), 4.0)) == 4.0
    assert write_raw(tmp_path / "f.png", np.full((3, 3), 4.01)) == 8.0
    noisy = torch.tensor([[[-0.1, 0.5], [2.5, 7.0]]])  # (1, H, W) tensors are accepted
    assert write_raw(tmp_path / "n.png", noisy, scale=2.0) == 2.0
    got = read_raw(tmp_path / "n.png")  # a given scale clips above offset + scale
    assert np.allclose(got, [[-0.1, 0.5], [1.9, 1.9]], atol=2.0 / 65535)


def test_raw_png_keeps_negative_noise(tmp_path: Path) -> None:
    """Noise pushes raw values below 0; the PNG stores them above an offset instead of
    clipping them (a silent loss before)."""
    rng = np.random.default_rng(3)
    raw = rng.random((20, 24)) * 4 + rng.normal(0, 15 / 255, (20, 24))
    raw[0, 0] = -0.2
    scale = write_raw(tmp_path / "n.png", raw)
    assert scale == 8.0  # max - min > 4
    with Image.open(tmp_path / "n.png") as im:
        assert float(im.info[RAW_OFFSET_KEY]) == pytest.approx(raw.min())
    got = read_raw(tmp_path / "n.png")
    assert got.min() < 0
    assert np.abs(got - raw).max() <= scale / 65535 / 2 * (1 + 1e-5) + 1e-7


def test_raw_png_without_chunk_is_normalised(tmp_path: Path) -> None:
    levels16 = np.array([[0, 32768, 65535]], dtype=np.uint16)
    Image.fromarray(levels16).save(tmp_path / "g16.png")
    assert np.allclose(read_raw(tmp_path / "g16.png"), levels16 / 65535.0, atol=1e-7)
    levels8 = np.array([[0, 128, 255]], dtype=np.uint8)
    Image.fromarray(levels8).save(tmp_path / "g8.png")
    assert np.allclose(read_raw(tmp_path / "g8.png"), levels8 / 255.0, atol=1e-7)


def test_raw_errors(tmp_path: Path) -> None:
    write_image(tmp_path / "rgb.png", _rgb8() / 255.0)
    with pytest.raises(ImageReadError, match="single-channel") as exc:
        read_raw(tmp_path / "rgb.png")
    _assert_names_file(exc, tmp_path / "rgb.png")
    np.save(tmp_path / "rgb.npy", np.zeros((4, 4, 3), np.float32))
    with pytest.raises(ImageReadError, match="single-channel"):
        read_raw(tmp_path / "rgb.npy")
    with pytest.raises(ImageReadError, match="file not found"):
        read_raw(tmp_path / "nothere.npy")
    with pytest.raises(ImageReadError, match="unsupported raw format"):
        read_raw(tmp_path / "r.tif")
    with pytest.raises(ValueError, match="suffix"):
        write_raw(tmp_path / "r.jpg", np.zeros((2, 2)))
    with pytest.raises(ValueError, match="scale"):
        write_raw(tmp_path / "r.png", np.zeros((2, 2)), scale=0.0)
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        write_raw(tmp_path / "r.png", np.zeros((2, 2, 3)))
