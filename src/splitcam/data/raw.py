"""Reading and writing raw sensor images and the record of how they were made.

A raw sensor image is a single-channel float image ``(H, W)``. Its values are non-negative
photon-count fractions that can exceed 1 (a lossless splitter can send up to four pixels' worth of
light to one pixel), and noise can make some of them negative. It is stored either exactly as
``.npy`` or as a 16-bit greyscale PNG with its scale and offset recorded in text chunks
(:data:`RAW_SCALE_KEY`, :data:`RAW_OFFSET_KEY`). How the image was made (the pattern and the
noise) can be recorded beside it (:data:`RAW_META_KEY`, :func:`read_raw_meta`).

Every read failure raises :class:`~splitcam.data.images.ImageReadError`, a :class:`ValueError`
whose message is one line naming the file and the problem.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..io import atomic_path, write_text
from ._png16 import PNG_SIGNATURE
from .images import ImageReadError, read_errors

if TYPE_CHECKING:
    import torch

__all__ = [
    "RAW_META_KEY",
    "RAW_OFFSET_KEY",
    "RAW_SCALE_KEY",
    "read_raw",
    "read_raw_meta",
    "write_raw",
]

RAW_SCALE_KEY = "splitcam:scale"
"""PNG text-chunk key under which :func:`write_raw` records the scale of a raw PNG."""

RAW_OFFSET_KEY = "splitcam:offset"
"""PNG text-chunk key under which :func:`write_raw` records the offset of a raw PNG (where it is
not 0)."""

RAW_META_KEY = "splitcam:meta"
"""PNG text-chunk key holding how a raw image was made: the pattern and the noise
(:func:`write_raw`'s ``meta``). A ``.npy`` file keeps it in the sidecar ``NAME.npy.json``."""


def _to_raw_array(raw: np.ndarray | torch.Tensor) -> np.ndarray:
    """Validate a raw image argument and return it as a float (H, W) numpy array."""
    if not isinstance(raw, np.ndarray):
        import torch

        if not isinstance(raw, torch.Tensor):
            raise TypeError(f"expected a numpy array or torch tensor, got {type(raw).__name__}")
        raw = raw.detach().to("cpu").numpy()
    if raw.ndim == 3 and raw.shape[0] == 1:
        raw = raw[0]
    if raw.ndim != 2:
        raise ValueError(f"expected a single-channel raw image of shape (H, W), got {raw.shape}")
    if not (np.issubdtype(raw.dtype, np.floating) or np.issubdtype(raw.dtype, np.integer)):
        raise TypeError(f"expected real values, got {raw.dtype}")
    if not np.isfinite(raw).all():
        raise ValueError("raw image contains NaN or infinite values")
    return raw


def _default_raw_scale(peak: float) -> float:
    """The smallest power of two that is at least ``peak`` and at least 1."""
    if peak <= 1.0:
        return 1.0
    return float(2.0 ** math.ceil(math.log2(peak)))


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def read_raw_meta(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """How a raw image was made, as :func:`write_raw` recorded it (``None`` if it was not).

    Raises:
        ImageReadError: The record is there but damaged.
    """
    path = Path(path)
    if path.suffix.lower() == ".npy":
        side = _sidecar(path)
        if not side.is_file():
            return None
        text: str | None = side.read_text(encoding="utf-8")
    else:
        from PIL import Image

        with read_errors(path), Image.open(path) as im:
            text = im.info.get(RAW_META_KEY)
        if text is None:
            return None
    try:
        meta = json.loads(text)
    except ValueError:
        raise ImageReadError(path, f"damaged {RAW_META_KEY} record") from None
    if not isinstance(meta, dict):
        raise ImageReadError(path, f"damaged {RAW_META_KEY} record")
    return meta


def write_raw(
    path: str | os.PathLike[str],
    raw: np.ndarray | torch.Tensor,
    *,
    scale: float | None = None,
    meta: dict[str, Any] | None = None,
) -> float:
    """Write a raw (single-channel) sensor image.

    ``.npy`` stores the values exactly as float32, negative values (noise) included.

    ``.png`` stores a 16-bit greyscale PNG of ``round((raw - offset) / scale * 65535)`` and
    records ``scale`` and ``offset`` in the text chunks ``splitcam:scale`` and
    ``splitcam:offset``, so :func:`read_raw` returns the values to within ``scale / 65535 / 2``.
    ``offset`` is the most negative value (noise makes some raw values negative; 0 if there are
    none), so nothing is clipped by default; with a given ``scale``, values above
    ``offset + scale`` are clipped to it. ``.npy`` keeps the values exactly.

    Args:
        path: Output file, ``.npy`` or ``.png``.
        raw: Float image (values may exceed 1, and noise may make some negative).
        meta: How the image was made (JSON-serialisable: pattern, noise), stored in the PNG's
            ``splitcam:meta`` text chunk or beside a ``.npy`` as ``NAME.npy.json``
            (:func:`read_raw_meta`); without it, a stale sidecar of an earlier file is removed.
        scale: Full-scale range of the PNG above ``offset``. Default: the smallest power of two
            that is at least ``max(raw) - offset`` (and at least 1), so that a lossless
            splitter's values up to 4 are kept. Ignored for ``.npy``.

    Returns:
        The scale the stored values were divided by: the PNG scale, or 1.0 for ``.npy``.

    Shape:
        raw: ``(H, W)`` (a leading singleton channel ``(1, H, W)`` is accepted).

    Raises:
        ValueError: Wrong shape, non-finite values, a non-positive scale, or another suffix.
    """
    path = Path(path)
    arr = _to_raw_array(raw)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        with atomic_path(path) as tmp:
            np.save(tmp, arr.astype(np.float32))
        if meta is not None:
            write_text(_sidecar(path), json.dumps(meta))
        else:
            _sidecar(path).unlink(missing_ok=True)
        return 1.0
    if suffix != ".png":
        raise ValueError(f"cannot write raw '{path}': expected a .npy or .png suffix")
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    values = arr.astype(np.float64)
    offset = min(0.0, float(values.min())) if values.size else 0.0
    if scale is None:
        scale = _default_raw_scale(float(values.max()) - offset if values.size else 0.0)
    scale = float(scale)
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a positive finite number, got {scale!r}")
    levels = np.rint(np.clip(values - offset, 0.0, scale) / scale * 65535.0)
    info = PngInfo()
    info.add_text(RAW_SCALE_KEY, repr(scale))
    if offset:
        info.add_text(RAW_OFFSET_KEY, repr(offset))
    if meta is not None:
        info.add_text(RAW_META_KEY, json.dumps(meta))
    with atomic_path(path) as tmp:
        Image.fromarray(levels.astype(np.uint16)).save(tmp, pnginfo=info)
    return scale


def _png_bit_depth_and_colour(path: Path) -> tuple[int, int]:
    """Bit depth and colour type from a PNG's IHDR (Pillow's mode names vary across versions)."""
    with open(path, "rb") as fh:
        head = fh.read(26)
    if len(head) < 26 or not head.startswith(PNG_SIGNATURE) or head[12:16] != b"IHDR":
        raise ImageReadError(path, "not a PNG file")
    return head[24], head[25]


def read_raw(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a raw (single-channel) sensor image written by :func:`write_raw`.

    A PNG without the ``splitcam:scale`` text chunk is read with scale 1, i.e. normalised by its
    bit depth (255 for 8-bit, 65535 for 16-bit); without ``splitcam:offset``, with offset 0.

    Args:
        path: A ``.npy`` or greyscale ``.png`` file.

    Returns:
        float32 array of the raw values.

    Shape:
        Output: ``(H, W)``.

    Raises:
        ImageReadError: The file is missing, unreadable, corrupt, not single-channel, or has
            another suffix.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        with read_errors(path):
            try:
                arr = np.load(path, allow_pickle=False)
            except ValueError:
                raise ImageReadError(path, "not a numeric .npy array") from None
        if arr.ndim == 3 and arr.shape[0] == 1:
            arr = arr[0]
        if arr.ndim != 2:
            raise ImageReadError(
                path, f"expected a single-channel raw image, got shape {arr.shape}"
            )
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise ImageReadError(path, f"expected real values, got {arr.dtype}")
        return arr.astype(np.float32)
    if suffix != ".png":
        raise ImageReadError(path, f"unsupported raw format '{suffix}'; expected .npy or .png")
    from PIL import Image

    with read_errors(path):
        depth, colour = _png_bit_depth_and_colour(path)
        if colour != 0:
            raise ImageReadError(path, "expected a single-channel (greyscale) raw PNG")
        with Image.open(path) as im:
            im.load()
            arr = np.asarray(im)
            text = im.info.get(RAW_SCALE_KEY)
            offset_text = im.info.get(RAW_OFFSET_KEY, "0.0")
    try:
        offset = float(offset_text)
    except ValueError:
        offset = math.nan
    if not math.isfinite(offset):
        raise ImageReadError(path, f"invalid {RAW_OFFSET_KEY} value {offset_text!r}")
    scale = 1.0
    if text is not None:
        try:
            scale = float(text)
        except ValueError:
            scale = math.nan
        if not (math.isfinite(scale) and scale > 0):
            raise ImageReadError(path, f"invalid {RAW_SCALE_KEY} value {text!r}")
    full = float((1 << depth) - 1)
    return (arr.astype(np.float64) * (scale / full) + offset).astype(np.float32)
