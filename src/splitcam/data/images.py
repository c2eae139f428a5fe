"""Reading and writing colour images.

Colour images are handled as float32 arrays ``(H, W, 3)`` with values in [0, 1]: 8-bit files are
divided by 255 and 16-bit files by 65535. The values are the code values stored in the file (no
gamma or ICC conversion, no EXIF rotation).

Pillow reads PNG, JPEG, TIFF and BMP, but it reduces 16-bit colour PNG and TIFF files to their high
bytes. 16-bit PNG files are read and written at full precision by :mod:`splitcam.data._png16`;
16-bit TIFF files are read and written with ``tifffile`` (a dependency of scikit-image).

Every read failure raises :class:`ImageReadError`, a :class:`ValueError` whose message is one line
naming the file and the problem; raw sensor images (:mod:`splitcam.data.raw`) report theirs the
same way.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..io import atomic_path, write_bytes
from ._png16 import TRUNCATED_RAWMODES, encode_png16_rgb, read_png16, tile_rawmode

if TYPE_CHECKING:
    import torch

__all__ = [
    "IMAGE_SUFFIXES",
    "ImageReadError",
    "decode_image",
    "read_image",
    "read_image_uint8",
    "write_image",
]

IMAGE_SUFFIXES: tuple[str, ...] = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
"""File suffixes (lower case) that are read as colour images."""

# Pillow modes that carry a single intensity channel (with or without alpha).
_GREY_MODES = frozenset({"1", "L", "LA", "La", "I", "F", "I;16", "I;16L", "I;16B", "I;16N"})
# Pillow modes that convert to RGB without losing colour information.
_COLOUR_MODES = frozenset({"RGBA", "RGBX", "RGBa", "P", "PA", "CMYK", "YCbCr", "LAB", "HSV"})


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
def read_errors(path: Path) -> Iterator[None]:
    """Turn any failure while reading ``path`` into an :class:`ImageReadError` (a context
    manager around the code that opens and decodes the file)."""
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
    with read_errors(path):
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
        rawmode = tile_rawmode(im) or ""
        # 16-bit grey+alpha PNGs open as "RGBA" with an "LA;16B" rawmode.
        if mode in _GREY_MODES or rawmode.startswith("LA;"):
            raise ImageReadError(path, "greyscale image; expected colour (RGB)")
        if im.format == "TIFF" and _tiff_bits(im) > 8:
            # Pillow keeps only 8 bits of 16-bit colour TIFFs, and misreads planar ones.
            return _read_tiff_tifffile(path)
        if im.format != "PNG" or rawmode not in TRUNCATED_RAWMODES:
            if mode == "RGB":
                return np.asarray(im)
            if mode in _COLOUR_MODES:
                return np.asarray(im.convert("RGB"))
            raise ImageReadError(path, f"unsupported image mode {mode!r}")
    return read_png16(path, rawmode)


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
            write_bytes(path, encode_png16_rgb(levels16))
        elif suffix in (".tif", ".tiff"):
            import tifffile

            with atomic_path(path) as tmp:
                tifffile.imwrite(tmp, levels16, photometric="rgb", compression="zlib")
        else:
            raise ValueError(f"cannot write '{path}': 16-bit output needs a .png or .tif suffix")
    else:
        raise ValueError(f"bits must be 8 or 16, got {bits!r}")
