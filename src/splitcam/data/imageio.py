"""Reading and writing colour images and raw sensor images.

Colour images are handled as float32 arrays ``(H, W, 3)`` with values in [0, 1]: 8-bit files are
divided by 255 and 16-bit files by 65535. The values are the code values stored in the file (no
gamma or ICC conversion, no EXIF rotation).

Pillow reads PNG, JPEG, TIFF and BMP, but it reduces 16-bit colour PNG and TIFF files to their high
bytes. Full 16-bit precision is recovered here: PNG files are decoded twice by Pillow's own decoder,
once keeping the high bytes and once keeping the low bytes; TIFF files are read with ``tifffile``
(a dependency of scikit-image). 16-bit colour PNG files are written by a small encoder in this
module because Pillow cannot write them.

A raw sensor image is a single-channel float image ``(H, W)``. Its values are non-negative
photon-count fractions that can exceed 1 (a lossless splitter can send up to four pixels' worth of
light to one pixel), so it is stored either exactly as ``.npy`` or as a 16-bit greyscale PNG with
its scale recorded in a text chunk.

Every read failure raises :class:`ImageReadError`, a :class:`ValueError` whose message is one line
naming the file and the problem.
"""

from __future__ import annotations

import json
import math
import os
import struct
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..io import atomic_path, write_bytes, write_text

if TYPE_CHECKING:
    import torch

__all__ = [
    "IMAGE_SUFFIXES",
    "RAW_META_KEY",
    "RAW_OFFSET_KEY",
    "RAW_SCALE_KEY",
    "ImageReadError",
    "decode_image",
    "read_image",
    "read_image_uint8",
    "read_raw",
    "read_raw_meta",
    "write_image",
    "write_raw",
]

IMAGE_SUFFIXES: tuple[str, ...] = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
"""File suffixes (lower case) that are read as colour images."""

RAW_SCALE_KEY = "splitcam:scale"
RAW_OFFSET_KEY = "splitcam:offset"
#: PNG text chunk (and, for ``.npy``, the sidecar ``NAME.npy.json``) holding how a raw image was
#: made: the pattern and the noise (:func:`write_raw`'s ``meta``).
RAW_META_KEY = "splitcam:meta"
"""PNG text-chunk key under which :func:`write_raw` records the scale of a raw PNG."""

# Pillow modes that carry a single intensity channel (with or without alpha).
_GREY_MODES = frozenset({"1", "L", "LA", "La", "I", "F", "I;16", "I;16L", "I;16B", "I;16N"})
# Pillow modes that convert to RGB without losing colour information.
_COLOUR_MODES = frozenset({"RGBA", "RGBX", "RGBa", "P", "PA", "CMYK", "YCbCr", "LAB", "HSV"})
# Split 16-bit PNG output into IDAT chunks of this size, as other encoders do.
_IDAT_SIZE = 1 << 20
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class ImageReadError(ValueError):
    """An image file could not be read.

    The message is one line, ``cannot read '<path>': <reason>``, fit to show to a user as it is.

    Attributes:
        path: The file that could not be read.
        reason: The problem, without the file name (e.g. ``"file not found"``).
    """

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"cannot read '{path}': {reason}")


@contextmanager
def _reading(path: Path) -> Iterator[None]:
    """Turn any failure while decoding ``path`` into an :class:`ImageReadError`."""
    from PIL import Image, UnidentifiedImageError

    try:
        yield
    except ImageReadError:
        raise
    except FileNotFoundError:
        raise ImageReadError(path, "file not found") from None
    except IsADirectoryError:
        raise ImageReadError(path, "is a directory, not a file") from None
    except PermissionError:
        raise ImageReadError(path, "permission denied") from None
    except UnidentifiedImageError:
        raise ImageReadError(path, "not an image file") from None
    except Image.DecompressionBombError as exc:
        raise ImageReadError(path, f"image too large ({exc})") from None
    except MemoryError:
        raise
    except Exception as exc:
        # Pillow plugins raise many exception types on corrupt data (OSError, SyntaxError,
        # struct.error, IndexError, ...); all of them mean the same thing to the user.
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ImageReadError(
            path, f"corrupt, truncated or unsupported image file ({detail})"
        ) from None


def _tile_rawmode(im: Any) -> str | None:
    """The rawmode of Pillow's first decoder tile: it tells the bit depth Pillow hides."""
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


def _read_png16(path: Path, rawmode: str) -> np.ndarray:
    """Decode a 16-bit RGB/RGBA PNG at full precision.

    Pillow's PNG decoder undoes the filters and interlacing correctly for 16-bit colour, then its
    ``;16B`` unpacker keeps the high byte of each sample. The ``;16L`` unpacker of the same data
    keeps the other byte, so two passes give the full 16-bit samples at C speed.
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


def _read_tiff_tifffile(path: Path) -> np.ndarray:
    """Read a colour TIFF with tifffile (used for 16-bit files and what Pillow cannot open)."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        photometric = int(page.photometric)
        arr = page.asarray()
        axes = page.axes
    if photometric in (0, 1):  # MINISWHITE, MINISBLACK
        raise ImageReadError(path, "greyscale image; expected colour (RGB)")
    if photometric != 2:  # RGB
        raise ImageReadError(path, f"unsupported TIFF photometric interpretation {photometric}")
    if axes.startswith("S") and arr.ndim == 3:
        arr = np.moveaxis(arr, 0, -1)
    if arr.ndim != 3 or arr.shape[-1] < 3:
        raise ImageReadError(path, f"unsupported TIFF layout (axes {axes}, shape {arr.shape})")
    if arr.dtype not in (np.uint8, np.uint16):
        raise ImageReadError(
            path, f"unsupported sample type {arr.dtype}; expected 8- or 16-bit integers"
        )
    return np.ascontiguousarray(arr[..., :3])


def _tiff_bits(im: Any) -> int:
    """Largest BitsPerSample of a TIFF opened by Pillow (8 if the tag is missing)."""
    bits = getattr(im, "tag_v2", {}).get(258, 8)
    if isinstance(bits, (tuple, list)):
        return max((int(b) for b in bits), default=8)
    return int(bits)


def _is_tiff(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(4) in (b"II*\x00", b"MM\x00*")
    except OSError:
        return False


def decode_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a colour image as the integers stored in the file.

    This is what :class:`splitcam.data.ImageCache` keeps in memory: 8-bit files stay uint8 and
    16-bit files stay uint16, so nothing is lost and nothing is stored twice as large as needed.

    Args:
        path: A PNG, JPEG, TIFF or BMP file (the format is detected from the content).

    Returns:
        uint8 or uint16 array, C-contiguous. Alpha is dropped; palette, CMYK and YCbCr images are
        converted to RGB.

    Shape:
        Output: ``(H, W, 3)``.

    Raises:
        ImageReadError: The file is missing, unreadable, not an image, corrupt or truncated, or
            greyscale (greyscale carries no colour to learn from).
    """
    path = Path(path)
    with _reading(path):
        try:
            arr = _decode_with_pillow(path)
        except ImageReadError:
            raise
        except Exception as pillow_error:
            # Pillow cannot open some valid TIFFs (planar 16-bit, unusual layouts): give tifffile
            # a go, but report Pillow's diagnosis if tifffile cannot read the file either.
            if not _is_tiff(path):
                raise
            try:
                arr = _read_tiff_tifffile(path)
            except ImageReadError:
                raise
            except Exception:
                raise pillow_error from None
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype not in (np.uint8, np.uint16):
        raise ImageReadError(path, f"unexpected decoded layout {arr.shape} {arr.dtype}")
    if not (arr.flags.c_contiguous and arr.flags.writeable):
        # Arrays built from Pillow's buffers can be read-only; callers own what they get.
        arr = arr.copy(order="C")
    return arr


def _decode_with_pillow(path: Path) -> np.ndarray:
    """The body of :func:`decode_image`; errors are translated by the caller."""
    from PIL import Image

    with Image.open(path) as im:
        mode = im.mode
        rawmode = _tile_rawmode(im) or ""
        # 16-bit grey+alpha PNGs open as "RGBA" with an "LA;16B" rawmode.
        if mode in _GREY_MODES or rawmode.startswith("LA;"):
            raise ImageReadError(path, "greyscale image; expected colour (RGB)")
        if im.format == "TIFF" and _tiff_bits(im) > 8:
            # Pillow keeps only 8 bits of 16-bit colour TIFFs, and misreads planar ones.
            return _read_tiff_tifffile(path)
        if im.format != "PNG" or rawmode not in ("RGB;16B", "RGBA;16B"):
            if mode == "RGB":
                return np.asarray(im)
            if mode in _COLOUR_MODES:
                return np.asarray(im.convert("RGB"))
            raise ImageReadError(path, f"unsupported image mode {mode!r}")
    return _read_png16(path, rawmode)


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a colour image as float32 values in [0, 1].

    Args:
        path: A PNG, JPEG, TIFF or BMP file; 8-bit or 16-bit per channel.

    Returns:
        float32 array: 8-bit values divided by 255, 16-bit values divided by 65535.

    Shape:
        Output: ``(H, W, 3)``.

    Raises:
        ImageReadError: See :func:`decode_image`.
    """
    arr = decode_image(path)
    return arr.astype(np.float32) / np.float32(np.iinfo(arr.dtype).max)


def read_image_uint8(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a colour image as 8-bit values.

    8-bit files are returned exactly; 16-bit values are rounded to the nearest of the 256 levels
    (``round(v / 257)``, since 65535 = 255 * 257).

    Shape:
        Output: ``(H, W, 3)`` uint8.

    Raises:
        ImageReadError: See :func:`decode_image`.
    """
    arr = decode_image(path)
    if arr.dtype == np.uint8:
        return arr
    return ((arr.astype(np.uint32) + 128) // 257).astype(np.uint8)


def _to_hwc_float(rgb: np.ndarray | torch.Tensor) -> np.ndarray:
    """Validate and convert an image argument to a float64 (H, W, 3) numpy array."""
    if isinstance(rgb, np.ndarray):
        arr = rgb
        if arr.ndim != 3 or arr.shape[2] != 3:
            raise ValueError(f"expected a numpy image of shape (H, W, 3), got {arr.shape}")
    else:
        import torch

        if not isinstance(rgb, torch.Tensor):
            raise TypeError(f"expected a numpy array or torch tensor, got {type(rgb).__name__}")
        if rgb.ndim != 3 or rgb.shape[0] != 3:
            raise ValueError(f"expected a torch image of shape (3, H, W), got {tuple(rgb.shape)}")
        if not rgb.is_floating_point():
            raise TypeError(f"expected float values in [0, 1], got {rgb.dtype}")
        arr = rgb.detach().to("cpu", torch.float64).permute(1, 2, 0).numpy()
    if not np.issubdtype(arr.dtype, np.floating):
        raise TypeError(f"expected float values in [0, 1], got {arr.dtype}")
    arr = arr.astype(np.float64, copy=False)
    if not np.isfinite(arr).all():
        raise ValueError("image contains NaN or infinite values")
    return np.clip(arr, 0.0, 1.0)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _encode_png16_rgb(arr: np.ndarray) -> bytes:
    """Encode a uint16 (H, W, 3) array as a 16-bit RGB PNG.

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
    parts = [_PNG_SIGNATURE, _png_chunk(b"IHDR", header)]
    for start in range(0, max(len(compressed), 1), _IDAT_SIZE):
        parts.append(_png_chunk(b"IDAT", compressed[start : start + _IDAT_SIZE]))
    parts.append(_png_chunk(b"IEND", b""))
    return b"".join(parts)


def write_image(
    path: str | os.PathLike[str], rgb: np.ndarray | torch.Tensor, *, bits: int = 8
) -> None:
    """Write a colour image.

    Values are clamped to [0, 1] and rounded to the nearest level. With ``bits=8`` the format
    follows the suffix (any format Pillow writes; JPEG at quality 95 without chroma subsampling).
    With ``bits=16`` the file must be ``.png`` or ``.tif``/``.tiff``.

    Args:
        path: Output file; its folder must exist.
        rgb: Float image, numpy ``(H, W, 3)`` or torch ``(3, H, W)``.
        bits: 8 or 16 bits per channel.

    Shape:
        rgb: ``(H, W, 3)`` numpy or ``(3, H, W)`` torch.

    Raises:
        TypeError: ``rgb`` is not a float array or tensor.
        ValueError: Wrong shape, non-finite values, unsupported ``bits`` or suffix.
    """
    from PIL import Image

    path = Path(path)
    arr = _to_hwc_float(rgb)
    suffix = path.suffix.lower()
    if bits == 8:
        levels = np.rint(arr * 255.0).astype(np.uint8)
        options: dict[str, Any] = {}
        if suffix in (".jpg", ".jpeg"):
            options = {"quality": 95, "subsampling": 0}
        try:
            with atomic_path(path) as tmp:
                Image.fromarray(levels).save(tmp, **options)
        except ValueError as exc:
            raise ValueError(f"cannot write '{path}': {exc}") from None
    elif bits == 16:
        levels16 = np.rint(arr * 65535.0).astype(np.uint16)
        if suffix == ".png":
            write_bytes(path, _encode_png16_rgb(levels16))
        elif suffix in (".tif", ".tiff"):
            import tifffile

            with atomic_path(path) as tmp:
                tifffile.imwrite(tmp, levels16, photometric="rgb", compression="zlib")
        else:
            raise ValueError(f"cannot write '{path}': 16-bit output needs a .png or .tif suffix")
    else:
        raise ValueError(f"bits must be 8 or 16, got {bits!r}")


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

        with _reading(path), Image.open(path) as im:
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
    if len(head) < 26 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
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
        with _reading(path):
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

    with _reading(path):
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
