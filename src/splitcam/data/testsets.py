"""Test image sets: named datasets, image folders, the bundled default images, and downloads.

Three kinds of test set are understood:

- **Dataset names**, ``kodak24`` and ``mcmaster``: folders under a data root. The root is the
  ``root`` argument, else the ``SPLITCAM_DATA`` environment variable, else
  ``~/.cache/splitcam/datasets``. ``splitcam data download kodak24 mcmaster --to DIR`` fills it.
- **Folders** of PNG, JPEG, TIFF or BMP images.
- **The default images** (:func:`default_images`): colour photographs that ship inside
  scikit-image, so an evaluation runs on a fresh machine without any download.

Downloads and their checks
--------------------------
Every file is fetched from the public address the dataset is published at, pinned to a commit
(:data:`_SOURCES`), and checked against the hashes in the registry file ``registry.tsv`` that
ships beside this module. The transfers go through `pooch <https://www.fatiando.org/pooch>`_
(:func:`pooch.retrieve`), which downloads to a temporary file in the dataset folder, checks its
SHA-256 and only then moves it to its final name.

- **Kodak24** (``kodim01.png`` ... ``kodim24.png``): GitHub ``cszn/IRCNN``,
  ``testsets/Set24/kodimNN.png``. The files are used as published, so pooch checks the downloaded
  bytes against the registered SHA-256. The registered git blob id describes the same bytes (the
  tests check that), so it needs no second check.
- **McMaster** (``01.png`` ... ``18.png``): GitHub ``cszn/FFDNet``, ``testsets/McMaster/N.tif``.
  The published files are TIFFs; ``N.tif`` becomes ``NN.png``. pooch cannot verify these: their
  registered hashes are a git blob id (``sha1(b"blob <size>\\0" + bytes)``, as
  ``git hash-object`` prints), which is no plain digest of the file, and a hash of the decoded
  pixels, ``sha256(np.asarray(Image.open(f).convert("RGB"), np.uint8).tobytes())``. So pooch
  downloads the TIFF into a scratch folder without a hash, and a pooch processor of ours checks
  both hashes and writes the pixels as PNG. The pixel hash is what makes the PNG trustworthy: a
  PNG encoder other than the one that made the reference files may write different bytes for the
  same pixels, so an existing McMaster PNG counts as verified if either its file SHA-256 or its
  pixel hash matches.

A mirror (``mirror=`` or the ``SPLITCAM_MIRROR`` environment variable) replaces the public
addresses by ``<mirror>/<dataset>/<file name>``, i.e. a server holding copies of the dataset
folders (PNG for both sets). Files from a mirror must have the registered file SHA-256, which
pooch checks. A mirror may also be a local folder or a ``file://`` URL; pooch has no downloader
for those, so a small one of ours copies the file and pooch verifies and places it as usual.

A file under its final name is always complete and verified: a failed check deletes the download
and raises :class:`ChecksumError`. Files already present and verified are not downloaded again.
Unlike earlier versions, an interrupted download is not resumed with an HTTP ``Range`` request
(pooch has no support for it): running the command again downloads that file from the start,
which costs little as no file is larger than about 1 MB.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import importlib.resources
import logging
import os
import re
import shutil
import sys
import tempfile
import urllib.parse
import urllib.request
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np

from .. import __version__
from .imageio import read_image
from .patches import list_images

if TYPE_CHECKING:
    import torch

__all__ = [
    "DATASET_NAMES",
    "DATA_ENV",
    "DEFAULT_IMAGE_NAMES",
    "MIRROR_ENV",
    "ChecksumError",
    "DownloadError",
    "add_cli",
    "centre_crop",
    "cmd_data",
    "data_root",
    "default_images",
    "download",
    "load_images",
    "resolve",
]

DATA_ENV = "SPLITCAM_DATA"
"""Environment variable naming the data root that dataset names are looked up in."""

MIRROR_ENV = "SPLITCAM_MIRROR"
"""Environment variable naming a mirror to download datasets from instead of the public sources."""

_DEFAULT_ROOT = "~/.cache/splitcam/datasets"
_CHUNK = 1 << 16
_USER_AGENT = f"splitcam/{__version__}"
_REGISTRY = "registry.tsv"


class DownloadError(OSError):
    """A dataset file could not be downloaded. The message names the file and what to do."""


class ChecksumError(DownloadError):
    """Downloaded data did not match its registered hash; the download has been deleted."""


@dataclass(frozen=True)
class _File:
    """One file of a downloadable dataset, as listed in the registry.

    Attributes:
        name: File name in the dataset folder, and on a mirror.
        source_path: Path of the published file inside the source repository.
        sha256: SHA-256 of the file as kept in the dataset folder.
        git_blob: Git blob id of the published file (``git hash-object``).
        pixels_sha256: SHA-256 of the decoded RGB uint8 pixel buffer; set where the published file
            is converted, as the converted file's bytes depend on the encoder.
    """

    name: str
    source_path: str
    sha256: str
    git_blob: str
    pixels_sha256: str | None = None

    @property
    def converted(self) -> bool:
        """Whether the published file has another format than the stored one."""
        return Path(self.source_path).suffix.lower() != Path(self.name).suffix.lower()


@dataclass(frozen=True)
class _Dataset:
    """A downloadable dataset: where it is published and what its files must hash to."""

    name: str
    description: str
    base_url: str
    files: tuple[_File, ...]


# Where each dataset is published: description, GitHub repository and the commit its files are
# pinned to. The files and their hashes are in registry.tsv; both were taken from the verified
# copies in the project's shared data folder (its MANIFEST.sha256 and SOURCES.tsv files).
_SOURCES: dict[str, tuple[str, str, str]] = {
    "kodak24": (
        "Kodak Lossless True Color Image Suite, 24 images of 768x512 (PNG)",
        "cszn/IRCNN",
        "d9dcd537bdac3ae5b753296cd675db8a303c8f72",
    ),
    "mcmaster": (
        "McMaster colour demosaicking set, 18 images of 500x500 (TIFF, stored as PNG)",
        "cszn/FFDNet",
        "e787f46df2f374ff3591186706229cb9a0591fea",
    ),
}

_REGISTRY_COLUMNS = ("dataset", "file", "source_path", "sha256", "git_blob", "pixels_sha256")
_SHA256 = re.compile(r"[0-9a-f]{64}")
_SHA1 = re.compile(r"[0-9a-f]{40}")


def _parse_registry(text: str) -> dict[str, _Dataset]:
    """The datasets described by the text of a registry file.

    The registry is our own tab-separated table rather than pooch's registry format, because
    pooch's holds one hash per file, and a converted file needs three (see the module
    documentation). Lines starting with ``#`` are comments.

    Args:
        text: Contents of a registry file; columns as in :data:`_REGISTRY_COLUMNS`.

    Returns:
        The datasets of :data:`_SOURCES`, in that order, with their files in registry order.

    Raises:
        RuntimeError: The table is malformed: wrong columns, an unknown dataset, a malformed
            hash, a repeated file, a converted file without pixel hash, or a dataset with no file.
    """
    lines = [line for line in text.splitlines() if line.strip() and not line.startswith("#")]
    reader = csv.DictReader(lines, delimiter="\t")
    if tuple(reader.fieldnames or ()) != _REGISTRY_COLUMNS:
        raise RuntimeError(
            f"dataset registry: expected the columns {', '.join(_REGISTRY_COLUMNS)}, "
            f"got {', '.join(reader.fieldnames or ())}"
        )
    files: dict[str, dict[str, _File]] = {name: {} for name in _SOURCES}
    for row in reader:
        label = f"{row['dataset']}/{row['file']}"
        if None in row or None in row.values():
            raise RuntimeError(f"dataset registry: row {label} does not have six columns")
        pixels = None if row["pixels_sha256"] == "-" else row["pixels_sha256"]
        entry = _File(row["file"], row["source_path"], row["sha256"], row["git_blob"], pixels)
        if row["dataset"] not in files:
            raise RuntimeError(f"dataset registry: unknown dataset in row {label}")
        if entry.name in files[row["dataset"]]:
            raise RuntimeError(f"dataset registry: {label} is listed twice")
        if not (
            _SHA256.fullmatch(entry.sha256)
            and _SHA1.fullmatch(entry.git_blob)
            and (pixels is None or _SHA256.fullmatch(pixels))
        ):
            raise RuntimeError(f"dataset registry: malformed hash in row {label}")
        if entry.converted and pixels is None:
            # Without it a converted file could not be verified at all.
            raise RuntimeError(f"dataset registry: {label} is converted but has no pixel hash")
        files[row["dataset"]][entry.name] = entry
    empty = [name for name, entries in files.items() if not entries]
    if empty:
        raise RuntimeError(f"dataset registry: no files listed for {', '.join(empty)}")
    return {
        name: _Dataset(
            name,
            description,
            f"https://raw.githubusercontent.com/{repository}/{commit}/",
            tuple(files[name].values()),
        )
        for name, (description, repository, commit) in _SOURCES.items()
    }


def _read_registry() -> dict[str, _Dataset]:
    """The datasets of the registry file shipped in this package (see :func:`_parse_registry`)."""
    resource = importlib.resources.files(__package__).joinpath(_REGISTRY)
    return _parse_registry(resource.read_text(encoding="utf-8"))


_DATASETS: dict[str, _Dataset] = _read_registry()

DATASET_NAMES: tuple[str, ...] = tuple(_DATASETS)
"""Names of the datasets :func:`download` can fetch and :func:`resolve` looks up by name."""


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


def data_root(root: str | os.PathLike[str] | None = None) -> Path:
    """The folder dataset names are looked up in.

    Args:
        root: Use this folder. Default: ``$SPLITCAM_DATA`` if set and not empty, else
            ``~/.cache/splitcam/datasets``.

    Returns:
        The folder, with ``~`` expanded. It need not exist.
    """
    if root is None:
        root = os.environ.get(DATA_ENV) or _DEFAULT_ROOT
    return Path(root).expanduser()


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
        root: Data root for dataset names; see :func:`data_root`.

    Returns:
        ``(name, path)`` pairs sorted by name, where the name is the file name without its suffix.
        Only files directly inside the folder with one of the suffixes in
        :data:`splitcam.data.imageio.IMAGE_SUFFIXES` count; hidden files are ignored.

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
            if spec in _DATASETS:
                raise FileNotFoundError(
                    f"dataset '{spec}' not found in {where}: download it with "
                    f"`splitcam data download {spec} --to DIR` and set {DATA_ENV}=DIR, "
                    f"or set {DATA_ENV} to a folder that has a '{spec}' subfolder"
                )
            raise FileNotFoundError(
                f"'{spec}' is neither a folder nor a dataset in {where}; give a folder of "
                f"images or one of the datasets {', '.join(DATASET_NAMES)}"
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
        root: Data root for dataset names; see :func:`data_root`.

    Returns:
        ``(name, image)`` pairs sorted by name; each image is a float32 tensor in [0, 1]
        (8-bit files divided by 255, 16-bit files by 65535).

    Shape:
        image: ``(3, H, W)``.

    Raises:
        FileNotFoundError: See :func:`resolve`.
        splitcam.data.imageio.ImageReadError: A file is not a readable colour image.
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
    (451x300), coffee (600x400), hubble_deep_field (1000x872), immunohistochemistry (512x512),
    motorcycle_left (741x500), retina (1411x1411) and rocket (640x427) (sizes as WxH). Greyscale,
    synthetic and RGBA images are not included.

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


# ---------------------------------------------------------------------------------------------
# Downloading


def _git_blob_id(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def _pixels_sha256(source: str | os.PathLike[str] | BinaryIO) -> str:
    from PIL import Image

    with Image.open(source) as im:
        return hashlib.sha256(np.asarray(im.convert("RGB"), np.uint8).tobytes()).hexdigest()


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def _is_verified(path: Path, entry: _File) -> bool:
    """Whether an existing dataset file has the expected content.

    pooch would skip a present file whose SHA-256 matches by itself, but it cannot accept a
    McMaster PNG that another encoder wrote with the same pixels, and for files converted on
    download it has no hash of the stored file to check; so every file is checked here first.
    """
    if not path.is_file():
        return False
    if _file_sha256(path) == entry.sha256:
        return True
    if entry.pixels_sha256 is None:
        return False
    try:
        return _pixels_sha256(path) == entry.pixels_sha256
    except Exception:
        # Whatever the decoder says about a damaged file, the answer is "download it again".
        return False


def _mirror_base(mirror: str) -> str:
    """A mirror argument as a URL without a trailing slash; local folders become file:// URLs."""
    if "://" not in mirror:
        folder = Path(mirror).expanduser()
        if not folder.is_dir():
            raise ValueError(
                f"mirror '{mirror}' is neither a URL (http://, https://, file://) nor a folder"
            )
        return folder.resolve().as_uri()
    scheme = urllib.parse.urlsplit(mirror).scheme.lower()
    if scheme not in ("http", "https", "file"):
        raise ValueError(
            f"mirror '{mirror}' has the unsupported scheme '{scheme}://'; give an http://, "
            "https:// or file:// URL, or a folder"
        )
    return mirror.rstrip("/")


def _tqdm(**kwargs: Any) -> Any:
    from tqdm.auto import tqdm

    return tqdm(**kwargs)


@contextmanager
def _pooch_quiet() -> Iterator[None]:
    """Hold back pooch's log messages for the duration of a download.

    pooch logs every file it fetches to stderr at INFO level, even when no progress is wanted,
    and for a download without known hash (the McMaster TIFFs) it advises recording the file's
    SHA-256, which does not apply here: those are checked by git blob id and pixels. Our progress
    bars already show what is being fetched; warnings and errors still come through.

    A filter does this rather than the logger's level: pooch's logger is not registered with the
    logging module, so a change of level would not reset the answer it caches for INFO.
    """
    import pooch

    logger = pooch.get_logger()
    logger.addFilter(_warnings_only)
    try:
        yield
    finally:
        logger.removeFilter(_warnings_only)


def _warnings_only(record: logging.LogRecord) -> bool:
    return record.levelno >= logging.WARNING


def _copy_local(url: str, output_file: str, pooch: object) -> None:
    """A pooch downloader for ``file://`` URLs, which pooch has no downloader for.

    pooch passes a temporary file in the dataset folder as ``output_file`` and, once this returns,
    checks the copy's hash and moves it to its final name, exactly as for an HTTP download.

    Raises:
        OSError: The file cannot be read (e.g. it is missing from the mirror).
    """
    source = urllib.request.url2pathname(urllib.parse.urlsplit(url).path)
    shutil.copyfile(source, output_file)


def _http_error(exc: OSError) -> str:
    """What went wrong in a failed transfer, in words; HTTP errors by their status."""
    response = getattr(exc, "response", None)  # set on requests' HTTPError
    if response is not None and getattr(response, "status_code", None) is not None:
        return f"HTTP {response.status_code} {response.reason}"
    return str(exc) or type(exc).__name__


_POOCH_MISMATCH = re.compile(r"expected (?:sha256:)?([0-9a-f]{64}) but got ([0-9a-f]{64})")


def _retrieve(
    url: str,
    folder: Path,
    fname: str,
    known_hash: str | None,
    label: str,
    *,
    timeout: float,
    progress: bool,
    processor: Any = None,
) -> None:
    """Fetch ``url`` to ``folder / fname`` with :func:`pooch.retrieve`, translating its errors.

    Args:
        url: ``http(s)://`` or ``file://`` URL.
        folder: Folder to place the file in.
        fname: File name to place it under.
        known_hash: ``"sha256:<hex>"`` the downloaded bytes must have, or ``None`` where the
            processor verifies them.
        label: ``<dataset>/<file>``, for messages and the progress bar.
        timeout: Seconds to wait for the server on connecting and on each read.
        progress: Show a progress bar of the bytes received.
        processor: A pooch processor run on the downloaded file.

    Raises:
        ChecksumError: The downloaded bytes did not match ``known_hash`` (pooch has deleted them),
            or the processor found a mismatch.
        DownloadError: The transfer failed.
    """
    import pooch

    bar = None
    if url.startswith("file:"):
        downloader: Any = _copy_local
    else:
        if progress:
            # pooch fills in a bar object it is given; it tests whether it has one by the bar's
            # truth value, which tqdm makes `total > 0`, so the bar starts with a dummy total.
            bar = _tqdm(
                total=1, unit="B", unit_scale=True, unit_divisor=1024, desc=label, leave=False
            )
        downloader = pooch.HTTPDownloader(
            progressbar=bar if bar is not None else False,
            chunk_size=_CHUNK,
            timeout=timeout,
            headers={"User-Agent": _USER_AGENT},
        )
    try:
        pooch.retrieve(
            url, known_hash, fname=fname, path=folder, downloader=downloader, processor=processor
        )
    except DownloadError:
        raise  # from the processor: already says what is wrong
    except OSError as exc:
        # requests' exceptions are OSErrors too (including the ones that are also ValueErrors).
        hint = (
            "check the mirror folder"
            if downloader is _copy_local
            else "check the network connection (or the mirror address)"
        )
        raise DownloadError(
            f"downloading {label} from {url} failed: {_http_error(exc)}; {hint} and run the "
            "command again"
        ) from None
    except ValueError as exc:
        # pooch reports a hash mismatch as ValueError, after deleting the download; its message
        # names both hashes, which are picked out to keep ours short.
        found = _POOCH_MISMATCH.search(str(exc))
        detail = f"SHA-256 expected {found[1]}, got {found[2]}" if found else str(exc)
        raise ChecksumError(
            f"{label}: the data downloaded from {url} is not the expected file ({detail}); it "
            "was deleted. Run the command again; if this persists, the source has changed or the "
            "connection is altered"
        ) from None
    finally:
        if bar is not None:
            bar.close()  # pooch closes it only after a complete transfer


class _TiffToPng:
    """pooch processor: verify a downloaded McMaster TIFF and store its pixels as PNG.

    This is our code because pooch can check only plain digests of the downloaded file, while a
    published TIFF is pinned by its git blob id and the hash of its decoded pixels.

    Args:
        entry: The registry entry; ``entry.git_blob`` and ``entry.pixels_sha256`` are checked.
        final: Where the PNG goes; it is written to a temporary file beside it and renamed, so it
            appears complete or not at all.
        label: ``<dataset>/<file>``, for messages.
        url: The address the TIFF came from, for messages.
    """

    def __init__(self, entry: _File, final: Path, label: str, url: str) -> None:
        self.entry, self.final, self.label, self.url = entry, final, label, url

    def __call__(self, fname: str, action: str, pooch: object) -> str:
        """Check the file at ``fname`` and write the PNG; returns the PNG's path.

        Raises:
            ChecksumError: The bytes do not have the registered git blob id.
            DownloadError: The bytes are right but decode to other pixels here.
        """
        import io

        from PIL import Image

        data = Path(fname).read_bytes()
        blob = _git_blob_id(data)
        if blob != self.entry.git_blob:
            raise ChecksumError(
                f"{self.label}: the data downloaded from {self.url} is not the expected file "
                f"(git blob id expected {self.entry.git_blob}, got {blob}); it was deleted. Run "
                "the command again; if this persists, the source has changed or the connection "
                "is altered"
            )
        try:
            with Image.open(io.BytesIO(data)) as im:
                pixels = np.asarray(im.convert("RGB"), np.uint8)
        except Exception as exc:
            raise DownloadError(
                f"{self.label}: the downloaded file is correct but the image library (Pillow) "
                f"cannot decode it here: {exc}"
            ) from None
        actual = hashlib.sha256(pixels.tobytes()).hexdigest()
        if actual != self.entry.pixels_sha256:
            # The bytes matched their git blob id, so only the decoder can disagree.
            raise DownloadError(
                f"{self.label}: the downloaded file is correct but decodes to different pixels "
                f"here (pixel SHA-256 expected {self.entry.pixels_sha256}, got {actual}); the "
                "image library (Pillow) may decode TIFF differently on this machine"
            )
        fd, tmp = tempfile.mkstemp(
            dir=self.final.parent, prefix=f".{self.final.name}.", suffix=".tmp"
        )
        try:
            with os.fdopen(fd, "wb") as fh:
                Image.fromarray(pixels).save(fh, format="PNG", optimize=True)
            os.replace(tmp, self.final)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return str(self.final)


def _install(
    dataset: _Dataset,
    entry: _File,
    folder: Path,
    mirror: str | None,
    timeout: float,
    progress: bool,
) -> None:
    """Download, verify and (if needed) convert one file to ``folder / entry.name``."""
    label = f"{dataset.name}/{entry.name}"
    options: dict[str, Any] = {"timeout": timeout, "progress": progress}
    if mirror is not None:
        url = f"{mirror}/{urllib.parse.quote(dataset.name)}/{urllib.parse.quote(entry.name)}"
        _retrieve(url, folder, entry.name, f"sha256:{entry.sha256}", label, **options)
        return
    url = dataset.base_url + urllib.parse.quote(entry.source_path)
    if not entry.converted:
        _retrieve(url, folder, entry.name, f"sha256:{entry.sha256}", label, **options)
        return
    # pooch keeps what it downloads under the name it is given, and a TIFF beside the PNGs would
    # be read as a second image of the set; a hidden scratch folder (on the same file system, so
    # the PNG's final rename stays atomic) keeps it out of sight and goes away in any case.
    with tempfile.TemporaryDirectory(dir=folder, prefix=".download-") as scratch:
        _retrieve(
            url,
            Path(scratch),
            Path(entry.source_path).name,
            None,
            label,
            processor=_TiffToPng(entry, folder / entry.name, label, url),
            **options,
        )


def download(
    names: str | Iterable[str],
    to: str | os.PathLike[str] | None = None,
    *,
    mirror: str | None = None,
    progress: bool = True,
    timeout: float = 30,
    files: Iterable[str] | None = None,
) -> list[Path]:
    """Download datasets into ``<to>/<dataset>``, verifying every file.

    See the module documentation for the sources and the checks. Files already present and
    verified are skipped; a file whose download was interrupted is downloaded again in full.

    Args:
        names: Dataset names (see :data:`DATASET_NAMES`), or one name.
        to: Data root to download into. Default: :func:`data_root` (``$SPLITCAM_DATA`` or
            ``~/.cache/splitcam/datasets``).
        mirror: Base URL (or local folder) of a mirror serving ``<dataset>/<file name>``.
            Default: ``$SPLITCAM_MIRROR`` if set, else the public sources.
        progress: Show progress bars (on stderr).
        timeout: Seconds to wait for the server on connecting and on each read.
        files: Only these file names (e.g. ``["kodim01.png"]``); default all files.

    Returns:
        The paths of the requested files, all present and verified.

    Raises:
        ValueError: An unknown dataset or file name, or an invalid mirror.
        ChecksumError: Downloaded data did not match its hash (the download is deleted).
        DownloadError: A network failure; nothing is left under the file's final name.
    """
    wanted = [names] if isinstance(names, str) else list(names)
    unknown = [n for n in wanted if n not in _DATASETS]
    if unknown:
        raise ValueError(
            f"unknown dataset(s) {', '.join(unknown)}; downloadable datasets: "
            f"{', '.join(DATASET_NAMES)}"
        )
    if not wanted:
        raise ValueError(f"no dataset given; choose from {', '.join(DATASET_NAMES)}")
    datasets = [_DATASETS[n] for n in dict.fromkeys(wanted)]
    jobs = [(d, f) for d in datasets for f in d.files]
    if files is not None:
        selected = set(files)
        missing = selected - {f.name for _, f in jobs}
        if missing:
            raise ValueError(
                f"file(s) {', '.join(sorted(missing))} are not in dataset(s) "
                f"{', '.join(d.name for d in datasets)}"
            )
        jobs = [(d, f) for d, f in jobs if f.name in selected]

    mirror = mirror if mirror is not None else os.environ.get(MIRROR_ENV) or None
    base = _mirror_base(mirror) if mirror else None
    root = data_root(to)
    paths = []
    bar = _tqdm(total=len(jobs), unit="file", desc="download", disable=not progress)
    try:
        with _pooch_quiet():
            for dataset, entry in jobs:
                folder = root / dataset.name
                folder.mkdir(parents=True, exist_ok=True)
                final = folder / entry.name
                bar.set_postfix_str(f"{dataset.name}/{entry.name}", refresh=False)
                if not _is_verified(final, entry):
                    if final.exists() and progress:
                        bar.write(
                            f"{final}: content does not match its checksum; downloading again",
                            file=sys.stderr,
                        )
                    _install(dataset, entry, folder, base, timeout, progress)
                paths.append(final)
                bar.update(1)
    finally:
        bar.close()
    return paths


# ---------------------------------------------------------------------------------------------
# Command line: `splitcam data ...`


def add_cli(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``data`` command (``data download``, ``data list``) to a subparsers object.

    Args:
        subparsers: The object returned by ``ArgumentParser.add_subparsers()``.

    Returns:
        The ``data`` parser; its handler is :func:`cmd_data` (``set_defaults(handler=...)``).
    """
    parser = subparsers.add_parser(
        "data",
        help="download the test datasets (Kodak24, McMaster) or list them",
        description="`splitcam data download kodak24 mcmaster --to DIR` downloads the datasets "
        "into DIR/<name>, verifying every file; use them by name with SPLITCAM_DATA=DIR. "
        "`splitcam data list` shows which are present.",
    )
    actions = parser.add_subparsers(dest="data_action", metavar="ACTION", required=True)
    p = actions.add_parser(
        "download",
        help="download and verify datasets",
        description="Downloads from the public sources pinned to a commit (or from a mirror) and "
        "checks every file against the hashes in the package's dataset registry. Files already "
        "present and verified are skipped; a file whose download was interrupted is downloaded "
        "again when the command is run again.",
    )
    p.add_argument(
        "names",
        nargs="*",
        metavar="DATASET",
        help=f"datasets to download (default: all of {', '.join(DATASET_NAMES)})",
    )
    p.add_argument(
        "--to",
        metavar="DIR",
        help=f"data root; each dataset goes to DIR/<name> (default: ${DATA_ENV} or "
        f"{_DEFAULT_ROOT})",
    )
    p.add_argument(
        "--mirror",
        metavar="URL",
        help="download <URL>/<dataset>/<file> instead of the public sources; also "
        f"a local folder (default: ${MIRROR_ENV} if set)",
    )
    p.add_argument(
        "--timeout", type=float, default=30.0, help="network timeout in seconds (default: 30)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p = actions.add_parser(
        "list",
        help="list the datasets and whether they are present",
        description="Counts the files of each dataset under the data root.",
    )
    p.add_argument(
        "--root", metavar="DIR", help=f"data root (default: ${DATA_ENV} or {_DEFAULT_ROOT})"
    )
    parser.set_defaults(handler=cmd_data)
    return parser


def cmd_data(args: argparse.Namespace) -> int:
    """Run ``splitcam data download`` or ``splitcam data list``; returns the exit status."""
    if args.data_action == "download":
        names = args.names or list(DATASET_NAMES)
        paths = download(
            names, args.to, mirror=args.mirror, progress=not args.quiet, timeout=args.timeout
        )
        root = data_root(args.to)
        for name in dict.fromkeys(names):
            count = sum(1 for p in paths if p.parent.name == name)
            print(f"{name}: {count} images in {root / name}")
        if root.resolve() != data_root().resolve():
            print(f"use them by name with {DATA_ENV}={root}")
        return 0
    root = data_root(args.root)
    print(f"data root: {root}")
    for dataset in _DATASETS.values():
        folder = root / dataset.name
        present = sum(1 for f in dataset.files if (folder / f.name).is_file())
        state = (
            "complete"
            if present == len(dataset.files)
            else f"{present}/{len(dataset.files)} files"
            if present
            else "not downloaded"
        )
        print(f"  {dataset.name:10s} {state:16s} {dataset.description}")
    return 0
