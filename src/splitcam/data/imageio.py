"""Colour image files (:mod:`splitcam.data.images`) and raw sensor files
(:mod:`splitcam.data.raw`) under one name."""

from .images import (
    IMAGE_SUFFIXES,
    ImageReadError,
    decode_image,
    read_image,
    read_image_uint8,
    write_image,
)
from .raw import RAW_META_KEY, RAW_OFFSET_KEY, RAW_SCALE_KEY, read_raw, read_raw_meta, write_raw

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
