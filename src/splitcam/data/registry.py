"""The registry of downloadable test sets, and the data root that dataset names are looked up in.

This module imports only the standard library, so the ``splitcam`` command can build its parser
(dataset names, default folders) without importing numpy or torch. The registry file
``registry.tsv`` that ships beside this module is read on first use (:func:`datasets`), not at
import.

Each dataset is published in a GitHub repository, pinned to a commit (:data:`_SOURCES`); the
registry lists its files and the hashes they must have. :mod:`splitcam.data.download` fetches and
verifies them; :mod:`splitcam.data.testsets` finds them under :func:`data_root`.
"""

from __future__ import annotations

import csv
import functools
import importlib.resources
import os
import re
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "DATA_ENV",
    "DEFAULT_ROOT",
    "MIRROR_ENV",
    "REGISTRY_COLUMNS",
    "Dataset",
    "DatasetFile",
    "data_root",
    "dataset_folder",
    "dataset_names",
    "datasets",
    "parse_registry",
    "portable_path",
    "training_folder",
]

DATA_ENV = "SPLITCAM_DATA"
"""Environment variable naming the data root that dataset names are looked up in."""

MIRROR_ENV = "SPLITCAM_MIRROR"
"""Environment variable naming a mirror to download datasets from instead of the public sources."""

DEFAULT_ROOT = "~/.cache/splitcam/datasets"
"""The data root where :data:`DATA_ENV` is unset or empty (``~`` is expanded by
:func:`data_root`)."""

REGISTRY_COLUMNS = ("dataset", "file", "source_path", "sha256", "git_blob", "pixels_sha256")
"""The columns of the registry file, in order."""

_REGISTRY = "registry.tsv"

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
    "train": (
        "training photos: 432 BSDS500 photos of 481x321 (its 200 train, 200 test and 32 of its "
        "val photos; JPEG), what the shipped networks trained on",
        "Sisso16/ssn_pytorch",
        "c4f9ac8c43397cbacbf2e2ba1505efafa769435d",
    ),
}

_SHA256 = re.compile(r"[0-9a-f]{64}")
_SHA1 = re.compile(r"[0-9a-f]{40}")


@dataclass(frozen=True)
class DatasetFile:
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
class Dataset:
    """A downloadable dataset: where it is published and what its files must hash to.

    Attributes:
        name: Dataset name, also the name of its folder under the data root.
        description: One line for ``splitcam data list``.
        base_url: URL the files' ``source_path`` is appended to (ends with ``/``).
        files: The files, in registry order.
    """

    name: str
    description: str
    base_url: str
    files: tuple[DatasetFile, ...]


def parse_registry(text: str) -> dict[str, Dataset]:
    """The datasets described by the text of a registry file.

    The registry is a tab-separated table of our own rather than pooch's registry format, because
    pooch's holds one hash per file, and a converted file needs three (see
    :mod:`splitcam.data.download`). Lines starting with ``#`` are comments.

    Args:
        text: Contents of a registry file; columns as in :data:`REGISTRY_COLUMNS`.

    Returns:
        The datasets of :data:`_SOURCES`, in that order, with their files in registry order.

    Raises:
        RuntimeError: The table is malformed: wrong columns, an unknown dataset, a malformed
            hash, a repeated file, a converted file without pixel hash, or a dataset with no file.
    """
    lines = [line for line in text.splitlines() if line.strip() and not line.startswith("#")]
    reader = csv.DictReader(lines, delimiter="\t")
    if tuple(reader.fieldnames or ()) != REGISTRY_COLUMNS:
        raise RuntimeError(
            f"dataset registry: expected the columns {', '.join(REGISTRY_COLUMNS)}, "
            f"got {', '.join(reader.fieldnames or ())}"
        )
    files: dict[str, dict[str, DatasetFile]] = {name: {} for name in _SOURCES}
    for row in reader:
        label = f"{row['dataset']}/{row['file']}"
        if None in row or None in row.values():
            raise RuntimeError(f"dataset registry: row {label} does not have six columns")
        pixels = None if row["pixels_sha256"] == "-" else row["pixels_sha256"]
        entry = DatasetFile(row["file"], row["source_path"], row["sha256"], row["git_blob"], pixels)
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
        name: Dataset(
            name,
            description,
            f"https://raw.githubusercontent.com/{repository}/{commit}/",
            tuple(files[name].values()),
        )
        for name, (description, repository, commit) in _SOURCES.items()
    }


@functools.cache
def datasets() -> dict[str, Dataset]:
    """The downloadable datasets, by name, from the registry file shipped in this package.

    The file is read on the first call; every call returns the same dictionary, which callers
    must not modify.

    Raises:
        RuntimeError: The shipped registry is malformed (see :func:`parse_registry`).
    """
    resource = importlib.resources.files(__package__).joinpath(_REGISTRY)
    return parse_registry(resource.read_text(encoding="utf-8"))


def dataset_names() -> tuple[str, ...]:
    """Names of the datasets that can be downloaded and looked up by name (``kodak24``,
    ``mcmaster``, ``train``)."""
    return tuple(datasets())


TRAINING_FOLDER = "train"
"""The folder of training photos under the data root (the 432 BSDS500 photos the shipped networks
trained on; ``splitcam data download train`` fetches them there; docs/commands.md)."""


def training_folder(root: str | os.PathLike[str] | None = None) -> Path:
    """The training photos' folder: :data:`TRAINING_FOLDER` under :func:`data_root`, what the
    studies and scripts read by default (``SPLITCAM_DATA=DIR`` with the photos in ``DIR/train``).
    It need not exist."""
    return data_root(root) / TRAINING_FOLDER


def dataset_folder(spec: str | os.PathLike[str]) -> Path:
    """A folder of images named by path, or by the name of a downloadable dataset (``train``,
    ``kodak24``, ...) that is not a folder here: then its folder under :func:`data_root`.

    Raises:
        FileNotFoundError: A dataset's name whose folder is not downloaded; the message gives
            the download command.
    """
    path = Path(spec)
    if path.exists() or str(spec) not in dataset_names():
        return path
    folder = data_root() / str(spec)
    if not folder.is_dir():
        raise FileNotFoundError(
            f"dataset {spec} is not downloaded to {folder}: splitcam data download {spec} (or set "
            f"{DATA_ENV} to the folder that holds it)"
        )
    return folder


def data_root(root: str | os.PathLike[str] | None = None) -> Path:
    """The folder dataset names are looked up in.

    Args:
        root: Use this folder. Default: ``$SPLITCAM_DATA`` if set and not empty, else
            :data:`DEFAULT_ROOT` (``~/.cache/splitcam/datasets``).

    Returns:
        The folder, with ``~`` expanded. It need not exist.
    """
    if root is None:
        root = os.environ.get(DATA_ENV) or DEFAULT_ROOT
    return Path(root).expanduser()


def portable_path(path: str | os.PathLike[str]) -> str:
    """How a data or run path is written into a file that leaves this machine (a shipped
    model's settings, the source of shipped statistics): relative to the data root where it
    lies under it (the training photos are ``train``, which :func:`dataset_folder` resolves
    on any machine), else relative to the working folder where it lies under that, else its
    last component. Relative paths are kept as given; so are empty ones.
    """
    text = str(path)
    given = Path(text)
    if not text or not given.is_absolute():
        return text
    resolved = given.resolve()
    for base in (data_root(), Path.cwd()):
        try:
            return resolved.relative_to(base.resolve()).as_posix() or "."
        except ValueError:
            continue
    return given.name
