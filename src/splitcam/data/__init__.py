"""Data: image and raw files (:mod:`.imageio`), training patches (:mod:`.patches`), and the test
sets with their download (:mod:`.testsets`)."""

from .imageio import read_image, read_raw, write_image, write_raw
from .patches import ImageCache, PatchSampler, list_images, load_validation
from .testsets import default_images, download, load_images

__all__ = [
    "ImageCache",
    "PatchSampler",
    "default_images",
    "download",
    "list_images",
    "load_images",
    "load_validation",
    "read_image",
    "read_raw",
    "write_image",
    "write_raw",
]
