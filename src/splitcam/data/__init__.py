"""Data: colour image files (:mod:`.images`), raw sensor files (:mod:`.raw`), training patches
(:mod:`.patches`), the test sets (:mod:`.testsets`), their registry (:mod:`.registry`) and their
download (:mod:`.download`).

The names below are imported from their modules on first use, so importing one light module
(such as :mod:`.registry`, which needs only the standard library) does not import torch.
``splitcam.data.download`` is the download module; its function is
:func:`splitcam.data.download.download`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..io.lazy import lazy_exports

if TYPE_CHECKING:
    from .images import read_image, write_image
    from .patches import ImageCache, PatchSampler, list_images, load_validation
    from .raw import read_raw, write_raw
    from .testsets import default_images, load_images

# Each exported name and the module (in this package) that defines it.
_EXPORTS = {
    "ImageCache": "patches",
    "PatchSampler": "patches",
    "default_images": "testsets",
    "list_images": "patches",
    "load_images": "testsets",
    "load_validation": "patches",
    "read_image": "images",
    "read_raw": "raw",
    "write_image": "images",
    "write_raw": "raw",
}

_SUBMODULES = (
    "download",
    "images",
    "imageio",
    "patches",
    "raw",
    "registry",
    "testsets",
)

__all__ = [
    "ImageCache",
    "PatchSampler",
    "default_images",
    "list_images",
    "load_images",
    "load_validation",
    "read_image",
    "read_raw",
    "write_image",
    "write_raw",
]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, _SUBMODULES)
