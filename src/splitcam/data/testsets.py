"""Test image sets: named datasets, image folders and the bundled default images.

Three kinds of test set are understood:

- **Dataset names**, ``kodak24`` and ``mcmaster``: folders under a data root. The root is the
  ``root`` argument, else the ``SPLITCAM_DATA`` environment variable, else
  ``~/.cache/splitcam/datasets`` (:func:`splitcam.data.registry.data_root`).
  ``splitcam data download kodak24 mcmaster --to DIR`` fills it (:mod:`splitcam.data.download`).
- **Folders** of PNG, JPEG, TIFF or BMP images.
- **The default images** (:func:`default_images`): colour photographs that ship inside
  scikit-image, so an evaluation runs on a fresh machine without any download.

:func:`load_datasets` reads several test sets at once, as ``splitcam evaluate --datasets`` names
them. The ``splitcam data`` command (:mod:`splitcam.cli.data`) downloads and lists them.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .images import read_image
from .patches import list_images
from .registry import DATA_ENV, data_root, dataset_names

if TYPE_CHECKING:
    import torch

__all__ = [
    "DEFAULT_IMAGE_NAMES",
    "centre_crop",
    "default_images",
    "load_datasets",
    "load_images",
    "resolve",
]


# Colour photographs bundled in scikit-image's package data: (name, file in skimage/data).
# Synthetic colour images (colorwheel, chessboard) and RGBA graphics (logo, horse) are left out,
# and so are hubble_deep_field and retina: mostly black, they would inflate PSNR and take 60% of
# the pixels (and the time) of the default set.
_SKIMAGE_PHOTOS: tuple[tuple[str, str], ...] = (
    ("astronaut", "astronaut.png"),
    ("chelsea", "chelsea.png"),
    ("coffee", "coffee.png"),
    ("immunohistochemistry", "ihc.png"),
    ("motorcycle_left", "motorcycle_left.png"),
    ("rocket", "rocket.jpg"),
)

DEFAULT_IMAGE_NAMES: tuple[str, ...] = tuple(f"skimage/{name}" for name, _ in _SKIMAGE_PHOTOS)
"""Names of the images :func:`default_images` returns where scikit-image bundles them."""


# ---------------------------------------------------------------------------------------------
# Finding and loading test sets


def _list_folder(folder: Path) -> list[tuple[str, Path]]:
    """(stem, path) of the image files directly inside ``folder`` (see
    :func:`splitcam.data.patches.list_images`), sorted by stem, with unique stems."""

    items = sorted((p.stem, p) for p in list_images(folder))
    # Image names key results and seed the evaluation noise, so two files must not share one.
    counts = Counter(stem for stem, _ in items)
    clashes = [p.name for stem, p in items if counts[stem] > 1]
    if clashes:
        raise ValueError(
            f"image names (file names without suffix) must be unique, but '{folder}' has "
            f"{', '.join(clashes)}; rename or remove the duplicates"
        )
    return items


def _looks_like_path(spec: str) -> bool:
    return (
        "/" in spec
        or os.sep in spec
        or (os.altsep is not None and os.altsep in spec)
        or spec.startswith((".", "~"))
    )


def resolve(
    spec: str | os.PathLike[str], *, root: str | os.PathLike[str] | None = None
) -> list[tuple[str, Path]]:
    """The image files of a test set.

    A plain word (no path separator, not starting with ``.`` or ``~``) is a dataset name and is
    looked up as the folder ``<root>/<name>``; if that folder does not exist but ``./<name>`` does,
    that folder is used. Anything else, and any :class:`os.PathLike`, is a folder path.

    Args:
        spec: A dataset name such as ``"kodak24"`` or ``"mcmaster"``, or a folder of images.
        root: Data root for dataset names; see
            :func:`~splitcam.data.registry.data_root`.

    Returns:
        ``(name, path)`` pairs sorted by name, where the name is the file name without its suffix.
        Only files directly inside the folder with one of the suffixes in
        :data:`splitcam.data.images.IMAGE_SUFFIXES` count; hidden files are ignored.

    Raises:
        FileNotFoundError: The dataset has not been downloaded, or the folder does not exist or
            holds no image files. The message says how to get the data.
        ValueError: Two image files have the same name (e.g. ``a.png`` and ``a.jpg``).
    """
    if not isinstance(spec, str):
        folder = Path(spec)
    elif _looks_like_path(spec):
        folder = Path(spec).expanduser()
    else:
        base = data_root(root)
        folder = base / spec
        if not folder.is_dir() and Path(spec).is_dir():
            folder = Path(spec)
        elif not folder.is_dir():
            where = f"data root '{base}'" + (
                " (from the root argument)"
                if root is not None
                else f" (from ${DATA_ENV})"
                if os.environ.get(DATA_ENV)
                else f" (the default; set ${DATA_ENV} to use another)"
            )
            if spec in dataset_names():
                raise FileNotFoundError(
                    f"dataset '{spec}' not found in {where}: download it with "
                    f"`splitcam data download {spec} --to DIR` and set {DATA_ENV}=DIR, "
                    f"or set {DATA_ENV} to a folder that has a '{spec}' subfolder"
                )
            raise FileNotFoundError(
                f"'{spec}' is neither a folder nor a dataset in {where}; give a folder of "
                f"images or one of the datasets {', '.join(dataset_names())}"
            )
    return _list_folder(folder)


def _to_tensor(rgb: np.ndarray) -> torch.Tensor:
    """A float32 ``(3, H, W)`` tensor from a float32 ``(H, W, 3)`` numpy image."""
    import torch

    return torch.from_numpy(np.ascontiguousarray(np.moveaxis(rgb, -1, 0)))


def load_images(
    spec: str | os.PathLike[str] | None, root: str | os.PathLike[str] | None = None
) -> list[tuple[str, torch.Tensor]]:
    """Read every image of a test set.

    Args:
        spec: A dataset name or folder (see :func:`resolve`), or ``None`` for
            :func:`default_images`.
        root: Data root for dataset names; see
            :func:`~splitcam.data.registry.data_root`.

    Returns:
        ``(name, image)`` pairs sorted by name; each image is a float32 tensor in [0, 1]
        (8-bit files divided by 255, 16-bit files by 65535).

    Shape:
        image: ``(3, H, W)``.

    Raises:
        FileNotFoundError: See :func:`resolve`.
        splitcam.data.images.ImageReadError: A file is not a readable colour image.
    """
    if spec is None:
        return default_images()
    return [(name, _to_tensor(read_image(path))) for name, path in resolve(spec, root=root)]


def _skimage_data_dir() -> Path:
    import importlib.resources

    try:
        return Path(str(importlib.resources.files("skimage.data")))
    except ModuleNotFoundError:
        raise ModuleNotFoundError(
            "the default test images come with scikit-image; install it with "
            "`pip install scikit-image`, or give a dataset or folder of images"
        ) from None


def centre_crop(rgb: torch.Tensor, max_size: int, multiple: int = 2) -> torch.Tensor:
    """The centre of a ``(..., H, W)`` image, at most ``max_size`` pixels a side, each side cut
    down to a multiple of ``multiple`` (2: whole periods of the 2x2 patterns A, B, D and bayer,
    so no image edge ends part-way through one of their periods; the 1x3 patterns C and E
    would need 6, and a 256-pixel crop ends one column into their period)."""
    h, w = rgb.shape[-2:]
    ch = min(h, max_size) // multiple * multiple
    cw = min(w, max_size) // multiple * multiple
    top, left = (h - ch) // 2, (w - cw) // 2
    return rgb[..., top : top + ch, left : left + cw].contiguous()


def default_images(names: Sequence[str] | None = None) -> list[tuple[str, torch.Tensor]]:
    """The default test images: colour photographs that ship inside scikit-image.

    The files are read straight from scikit-image's package data, never downloaded, so this works
    offline on a fresh installation. With scikit-image 0.26 these are astronaut (512x512), chelsea
    (451x300), coffee (600x400), immunohistochemistry (512x512), motorcycle_left (741x500) and
    rocket (640x427) (sizes as WxH). Greyscale, synthetic and RGBA images are not included, nor
    are the mostly black hubble_deep_field and retina.

    Args:
        names: Which images, as in :data:`DEFAULT_IMAGE_NAMES` (with or without the ``skimage/``
            prefix). Default: all of them that the installed scikit-image bundles.

    Returns:
        ``(name, image)`` pairs, names ``skimage/<name>``; each image is a float32 tensor in
        [0, 1].

    Shape:
        image: ``(3, H, W)``.

    Raises:
        ValueError: An unknown name.
        FileNotFoundError: A requested image (or, with ``names=None``, every image) is missing
            from the installed scikit-image.
    """
    data_dir = _skimage_data_dir()
    available = dict(_SKIMAGE_PHOTOS)
    if names is None:
        wanted = [name for name, _ in _SKIMAGE_PHOTOS]
    else:
        wanted = [name.removeprefix("skimage/") for name in names]
        unknown = [name for name in wanted if name not in available]
        if unknown:
            raise ValueError(
                f"unknown default image(s) {', '.join(unknown)}; "
                f"choose from {', '.join(DEFAULT_IMAGE_NAMES)}"
            )
    images = []
    for name in wanted:
        path = data_dir / available[name]
        if not path.is_file():
            if names is not None:
                raise FileNotFoundError(
                    f"the installed scikit-image does not bundle '{available[name]}' "
                    f"(looked in '{data_dir}')"
                )
            continue
        images.append((f"skimage/{name}", _to_tensor(read_image(path))))
    if not images:
        raise FileNotFoundError(
            f"no default test images found in '{data_dir}': the installed scikit-image bundles "
            "none of them; give a dataset or folder of images instead"
        )
    return images


def load_datasets(
    spec: str | None, max_images: int | None = None, max_size: int | None = None
) -> list[tuple[str, list[tuple[str, torch.Tensor]]]]:
    """Read the test sets of a comma-separated list of dataset names and folders.

    Args:
        spec: Comma-separated dataset names or folders (see :func:`resolve`); ``None``, ``""``
            or ``"default"`` for the default images (:func:`default_images`), as the one test set
            ``skimage``.
        max_images: Keep only the first this many images of each test set (by name); ``None`` or
            0 for all.
        max_size: Cut every image to its centre, at most this many pixels a side
            (:func:`centre_crop`); ``None`` for whole images. The test set's name then ends
            in ``-<max_size>px``, which keeps results of whole and cropped images apart.

    Returns:
        ``(test set name, [(image name, image)])`` in the order given; a test set is named by its
        dataset name or its folder's last part. Images as in :func:`load_images`.

    Raises:
        ValueError: ``max_size`` is less than 2.
        FileNotFoundError: See :func:`resolve`.
    """
    if max_size is not None and max_size < 2:
        raise ValueError(f"max_size must be at least 2 pixels, got {max_size}")
    if not spec or spec == "default":
        named = [("skimage", default_images())]
    else:
        items = (s.strip() for s in spec.split(",") if s.strip())
        named = [(Path(item).name or item, load_images(item)) for item in items]
    out = []
    for name, images in named:
        images = images[:max_images] if max_images else images
        if max_size is not None:
            images = [(n, centre_crop(rgb, max_size)) for n, rgb in images]
            name = f"{name}-{max_size}px"
        out.append((name, images))
    return out


# ---------------------------------------------------------------------------------------------
# Command line: `splitcam data ...`
