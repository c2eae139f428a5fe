"""Whether the installed torchvision can import beside this torch (deepinv imports it).

Kept apart from :mod:`splitcam.integrations.deepinv`, which cannot be imported without deepinv,
so that the check can be used and tested anywhere.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import logging
import sys
from pathlib import Path

import torch

logger = logging.getLogger(__name__)


def torchvision_mismatch(folder: Path | None = None) -> str | None:
    """Why the installed torchvision cannot import beside this torch (one line, with the install
    command that fixes it), or None where its compiled operators load or it is not installed.

    Args:
        folder: torchvision's package folder (default: the installed one's).
    """
    if folder is None:
        if "torchvision" in sys.modules:
            return None
        spec = importlib.util.find_spec("torchvision")
        if spec is None or not spec.submodule_search_locations:
            return None
        folder = Path(next(iter(spec.submodule_search_locations)))
    # torchvision's compiled operators: _C (and, from 0.29, _C_stable) extension modules.
    libraries = sorted(
        p for suffix in importlib.machinery.EXTENSION_SUFFIXES for p in folder.glob(f"_C*{suffix}")
    )
    for library in libraries:
        try:
            torch.ops.load_library(str(library))
        except (OSError, RuntimeError) as err:
            logger.debug("torchvision's operators do not load: %s", err)
            return _mismatch_line(folder)
    return None


def _mismatch_line(folder: Path) -> str:
    version = _installed_version("torchvision", folder)
    release = torch.__version__.split("+")[0]
    major, minor = (int(v) for v in release.split(".")[:2])
    matching = f"0.{minor + 15}" if major == 2 else "the release for this torch"
    build = torch.__version__.split("+")[1] if "+" in torch.__version__ else None
    # Reinstalling torchvision alone changes nothing where pip sees it as satisfied, and a
    # torch installed from a local file has no index of its own: the pair is installed again
    # together from one index (PyPI, ignoring local settings), so the two are built together.
    other = (
        f" (or their {build} builds: add --index-url https://download.pytorch.org/whl/{build})"
        if build
        else ""
    )
    return (
        f"torchvision {version} cannot load its operators beside torch {torch.__version__} (it "
        f"was built for another torch); install the two as one pair: pip install --isolated "
        f"--force-reinstall 'torch=={release}' 'torchvision=={matching}.*'{other}"
    )


def _installed_version(name: str, folder: Path) -> str:
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:  # noqa: BLE001 - a version is only for the message
        return f"in {folder}"
