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
Every file is fetched from the public address the dataset is published at, pinned to a commit,
and checked against hashes embedded in this module (:data:`_DATASETS`):

- **Kodak24** (``kodim01.png`` ... ``kodim24.png``): GitHub ``cszn/IRCNN``,
  ``testsets/Set24/kodimNN.png``. The files are used as published, so the downloaded bytes must
  have the embedded SHA-256 and git blob id.
- **McMaster** (``01.png`` ... ``18.png``): GitHub ``cszn/FFDNet``, ``testsets/McMaster/N.tif``.
  The published files are TIFFs; ``N.tif`` becomes ``NN.png``. The TIFF bytes must have the
  embedded git blob id (``sha1(b"blob <size>\\0" + bytes)``, as ``git hash-object`` prints), and
  the decoded pixels must have the embedded pixel hash,
  ``sha256(np.asarray(Image.open(f).convert("RGB"), np.uint8).tobytes())``. The pixels are then
  saved as PNG. The pixel hash is what makes the PNG trustworthy: a PNG encoder other than the one
  that made the reference files may write different bytes for the same pixels, so an existing
  McMaster PNG counts as verified if either its file SHA-256 or its pixel hash matches.

A mirror (``mirror=`` or the ``SPLITCAM_MIRROR`` environment variable) replaces the public
addresses by ``<mirror>/<dataset>/<file name>``, i.e. a server holding copies of the dataset
folders (PNG for both sets). Files from a mirror must have the embedded file SHA-256. A mirror
may also be a local folder or a ``file://`` URL.

Each file is written to ``<file>.part`` in the dataset folder, verified, and only then renamed to
its final name, so a file under its final name is always complete and verified. A ``.part`` left
by an interrupted download is continued with an HTTP ``Range`` request where the server supports
it. Files already present and verified are not downloaded again.
"""

from __future__ import annotations

import argparse
import hashlib
import http.client
import os
import re
import sys
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, NoReturn

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
_USER_AGENT = f"splitcam/{__version__} (+python-urllib)"


class DownloadError(OSError):
    """A dataset file could not be downloaded. The message names the file and what to do."""


class ChecksumError(DownloadError):
    """Downloaded data did not match its embedded hash; the partial file has been deleted."""


@dataclass(frozen=True)
class _File:
    """One file of a downloadable dataset.

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


def _github(repository: str, commit: str) -> str:
    return f"https://raw.githubusercontent.com/{repository}/{commit}/"


# The hashes below were computed from the verified copies in the project's shared data folder:
# `sha256` is the SHA-256 of each file (listed in its MANIFEST.sha256), `git_blob` is the blob id
# of the published file (listed in its SOURCES.tsv and, for Kodak24, recomputed from the bytes),
# and `pixels_sha256` is the SHA-256 of the decoded RGB uint8 pixels of each McMaster PNG, which
# equal those of the published TIFF.
_KODAK24 = _Dataset(
    name="kodak24",
    description="Kodak Lossless True Color Image Suite, 24 images of 768x512 (PNG)",
    base_url=_github("cszn/IRCNN", "d9dcd537bdac3ae5b753296cd675db8a303c8f72"),
    files=(
        _File("kodim01.png", "testsets/Set24/kodim01.png",
              "a56e27cbf5f843c048b6af1d6e090760e9c92fadba88b7dee0205918a37523bd",
              "14317f0301e7610026f61e78192ade6089025115"),
        _File("kodim02.png", "testsets/Set24/kodim02.png",
              "4f4b74a79237e311d72cad958237b5f7088d8bce1c82305ebefe1a70e3022dfd",
              "20c720617e089f6854b313e712fc13354ecc707b"),
        _File("kodim03.png", "testsets/Set24/kodim03.png",
              "e25ca1ff2f0c0cb5fdfd5f9b0a0bb21ac4c3de3c84a67f35b09a85d3306249db",
              "d57e8bd2ceb82ed2153c776b283a5a15f444f312"),
        _File("kodim04.png", "testsets/Set24/kodim04.png",
              "e3b946107c5d3441c022f678d0c3caf1e224d81b1604ba840a4f88e562de61aa",
              "de0991c65ee41d9a7507ef1b6136b23a5f487944"),
        _File("kodim05.png", "testsets/Set24/kodim05.png",
              "10349e963c5c813d327852f82c1795fa4148d69fedffc4c589bee458e3ac3d53",
              "400e4cfc91db5358a9b3cae17386e23a68e31734"),
        _File("kodim06.png", "testsets/Set24/kodim06.png",
              "363510303b715d4cbc384e1ce227e466b613a09e1b71ae985882bf8e7fbd9b18",
              "949d1e29842184e8b7764b22049dd99e4c40f08b"),
        _File("kodim07.png", "testsets/Set24/kodim07.png",
              "b77d3f006f42414bb242222e0482e750c0fb9e5ee8d4bed2f6f11c5605fe54a4",
              "d04374d24676b2d4b3456637f573b53313bd1035"),
        _File("kodim08.png", "testsets/Set24/kodim08.png",
              "ba23983c76b4832ee0e8af0592664756841a16779acd69f792e268fb6d13d6e7",
              "d628801b140bdcc92224c1279ac309dec13e3534"),
        _File("kodim09.png", "testsets/Set24/kodim09.png",
              "6a4361c2fc194feb4edaa9f9a4a0620fb9943e460ac7fdf037fb0f6dd6607a7d",
              "1d471889b4c565de18c07c1585996bbcec590beb"),
        _File("kodim10.png", "testsets/Set24/kodim10.png",
              "9dfb70f5867c29ff9ed6313683f19b3d867849e40fbc0c4c54a4a89df341cf23",
              "2e4b18b6febe51e70afb5ff365ddaebc69fe9e7f"),
        _File("kodim11.png", "testsets/Set24/kodim11.png",
              "7936814b58b5387fce2e4e2488b4ec830dadd95fa9520f358ddb30990b50f2b6",
              "3c66526c04bab5a4e87ea14adf1fa61b237a1391"),
        _File("kodim12.png", "testsets/Set24/kodim12.png",
              "d78c37c2f04f23761ed2367dd77e2db584ddd4c3950833fecf89f199a8126980",
              "55db018bb61e6498517fff6dd92d0629d73718f1"),
        _File("kodim13.png", "testsets/Set24/kodim13.png",
              "bc34a3ce58dea09dce1704c997171602de90cb34d0c8503a988b77f473d39b08",
              "b35c9d39b44b33140512bda5679c4f3381ce694f"),
        _File("kodim14.png", "testsets/Set24/kodim14.png",
              "55a94550ff18f3246c4074fd32b77b0c74447c26b6ad274d564d999c0450ba6e",
              "e7b328346a6e0261705dc7b6d463df9bcc5154f5"),
        _File("kodim15.png", "testsets/Set24/kodim15.png",
              "7538cbb80cb9103606c48b806eae57d56c885c7f90b9b3be70a41160f9cbb683",
              "9c5eacf7682c914d4269602a1c75aa8f57cc0150"),
        _File("kodim16.png", "testsets/Set24/kodim16.png",
              "a89c7268ccd4718ba424a99fc4643c572cf692ca6eae887185ceb4e9f11d2e54",
              "54b0d0dec8178078159f32ccce5d54206c85a9b0"),
        _File("kodim17.png", "testsets/Set24/kodim17.png",
              "37afcc89fbdcb76d9518e04b2fc011027e2f4cd14b3b2f83cefd721641a47c5b",
              "5e4583e820482f6285fda86a2b2e117a1b667efb"),
        _File("kodim18.png", "testsets/Set24/kodim18.png",
              "1a9258c365988961d87a0598725b609139c303ad48a5aad6c503c3b1a87849aa",
              "48097fcfa7dca834345302195b696aa987c5f3db"),
        _File("kodim19.png", "testsets/Set24/kodim19.png",
              "b7450b264b1b0a411390d8931b112c27905a992520fc90569dc4b920aa32bbdc",
              "e359a32a4833d25c903a6be72c3a8434cbc68a52"),
        _File("kodim20.png", "testsets/Set24/kodim20.png",
              "3b46c71e3b92a563820ba32936be8330c586c41f938efd94be938386aae4328a",
              "86e2837b0bfabe3fa4f653e18339050f16a0642a"),
        _File("kodim21.png", "testsets/Set24/kodim21.png",
              "ac958597c82073f6bb65129c68f72b651db5b9efd82e11547d07350214bc268b",
              "ccd4c3f69aacfd9d93505c763309db2caf102d14"),
        _File("kodim22.png", "testsets/Set24/kodim22.png",
              "1cee58eb1f2d9c7ebb254d208a03c783ce6cf2c4d8c2cf45e235dd23b4ce1b29",
              "52bcd47b74f11e36d0a0ffe103171ab36a0481de"),
        _File("kodim23.png", "testsets/Set24/kodim23.png",
              "e3111a2fd4da24af15d6459ef9eacfe54106b38e27b4a21821b75c3f5d2d5baf",
              "ff22e837372943b79e2b61dec9c16fecb5d0c31f"),
        _File("kodim24.png", "testsets/Set24/kodim24.png",
              "1071c68372cc5a01435c2c225a5cf7d4bb803846ec08bb6b3d6721b156d7cb96",
              "85bd64fb8ac6adb421ed4746bc57b80f7c785854"),
    ),
)

_MCMASTER = _Dataset(
    name="mcmaster",
    description="McMaster colour demosaicking set, 18 images of 500x500 (TIFF, stored as PNG)",
    base_url=_github("cszn/FFDNet", "e787f46df2f374ff3591186706229cb9a0591fea"),
    files=(
        _File("01.png", "testsets/McMaster/1.tif",
              "d94545a6290cf0d5740b7aee9bd74a4ff531c828fcc18a4297e67952f01e194b",
              "5bca1b4b1876f1651f481d4edbeba6bb735babd0",
              "70d880a0b4d3699134da3e8389a0b5506ba996e7fb06b0e0ba7c5f1a0d20dc5f"),
        _File("02.png", "testsets/McMaster/2.tif",
              "09a1f71e9fd288b043ec5d2e9614ab42b5e2a7fdccd256fc26b3da0f0f2aa333",
              "b3bcca63645110a0b2a5fa93d038c9e68070703e",
              "6f9a3ec7248d86e3361dac7b1f975f56de9fc44ec766faf83b77c76c70a149d9"),
        _File("03.png", "testsets/McMaster/3.tif",
              "20110da87588cf253b4f31fc287d9eaf0045c7b214a6694186d346df8ad861d9",
              "3bde17ccb9c9e89ab7504ccbc14dcb76e52e7100",
              "ba85adf6e91abb7849ff374ece8439fabf6b982c44242932df568bf15a193d46"),
        _File("04.png", "testsets/McMaster/4.tif",
              "b8e1768cf1afffc9f63e6d53df063ecc241bdf946ee2cacbb2abc7bc31d227cd",
              "ca4a94cdc56a5dc12c919993e7ae2da64be274e8",
              "4895cd9fabdac3d5564973996f0ceaff6324077dcf86f624569a29638cef3783"),
        _File("05.png", "testsets/McMaster/5.tif",
              "5ba385c2e6dd4e7e2d238b9a28734d3b93bb38709f27a45ee52bcfe3aac10d85",
              "da527c1d679e398a06aa94c0e8e10fc762386f5d",
              "e8544cebf3e2768cfb62e655a278b233f2c1b6585d615b4619d2c5a1a9448626"),
        _File("06.png", "testsets/McMaster/6.tif",
              "f2be18975401228b079473f0349a19ba94b9d8c82b31ca97cb90156459197302",
              "ccc83682ee07ac2fa58625fc26ffcb132aaf591f",
              "f01472bb940367a233d50eda3a6e04b4865c32b1ea46557a0f9b55a79e238277"),
        _File("07.png", "testsets/McMaster/7.tif",
              "30edc7b7152b0823f02dcb3b5098459b50f8e071bf6777530e3371d8440b5561",
              "a53de4c2de7fa02e2ad04f3a6a8c25c914968ed6",
              "9bab193e76304aa080a7d47c7518f841df831ef2bcba10abc49e13784aa09f2c"),
        _File("08.png", "testsets/McMaster/8.tif",
              "56ebb6db1bb7d1e98fef41085c94bc80aa87f84e8ffd71224815c57b772f7368",
              "9265a9f3e68b526f3e0dd6233d12a42a479b589c",
              "860b9a5d23ba75962c81f47b4b9d04a487d4aedb69ad6583a65654348fd35842"),
        _File("09.png", "testsets/McMaster/9.tif",
              "e02950fdcb2415c83fd4cc5d2ae5f712ae881d67dc3e567e56e6db1db9b65581",
              "42855b1035c3945e7ae602f75093d09d9a3ea44e",
              "4a918df72b5bc9aec1588c6af4efc4bc1038ca91beb494fc502438661586a455"),
        _File("10.png", "testsets/McMaster/10.tif",
              "665904fe088d3d686ace684ca861e92cffe043591c014e06788a231b49864e2d",
              "ff2ec209aeaeed2c403daa1ddd5d4621a03d8dc4",
              "7765fe9e799ec21cc52345247e24a67cd903c49292f4c9c98680511df5900a6f"),
        _File("11.png", "testsets/McMaster/11.tif",
              "eb8bd56692c4e29ab811fb56dafbead0ec36aa156a1b450e1802163b50768f83",
              "1b9fdaf604deeeab2789e84d7453af955d5e59db",
              "8b34ab8eb96d420efd208c5933b45a91e167133154943daabac4298fa7d6eb44"),
        _File("12.png", "testsets/McMaster/12.tif",
              "50b0e70487b1653041732687e56b7368681aca0059417fc15dfb7e79a529fc89",
              "0538086d2d8e2f8f502bcb47f15fa8ed036ba48d",
              "9eac57d83e7bd7e1175e3b439450b10e79030ae2d59d4d23e1916f24b10be82d"),
        _File("13.png", "testsets/McMaster/13.tif",
              "838b86d19d5a61374c30fe89a52a02c543ca72cd959605d7b21527235f75de09",
              "d0e71315f4cb81836aa32a7361c90af5a7ee164c",
              "68ed9b9b1137b86b2f3e520d12a382d83f709656fa29e0f008eb7367c2acdd7d"),
        _File("14.png", "testsets/McMaster/14.tif",
              "f7e9706a8eff515bbc7bdd416e934200863cb310fcba8d2eadb0a103d7555f07",
              "8b6373dfed62f8d1a2b02d7cd926c1f26b58e198",
              "be177da9e4e8221b3a2d548fbacde0d78113e5491f2aaa7bb0e5142270b3684b"),
        _File("15.png", "testsets/McMaster/15.tif",
              "884db8cd99a07c9ee3bcba780a033fd08a702d4167fc7ac557c0632e2375eecc",
              "a440fd59d532d5d60a92395af675c574f1a3f02d",
              "dde5cb76b77cd4a5b460579067c5c2821f62636bfa138285a6e818538733caa6"),
        _File("16.png", "testsets/McMaster/16.tif",
              "d57ef5ee8057c6010e2f0a46e49caf8407232f6e952043e6859b8497dcb9373c",
              "0be20a110861cfece1ead74739cbed34f57ce252",
              "292040375a7db79ca67577905481a59e92f2262c90aa66e1d8bd1b7b20a36226"),
        _File("17.png", "testsets/McMaster/17.tif",
              "9f6dfce8be14f9e8f817689dc5594a545d217c044d8884987a8b903d648f598c",
              "a511b63c64c21e70d423bad078721eb8633f785a",
              "5ba4f3f93175abbcf875e5bd33076c6f81faadd75368031190cb79d6fc339731"),
        _File("18.png", "testsets/McMaster/18.tif",
              "cdd352fd03a2795b9cc48833a753fd9a82cce5656aeb221a2d3f55820d118585",
              "150dba1945ee9a06cff5380f46fc0db816e882d7",
              "e6474ee7cdc1408e7e95ea2e6102b9c9957aa599ed625d3787c64198fb7d012e"),
    ),
)

_DATASETS: dict[str, _Dataset] = {d.name: d for d in (_KODAK24, _MCMASTER)}

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
                " (from the root argument)" if root is not None
                else f" (from ${DATA_ENV})" if os.environ.get(DATA_ENV)
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
    """Whether an existing dataset file has the expected content."""
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
    return mirror.rstrip("/")


def _tqdm(**kwargs: Any) -> Any:
    from tqdm.auto import tqdm

    return tqdm(**kwargs)


_CONTENT_RANGE = re.compile(r"bytes\s+(\d+)-\d+/(\d+|\*)", re.IGNORECASE)


def _fetch(url: str, part: Path, label: str, timeout: float, progress: bool) -> None:
    """Download ``url`` into ``part``, continuing a partial ``part`` where the server allows it.

    Raises:
        DownloadError: The request failed or the connection broke; what arrived stays in ``part``.
    """
    offset = part.stat().st_size if part.is_file() else 0
    headers = {"User-Agent": _USER_AGENT}
    if offset:
        headers["Range"] = f"bytes={offset}-"
    try:
        response = urllib.request.urlopen(urllib.request.Request(url, headers=headers),
                                          timeout=timeout)
    except urllib.error.HTTPError as exc:
        exc.close()
        if exc.code == 416 and offset:
            # The partial file is as long as the server's file, or longer: start afresh.
            part.unlink()
            _fetch(url, part, label, timeout, progress)
            return
        raise DownloadError(
            f"downloading {label} from {url} failed: HTTP {exc.code} {exc.reason}"
        ) from None
    except (OSError, http.client.HTTPException, ValueError) as exc:
        raise DownloadError(
            f"downloading {label} from {url} failed: {_reason(exc)}; check the network "
            "connection (or the --mirror address) and run the command again"
        ) from None

    with response:
        # file:// URLs have no status; they, and servers without Range support, send everything.
        resumed = bool(offset) and getattr(response, "status", None) == 206
        if resumed:
            match = _CONTENT_RANGE.match(response.headers.get("Content-Range", ""))
            if match is None or int(match.group(1)) != offset:
                # Not the range asked for: starting over is safer than guessing.
                response.close()
                part.unlink()
                _fetch(url, part, label, timeout, progress)
                return
        else:
            offset = 0
        length_header = response.headers.get("Content-Length")
        expected = int(length_header) if length_header and length_header.isdigit() else None
        received = 0
        bar = _tqdm(
            total=None if expected is None else offset + expected, initial=offset, unit="B",
            unit_scale=True, unit_divisor=1024, desc=label, leave=False, disable=not progress,
        )
        try:
            with open(part, "ab" if resumed else "wb") as fh:
                while chunk := response.read(_CHUNK):
                    fh.write(chunk)
                    received += len(chunk)
                    bar.update(len(chunk))
        except (OSError, http.client.HTTPException) as exc:
            raise DownloadError(
                f"downloading {label} from {url} broke off after {offset + received} bytes "
                f"({_reason(exc)}); run the command again to resume"
            ) from None
        finally:
            bar.close()
    # http.client reports a connection closed early as a normal end of data.
    if expected is not None and received < expected:
        raise DownloadError(
            f"downloading {label} from {url} broke off after {offset + received} of "
            f"{offset + expected} bytes; run the command again to resume"
        )


def _reason(exc: BaseException) -> str:
    if isinstance(exc, urllib.error.URLError) and not isinstance(exc.reason, str):
        exc = exc.reason  # type: ignore[assignment]
    return str(exc) or type(exc).__name__


def _mismatch(
    label: str, url: str, part: Path, what: str, expected: str, actual: str
) -> NoReturn:
    part.unlink(missing_ok=True)
    raise ChecksumError(
        f"{label}: the data downloaded from {url} is not the expected file "
        f"({what} expected {expected}, got {actual}); the partial file was deleted. Run the "
        "command again; if this persists, the source has changed or the connection is altered"
    )


def _install(dataset: _Dataset, entry: _File, folder: Path, mirror: str | None,
             timeout: float, progress: bool) -> None:
    """Download, verify and (if needed) convert one file to ``folder / entry.name``."""
    final = folder / entry.name
    label = f"{dataset.name}/{entry.name}"
    from_source = mirror is None
    if from_source:
        url = dataset.base_url + urllib.parse.quote(entry.source_path)
        # The partial file carries the published file's suffix: a partial TIFF must never be
        # continued with PNG bytes from a mirror, or the other way round.
        part = folder / (Path(entry.name).stem + Path(entry.source_path).suffix + ".part")
    else:
        url = f"{mirror}/{urllib.parse.quote(dataset.name)}/{urllib.parse.quote(entry.name)}"
        part = folder / (entry.name + ".part")

    _fetch(url, part, label, timeout, progress)

    if not (from_source and entry.converted):
        actual = _file_sha256(part)
        if actual != entry.sha256:
            _mismatch(label, url, part, "SHA-256", entry.sha256, actual)
        if from_source:
            blob = _git_blob_id(part.read_bytes())
            if blob != entry.git_blob:
                _mismatch(label, url, part, "git blob id", entry.git_blob, blob)
        os.replace(part, final)
        return

    data = part.read_bytes()
    blob = _git_blob_id(data)
    if blob != entry.git_blob:
        _mismatch(label, url, part, "git blob id", entry.git_blob, blob)
    _convert_to_png(data, entry, final, label)
    part.unlink()


def _convert_to_png(data: bytes, entry: _File, final: Path, label: str) -> None:
    """Decode a verified published file, check its pixels, and write them as PNG to ``final``."""
    import io

    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        pixels = np.asarray(im.convert("RGB"), np.uint8)
    actual = hashlib.sha256(pixels.tobytes()).hexdigest()
    if actual != entry.pixels_sha256:
        # The bytes matched their git blob id, so only the decoder can disagree.
        raise DownloadError(
            f"{label}: the downloaded file is correct but decodes to different pixels here "
            f"(pixel SHA-256 expected {entry.pixels_sha256}, got {actual}); the image library "
            "(Pillow) may decode TIFF differently on this machine"
        )
    fd, tmp = tempfile.mkstemp(dir=final.parent, prefix=f".{final.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            Image.fromarray(pixels).save(fh, format="PNG", optimize=True)
        os.replace(tmp, final)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
    verified are skipped; a ``.part`` file left by an interrupted run is continued.

    Args:
        names: Dataset names (see :data:`DATASET_NAMES`), or one name.
        to: Data root to download into. Default: :func:`data_root` (``$SPLITCAM_DATA`` or
            ``~/.cache/splitcam/datasets``).
        mirror: Base URL (or local folder) of a mirror serving ``<dataset>/<file name>``.
            Default: ``$SPLITCAM_MIRROR`` if set, else the public sources.
        progress: Show progress bars (on stderr).
        timeout: Seconds to wait for the server on each connection attempt and read.
        files: Only these file names (e.g. ``["kodim01.png"]``); default all files.

    Returns:
        The paths of the requested files, all present and verified.

    Raises:
        ValueError: An unknown dataset or file name, or an invalid mirror.
        ChecksumError: Downloaded data did not match its hash (the partial file is deleted).
        DownloadError: A network failure; the partial file is kept, and the next run resumes it.
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
        for dataset, entry in jobs:
            folder = root / dataset.name
            folder.mkdir(parents=True, exist_ok=True)
            final = folder / entry.name
            bar.set_postfix_str(f"{dataset.name}/{entry.name}", refresh=False)
            if not _is_verified(final, entry):
                if final.exists() and progress:
                    bar.write(f"{final}: content does not match its checksum; downloading again",
                              file=sys.stderr)
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
        "data", help="download the test datasets (Kodak24, McMaster) or list them",
        description="`splitcam data download kodak24 mcmaster --to DIR` downloads the datasets "
        "into DIR/<name>, verifying every file; use them by name with SPLITCAM_DATA=DIR. "
        "`splitcam data list` shows which are present.",
    )
    actions = parser.add_subparsers(dest="data_action", metavar="ACTION", required=True)
    p = actions.add_parser(
        "download", help="download and verify datasets",
        description="Downloads from the public sources pinned to a commit (or from a mirror) and "
        "checks every file against embedded hashes. Files already present and verified are "
        "skipped; an interrupted download is resumed when run again.",
    )
    p.add_argument("names", nargs="*", metavar="DATASET",
                   help=f"datasets to download (default: all of {', '.join(DATASET_NAMES)})")
    p.add_argument("--to", metavar="DIR",
                   help=f"data root; each dataset goes to DIR/<name> (default: ${DATA_ENV} or "
                   f"{_DEFAULT_ROOT})")
    p.add_argument("--mirror", metavar="URL",
                   help="download <URL>/<dataset>/<file> instead of the public sources; also "
                   f"a local folder (default: ${MIRROR_ENV} if set)")
    p.add_argument("--timeout", type=float, default=30.0,
                   help="network timeout in seconds (default: 30)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p = actions.add_parser("list", help="list the datasets and whether they are present",
                           description="Counts the files of each dataset under the data root.")
    p.add_argument("--root", metavar="DIR",
                   help=f"data root (default: ${DATA_ENV} or {_DEFAULT_ROOT})")
    parser.set_defaults(handler=cmd_data)
    return parser


def cmd_data(args: argparse.Namespace) -> int:
    """Run ``splitcam data download`` or ``splitcam data list``; returns the exit status."""
    if args.data_action == "download":
        names = args.names or list(DATASET_NAMES)
        paths = download(names, args.to, mirror=args.mirror, progress=not args.quiet,
                         timeout=args.timeout)
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
        state = ("complete" if present == len(dataset.files)
                 else f"{present}/{len(dataset.files)} files" if present else "not downloaded")
        print(f"  {dataset.name:10s} {state:16s} {dataset.description}")
    return 0
