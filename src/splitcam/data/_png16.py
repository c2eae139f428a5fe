"""16-bit colour PNG files at full precision, which Pillow alone cannot read or write.

Pillow's PNG decoder undoes the filters and interlacing of a 16-bit RGB or RGBA PNG correctly,
but the unpacker it then picks (rawmode ``RGB;16B``) keeps only the high byte of each sample, so
a 16-bit image arrives as 8 bits. Pillow has no writer for 16-bit colour PNG at all. Since 16-bit
files are the lossless way to keep a linear image, :func:`read_png16` recovers the full samples
from Pillow's own decoder (run twice, once per byte) and :func:`encode_png16_rgb` is a small
encoder. Nothing else in the package works around Pillow's PNG support.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
"""The eight bytes every PNG file starts with."""

TRUNCATED_RAWMODES = frozenset({"RGB;16B", "RGBA;16B"})
"""Pillow rawmodes of the PNG files whose samples Pillow cuts to their high bytes."""

# Split 16-bit PNG output into IDAT chunks of this size, as other encoders do.
_IDAT_SIZE = 1 << 20


def tile_rawmode(im: Any) -> str | None:
    """The rawmode of the first decoder tile of an open Pillow image (``None`` if it has none).

    It tells the bit depth that Pillow's mode hides: a 16-bit RGB PNG opens in mode ``RGB``
    with rawmode ``RGB;16B``.
    """
    if not getattr(im, "tile", None):
        return None
    args = im.tile[0][3]
    if isinstance(args, tuple):
        args = args[0] if args else None
    return args if isinstance(args, str) else None


def _with_rawmode(tile: Any, rawmode: str) -> Any:
    """A copy of a Pillow tile descriptor decoding to ``rawmode`` instead."""
    codec, extents, offset, _ = tile
    if hasattr(tile, "_replace"):
        return tile._replace(args=rawmode)
    return (codec, extents, offset, rawmode)


def read_png16(path: Path, rawmode: str) -> np.ndarray:
    """Decode a 16-bit RGB/RGBA PNG at full precision.

    Pillow's ``;16B`` unpacker keeps the high byte of each sample; the ``;16L`` unpacker of the
    same data keeps the other byte, so two passes of Pillow's decoder give the full 16-bit
    samples at C speed.

    Args:
        path: The PNG file.
        rawmode: Its rawmode (:func:`tile_rawmode`), one of :data:`TRUNCATED_RAWMODES`.

    Returns:
        uint16 array; alpha is dropped.

    Shape:
        Output: ``(H, W, 3)``.
    """
    from PIL import Image

    planes = []
    for variant in (rawmode, rawmode[:-1] + "L"):
        with Image.open(path) as im:
            im.tile = [_with_rawmode(im.tile[0], variant)]
            im.load()
            planes.append(np.asarray(im)[..., :3].astype(np.uint16))
    high, low = planes
    return (high << 8) | low


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def encode_png16_rgb(arr: np.ndarray) -> bytes:
    """Encode a uint16 ``(H, W, 3)`` array as a 16-bit RGB PNG.

    Every row uses the "Up" filter (difference to the previous row), which is vectorisable and
    compresses natural images well; the first row has an implicit zero row above it.
    """
    height, width, _ = arr.shape
    rows = arr.astype(">u2").reshape(height, width * 3).view(np.uint8)
    filtered = rows.copy()
    filtered[1:] -= rows[:-1]  # uint8 arithmetic wraps modulo 256, as the filter requires
    data = np.empty((height, filtered.shape[1] + 1), np.uint8)
    data[:, 0] = 2
    data[:, 1:] = filtered
    compressed = zlib.compress(data.tobytes(), 6)
    header = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    parts = [PNG_SIGNATURE, _chunk(b"IHDR", header)]
    for start in range(0, max(len(compressed), 1), _IDAT_SIZE):
        parts.append(_chunk(b"IDAT", compressed[start : start + _IDAT_SIZE]))
    parts.append(_chunk(b"IEND", b""))
    return b"".join(parts)
