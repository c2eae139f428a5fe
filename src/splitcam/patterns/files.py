"""Pattern files: JSON or TOML, the same fields as :meth:`Pattern.to_dict`.

A pattern file looks like (TOML)::

    name = "my-pattern"
    provenance = "user"
    description = "what it is"
    reference = "where it comes from"
    layout = [[0, 1], [2, 3]]

    [[kernels]]          # splitter 0; one table per splitter, kh x kw lists per colour
    R = [[0, 1, 0]]
    G = [[0, 1, 0]]
    B = [[0, 1, 0]]

Kernels may also be given as one 4-D list ``(S, 3, kh, kw)``. A file with ``wavelengths`` is a
spectral pattern (:mod:`splitcam.patterns.spectral`), reduced to RGB kernels when read.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..io import write_text
from .core import Pattern, PatternError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

SUFFIXES = (".json", ".toml")


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise PatternError(
            f"pattern file {str(path)!r}: expected a .json or .toml file, got {suffix or 'none'!r}"
        )
    return suffix


def load(path: str | os.PathLike) -> Pattern:
    """Read and validate a pattern file.

    Raises:
        PatternError: Missing file, bad syntax, or an invalid pattern; the message names the file.
    """
    path = Path(path)
    suffix = _suffix(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise PatternError(f"pattern file {str(path)!r} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise PatternError(f"cannot read pattern file {str(path)!r}: {exc}") from None
    try:
        data = json.loads(text) if suffix == ".json" else tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
        raise PatternError(f"pattern file {str(path)!r} is not valid {suffix[1:]}: {exc}") from None
    source = f"pattern file {str(path)!r}"
    if isinstance(data, dict) and "wavelengths" in data:
        from .spectral import SpectralPattern

        return SpectralPattern.from_dict(data, source=source).to_pattern()
    return Pattern.from_dict(data, source=source)


def _toml(data: dict) -> str:
    """TOML with one line per kernel row, so a pattern file reads like the tables of docs/model.md.

    ``tomli_w`` would put every number on a line of its own; the format here is simple enough
    to write directly (strings as JSON strings, which are valid TOML basic strings).
    """
    import tomli_w

    def row(values) -> str:
        return "[" + ", ".join(repr(float(v)) for v in values) + "]"

    lines = [
        f"{key} = {json.dumps(data[key])}"
        for key in ("name", "provenance", "description", "reference")
    ]
    lines.append(
        "layout = ["
        + ", ".join("[" + ", ".join(str(int(v)) for v in r) + "]" for r in data["layout"])
        + "]"
    )
    if data.get("metadata"):
        lines += ["", tomli_w.dumps({"metadata": data["metadata"]}).strip()]
    for s, kernel in enumerate(data["kernels"]):
        lines += ["", f"[[kernels]]  # splitter {s}"]
        lines += [f"{c} = [" + ", ".join(row(r) for r in kernel[c]) + "]" for c in kernel]
    return "\n".join(lines) + "\n"


def save(pattern: Pattern, path: str | os.PathLike) -> Path:
    """Write ``pattern`` as JSON or TOML (by the file suffix), atomically."""
    path = Path(path)
    suffix = _suffix(path)
    data = pattern.to_dict()
    text = json.dumps(data, indent=2) + "\n" if suffix == ".json" else _toml(data)
    return write_text(path, text)


def save_transmission(
    path: str | os.PathLike, name: str, wavelengths, transmission, **info: str
) -> Path:
    """Write a router's spectra as a spectral pattern file (TOML): ``transmission[i, j, l]``,
    the share of light of wavelength ``l`` arriving on the period that lands on pixel
    ``(i, j)`` (:meth:`~splitcam.patterns.spectral.SpectralPattern.from_transmission`, whose
    checks run first: wavelengths in range, no light created), with ``info`` (provenance,
    description, reference). Written atomically and read back.

    Raises:
        PatternError: Spectra that fail those checks (nothing is written).
    """
    from .spectral import SpectralPattern

    SpectralPattern.from_transmission(name, wavelengths, transmission, **info)
    transmission = np.asarray(transmission, dtype=np.float64)
    transmission = _six_decimals(transmission, transmission.sum(axis=(0, 1), keepdims=True))
    lines = [f"name = {json.dumps(name, ensure_ascii=False)}"]
    lines += [f"{k} = {json.dumps(v, ensure_ascii=False)}" for k, v in info.items()]
    lines.append("wavelengths = [" + ", ".join(f"{v:g}" for v in wavelengths) + "]")
    lines.append("# transmission[row][column]: the share of each wavelength's light arriving on")
    lines.append("# the period that lands on that pixel")
    lines.append("transmission = [")
    for row in transmission:
        lines.append("  [")
        lines += ["    [" + ", ".join(f"{v:.6f}" for v in px) + "]," for px in row]
        lines.append("  ],")
    lines.append("]")
    written = write_text(path, "\n".join(lines) + "\n")
    load(written)
    return written


def _six_decimals(values: np.ndarray, sums: np.ndarray) -> np.ndarray:
    """``values`` at the six decimals the pattern files keep, rounded down where the light they
    share (``sums``, broadcast against them) is within 1e-5 of all of it, so that rounding a
    lossless splitter's shares never creates light the file's reader would refuse."""
    return np.where(sums > 1 - 1e-5, np.floor(values * 1e6), np.round(values * 1e6)) / 1e6


def save_spectral_kernels(
    path: str | os.PathLike, name: str, wavelengths, layout, kernels, **info: Any
) -> Path:
    """Write a spectral pattern given by its kernels (``kernels[s, l]``, the ``kh x kw`` kernel
    of splitter ``s`` at wavelength ``l``; :class:`~splitcam.patterns.spectral.SpectralPattern`,
    whose checks run first) as JSON, with ``info`` (provenance, description, reference,
    metadata). Written atomically and read back.

    Raises:
        PatternError: Kernels that fail those checks (nothing is written).
    """
    from .spectral import SpectralPattern

    kernels = np.asarray(kernels, dtype=np.float64)
    kernels = _six_decimals(kernels, kernels.sum(axis=(-2, -1), keepdims=True))
    pattern = SpectralPattern(name, layout, wavelengths, kernels, **info)
    data = {
        "name": pattern.name,
        **{k: getattr(pattern, k) for k in ("provenance", "description", "reference")},
        "metadata": pattern.metadata,
        "wavelengths": pattern.wavelengths.tolist(),
        "layout": pattern.layout.tolist(),
        "kernels": pattern.kernels.tolist(),
    }
    written = write_text(Path(path), json.dumps(data, ensure_ascii=False) + "\n")
    load(written)
    return written
