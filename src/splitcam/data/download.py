"""Downloading the test sets, verifying every file.

Every file is fetched from the public address the dataset is published at, pinned to a commit,
and checked against the hashes in the registry (:mod:`splitcam.data.registry`). The transfers go
through `pooch <https://www.fatiando.org/pooch>`_ (:func:`pooch.retrieve`), which downloads to a
temporary file in the dataset folder, checks its SHA-256 and only then moves it to its final name.

- **Kodak24** (``kodim01.png`` ... ``kodim24.png``): GitHub ``cszn/IRCNN``,
  ``testsets/Set24/kodimNN.png``. The files are used as published, so pooch checks the downloaded
  bytes against the registered SHA-256. The registered git blob id describes the same bytes (the
  tests check that), so it needs no second check.
- **McMaster** (``01.png`` ... ``18.png``): GitHub ``cszn/FFDNet``, ``testsets/McMaster/N.tif``.
  The published files are TIFFs; ``N.tif`` becomes ``NN.png``. pooch cannot verify these: their
  registered hashes are a git blob id (``sha1(b"blob <size>\\0" + bytes)``, as
  ``git hash-object`` prints), which is no plain digest of the file, and a hash of the decoded
  pixels, ``sha256(np.asarray(Image.open(f).convert("RGB"), np.uint8).tobytes())``. So pooch
  downloads the TIFF into a scratch folder without a hash, and a pooch processor of ours
  (:class:`_TiffToPng`) checks both hashes and writes the pixels as PNG. The pixel hash is what
  makes the PNG trustworthy: a PNG encoder other than the one that made the reference files may
  write different bytes for the same pixels, so an existing McMaster PNG counts as verified if
  either its file SHA-256 or its pixel hash matches.

A mirror (``mirror=`` or the ``SPLITCAM_MIRROR`` environment variable) replaces the public
addresses by ``<mirror>/<dataset>/<file name>``, i.e. a server holding copies of the dataset
folders (PNG for both sets). Files from a mirror must have the registered file SHA-256, which
pooch checks. A mirror may also be a local folder or a ``file://`` URL; pooch has no downloader
for those, so a small one of ours copies the file and pooch verifies and places it as usual.

A file under its final name is always complete and verified: a failed check deletes the download
and raises :class:`ChecksumError`. Files already present and verified are not downloaded again.
An interrupted download is not resumed with an HTTP ``Range`` request (pooch has no support for
it): running the command again downloads that file from the start, which costs little as no file
is larger than about 1 MB.

This module imports only the standard library and :mod:`splitcam.data.registry` at import;
pooch, Pillow, numpy and tqdm are imported when a download needs them.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import shutil
import sys
import tempfile
import urllib.parse
import urllib.request
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO

from .. import __version__
from ..io import atomic_path
from .registry import MIRROR_ENV, Dataset, DatasetFile, data_root, dataset_names, datasets

__all__ = ["ChecksumError", "DownloadError", "download"]

_CHUNK = 1 << 16
_USER_AGENT = f"splitcam/{__version__}"


class DownloadError(OSError):
    """A dataset file could not be downloaded. The message names the file and what to do."""


class ChecksumError(DownloadError):
    """Downloaded data did not match its registered hash; the download has been deleted."""


def _git_blob_id(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def _pixels_sha256(source: str | os.PathLike[str] | BinaryIO) -> str:
    """SHA-256 of an image's decoded RGB uint8 pixel buffer (the registry's ``pixels_sha256``)."""
    import numpy as np
    from PIL import Image

    with Image.open(source) as im:
        return hashlib.sha256(np.asarray(im.convert("RGB"), np.uint8).tobytes()).hexdigest()


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def dataset_state(folder: Path, files: list[DatasetFile] | tuple[DatasetFile, ...]) -> str:
    """What a dataset's folder holds, in words: ``complete`` when every file is there with
    the expected content, else how many are there and how many of those are damaged, or
    ``not downloaded``."""
    present = [f for f in files if (folder / f.name).is_file()]
    damaged = [f for f in present if not _is_verified(folder / f.name, f)]
    if not present:
        return "not downloaded"
    if len(present) == len(files) and not damaged:
        return "complete"
    text = f"{len(present)}/{len(files)} files"
    return f"{text}, {len(damaged)} damaged" if damaged else text


def _is_verified(path: Path, entry: DatasetFile) -> bool:
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

    def __init__(self, entry: DatasetFile, final: Path, label: str, url: str) -> None:
        self.entry, self.final, self.label, self.url = entry, final, label, url

    def __call__(self, fname: str, action: str, pooch: object) -> str:
        """Check the file at ``fname`` and write the PNG; returns the PNG's path.

        Raises:
            ChecksumError: The bytes do not have the registered git blob id.
            DownloadError: The bytes are right but decode to other pixels here.
        """
        import io

        import numpy as np
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
        with atomic_path(self.final) as tmp:
            Image.fromarray(pixels).save(tmp, format="PNG", optimize=True)
        return str(self.final)


def _install(
    dataset: Dataset,
    entry: DatasetFile,
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
        names: Dataset names (see :func:`~splitcam.data.registry.dataset_names`), or one name.
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
    known = datasets()
    unknown = [n for n in wanted if n not in known]
    if unknown:
        raise ValueError(
            f"unknown dataset(s) {', '.join(unknown)}; downloadable datasets: "
            f"{', '.join(dataset_names())}"
        )
    if not wanted:
        raise ValueError(f"no dataset given; choose from {', '.join(dataset_names())}")
    chosen = [known[n] for n in dict.fromkeys(wanted)]
    jobs = [(d, f) for d in chosen for f in d.files]
    if files is not None:
        selected = set(files)
        missing = selected - {f.name for _, f in jobs}
        if missing:
            raise ValueError(
                f"file(s) {', '.join(sorted(missing))} are not in dataset(s) "
                f"{', '.join(d.name for d in chosen)}"
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
