"""Colour image files (splitcam.data.images): round trips in every format, 16-bit PNG included,
and the files refused."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from splitcam.data.images import (
    ImageReadError,
    decode_image,
    read_image,
    read_image_uint8,
    write_image,
)


def _rgb8(height: int = 13, width: int = 17, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def _rgb16(height: int = 13, width: int = 17, seed: int = 0, channels: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    arr = rng.integers(0, 65536, (height, width, channels), dtype=np.uint16)
    arr[0, 0, 0] = 0  # the extremes and the midpoint are always present
    arr[0, 1, 0] = 65535
    arr[0, 2, 0] = 32768
    return arr


# An independent 16-bit PNG encoder, so the reader is not only tested against our own writer: it
# uses every PNG filter type (row i uses filter i % 5) and optionally Adam7 interlacing.
def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _filtered_rows(img: np.ndarray) -> bytes:
    height = img.shape[0]
    bpp = 2 * img.shape[2]
    rows = img.astype(">u2").reshape(height, -1).view(np.uint8).astype(np.int32)
    out = bytearray()
    for i in range(height):
        x = rows[i]
        up = rows[i - 1] if i else np.zeros_like(x)
        left = np.concatenate([np.zeros(bpp, np.int32), x[:-bpp]])
        upleft = np.concatenate([np.zeros(bpp, np.int32), up[:-bpp]])
        p = left + up - upleft
        pa, pb, pc = np.abs(p - left), np.abs(p - up), np.abs(p - upleft)
        paeth = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, up, upleft))
        kind = i % 5
        predictor = [np.zeros_like(x), left, up, (left + up) // 2, paeth][kind]
        out.append(kind)
        out += ((x - predictor) % 256).astype(np.uint8).tobytes()
    return bytes(out)


_ADAM7 = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
          (0, 1, 1, 2)]  # fmt: skip


def _png16_bytes(img: np.ndarray, interlace: bool = False) -> bytes:
    height, width, channels = img.shape
    colour_type = {1: 0, 2: 4, 3: 2, 4: 6}[channels]
    if interlace:
        passes = [img[y0::dy, x0::dx] for x0, y0, dx, dy in _ADAM7]
        data = b"".join(_filtered_rows(p) for p in passes if p.size)
    else:
        data = _filtered_rows(img)
    header = struct.pack(">IIBBBBB", width, height, 16, colour_type, 0, 0, int(interlace))
    return (
        b"\x89PNG\r\n\x1a\n"
        + _chunk(b"IHDR", header)
        + _chunk(b"IDAT", zlib.compress(data))
        + _chunk(b"IEND", b"")
    )


def _assert_names_file(exc_info: pytest.ExceptionInfo[ImageReadError], path: Path) -> None:
    message = str(exc_info.value)
    assert str(path) in message
    assert "\n" not in message
    assert isinstance(exc_info.value, ValueError)


def test_png8_round_trip_exact(tmp_path: Path) -> None:
    arr = _rgb8()
    path = tmp_path / "a.png"
    write_image(path, arr / 255.0)
    assert np.array_equal(decode_image(path), arr)
    got = read_image(path)
    assert got.dtype == np.float32 and got.shape == (13, 17, 3)
    assert np.array_equal(got, arr.astype(np.float32) / 255)


def test_png16_round_trip_exact(tmp_path: Path) -> None:
    arr = _rgb16()
    path = tmp_path / "a16.png"
    write_image(path, arr / 65535.0, bits=16)
    raw = path.read_bytes()
    assert raw[24] == 16 and raw[25] == 2  # IHDR: 16 bits per sample, truecolour
    with Image.open(path) as im:  # a valid PNG for another reader too (which keeps high bytes)
        assert np.array_equal(np.asarray(im), (arr >> 8).astype(np.uint8))
    assert np.array_equal(decode_image(path), arr)
    got = read_image(path)
    assert np.array_equal(got, arr.astype(np.float32) / 65535)
    assert got[0, 1, 0] == 1.0 and got[0, 2, 0] == np.float32(32768 / 65535)


@pytest.mark.parametrize("interlace", [False, True])
@pytest.mark.parametrize("channels", [3, 4])
def test_png16_from_other_encoder_all_filters(tmp_path: Path, interlace: bool, channels: int):
    arr = _rgb16(23, 19, seed=channels, channels=channels)
    path = tmp_path / "other16.png"
    path.write_bytes(_png16_bytes(arr, interlace))
    assert np.array_equal(decode_image(path), arr[..., :3])


@pytest.mark.parametrize("suffix", [".tif", ".tiff"])
def test_tiff_round_trips(tmp_path: Path, suffix: str) -> None:
    arr8 = _rgb8(seed=1)
    write_image(tmp_path / f"a8{suffix}", arr8 / 255.0)
    assert np.array_equal(decode_image(tmp_path / f"a8{suffix}"), arr8)
    arr16 = _rgb16(seed=2)
    write_image(tmp_path / f"a16{suffix}", arr16 / 65535.0, bits=16)
    assert np.array_equal(decode_image(tmp_path / f"a16{suffix}"), arr16)
    assert np.array_equal(read_image(tmp_path / f"a16{suffix}"), arr16.astype(np.float32) / 65535)


def test_tiff16_planar_and_float(tmp_path: Path) -> None:
    tifffile = pytest.importorskip("tifffile")
    arr = _rgb16(seed=11)
    tifffile.imwrite(
        tmp_path / "planar.tif",
        np.ascontiguousarray(arr.transpose(2, 0, 1)),
        planarconfig="separate",
        photometric="rgb",
    )
    assert np.array_equal(decode_image(tmp_path / "planar.tif"), arr)
    tifffile.imwrite(tmp_path / "float.tif", arr.astype(np.float32), photometric="rgb")
    with pytest.raises(ImageReadError, match="unsupported sample type float32") as exc:
        read_image(tmp_path / "float.tif")
    _assert_names_file(exc, tmp_path / "float.tif")


def test_bmp_round_trip_exact(tmp_path: Path) -> None:
    arr = _rgb8(seed=3)
    write_image(tmp_path / "a.bmp", arr / 255.0)
    assert np.array_equal(read_image_uint8(tmp_path / "a.bmp"), arr)


def test_jpeg_round_trip_close(tmp_path: Path) -> None:
    yy, xx = np.mgrid[0:48, 0:64] / 64.0
    rgb = np.stack([yy, xx, 0.5 + 0.3 * np.sin(6 * xx)], axis=-1)
    write_image(tmp_path / "a.jpg", rgb)
    got = read_image(tmp_path / "a.jpg")
    assert got.shape == (48, 64, 3)
    assert np.abs(got - rgb).mean() < 2 / 255
    assert np.abs(got - rgb).max() < 12 / 255


def test_rgba_drops_alpha_keeps_colour(tmp_path: Path) -> None:
    arr = _rgb8(seed=4)
    alpha = np.random.default_rng(5).integers(0, 256, arr.shape[:2], dtype=np.uint8)
    alpha[:2] = 0  # fully transparent pixels must keep their colour too
    Image.fromarray(np.dstack([arr, alpha]), "RGBA").save(tmp_path / "rgba.png")
    assert np.array_equal(decode_image(tmp_path / "rgba.png"), arr)


def test_palette_image_converted(tmp_path: Path) -> None:
    palette = np.random.default_rng(6).integers(0, 256, (256, 3), dtype=np.uint8)
    indices = np.random.default_rng(7).integers(0, 256, (9, 11), dtype=np.uint8)
    im = Image.fromarray(indices, "P")
    im.putpalette(palette.tobytes())
    im.save(tmp_path / "p.png")
    assert np.array_equal(decode_image(tmp_path / "p.png"), palette[indices])


def test_greyscale_refused(tmp_path: Path) -> None:
    grey = _rgb8()[..., 0]
    files = {
        "l.png": Image.fromarray(grey, "L"),
        "la.png": Image.fromarray(np.dstack([grey, grey]), "LA"),
        "one.png": Image.fromarray(grey > 127),
        "i16.png": Image.fromarray(grey.astype(np.uint16) * 257),
        "l.jpg": Image.fromarray(grey, "L"),
    }
    for name, im in files.items():
        im.save(tmp_path / name)
    (tmp_path / "la16.png").write_bytes(_png16_bytes(_rgb16(channels=2)))
    for name in [*files, "la16.png"]:
        with pytest.raises(ImageReadError, match="greyscale image; expected colour") as exc:
            read_image(tmp_path / name)
        _assert_names_file(exc, tmp_path / name)


def test_missing_file_refused(tmp_path: Path) -> None:
    path = tmp_path / "nothere.png"
    with pytest.raises(ImageReadError, match="file not found") as exc:
        read_image(path)
    _assert_names_file(exc, path)


def test_non_image_and_corrupt_refused(tmp_path: Path) -> None:
    text = tmp_path / "notes.png"
    text.write_text("this is not an image\n")
    noise = tmp_path / "noise.jpg"
    noise.write_bytes(np.random.default_rng(8).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    for path in (text, noise):
        with pytest.raises(ImageReadError, match="not an image file") as exc:
            read_image(path)
        _assert_names_file(exc, path)
    with pytest.raises(ImageReadError, match="directory") as exc:
        read_image(tmp_path)
    _assert_names_file(exc, tmp_path)


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".bmp"])
def test_truncated_refused(tmp_path: Path, suffix: str) -> None:
    full = tmp_path / f"full{suffix}"
    write_image(full, _rgb8(64, 64) / 255.0)
    cut = tmp_path / f"cut{suffix}"
    data = full.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageReadError, match="corrupt, truncated") as exc:
        read_image(cut)
    _assert_names_file(exc, cut)


def test_truncated_png16_refused(tmp_path: Path) -> None:
    data = _png16_bytes(_rgb16(40, 40))
    cut = tmp_path / "cut16.png"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageReadError, match="corrupt, truncated") as exc:
        read_image(cut)
    _assert_names_file(exc, cut)


def test_read_image_uint8_rounds_16_bit(tmp_path: Path) -> None:
    arr = _rgb16(seed=9)
    write_image(tmp_path / "a16.png", arr / 65535.0, bits=16)
    expected = np.rint(arr / 257.0).astype(np.uint8)
    assert np.array_equal(read_image_uint8(tmp_path / "a16.png"), expected)


def test_write_image_torch_clamps_and_validates(tmp_path: Path) -> None:
    img = torch.linspace(-0.5, 1.5, 3 * 4 * 5).reshape(3, 4, 5)
    write_image(tmp_path / "t.png", img)
    expected = np.rint(img.clamp(0, 1).permute(1, 2, 0).double().numpy() * 255) / 255
    assert np.allclose(read_image(tmp_path / "t.png"), expected, atol=1e-7)
    with pytest.raises(ValueError, match=r"\(3, H, W\)"):
        write_image(tmp_path / "bad.png", torch.zeros(4, 5, 3))
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        write_image(tmp_path / "bad.png", np.zeros((3, 4, 5)))
    with pytest.raises(ValueError, match="NaN"):
        write_image(tmp_path / "bad.png", np.full((2, 2, 3), np.nan))
    with pytest.raises(TypeError, match="float"):
        write_image(tmp_path / "bad.png", np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(ValueError, match="16-bit"):
        write_image(tmp_path / "bad.jpg", np.zeros((2, 2, 3)), bits=16)
    with pytest.raises(ValueError, match="bits"):
        write_image(tmp_path / "bad.png", np.zeros((2, 2, 3)), bits=12)
