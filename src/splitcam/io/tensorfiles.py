"""A pair of files for tensors and what they mean: ``NAME.safetensors`` plus ``NAME.json``.

The tensor file is plain safetensors (never a pickle); the JSON file says what the tensors are
(``format``, ``version`` and any fields of the caller) and records the SHA-256 of the tensor file
and of its own fields (``meta_sha256``: an edited architecture or pattern changes results as
much as edited weights), so a damaged, edited or mismatched pair is found on loading. Used for
the LMMSE statistics (fitted and pattern-free) and the shipped models.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import torch

from . import write_bytes, write_text


class TensorFileError(ValueError):
    """A tensor-file pair is missing, unreadable, damaged or of another kind; the message says
    which file and why."""


def paired_paths(path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """``(NAME.safetensors, NAME.json)`` for ``NAME``, ``NAME.safetensors`` or ``NAME.json``."""
    path = Path(path)
    if path.suffix.lower() in (".safetensors", ".json"):
        path = path.with_suffix("")
    return path.with_name(path.name + ".safetensors"), path.with_name(path.name + ".json")


def save_pair(
    path: str | os.PathLike[str],
    tensors: dict[str, torch.Tensor],
    fmt: str,
    version: int,
    meta: dict[str, Any],
) -> Path:
    """Write ``tensors`` and ``meta`` (JSON-serialisable) as a pair; returns the JSON path.

    The tensor file's bytes depend only on the tensors (see :func:`_canonical`), so exporting
    the same weights twice gives the same file and the same recorded checksum.
    """
    from safetensors.torch import save

    tensors_path, meta_path = paired_paths(path)
    tensors_path.parent.mkdir(parents=True, exist_ok=True)
    blob = save(
        {k: v.detach().cpu().contiguous() for k, v in tensors.items()},
        metadata={"format": fmt, "version": str(version)},
    )
    data = _canonical(blob)
    header = {
        "format": fmt,
        "version": version,
        **meta,
        "tensors": tensors_path.name,
        "sha256": hashlib.sha256(data).hexdigest(),
    }
    header["meta_sha256"] = meta_checksum(header)
    write_bytes(tensors_path, data)
    write_text(meta_path, json.dumps(header, indent=1) + "\n")
    return meta_path


def meta_checksum(header: dict[str, Any]) -> str:
    """SHA-256 of a pair's JSON fields (all but ``meta_sha256`` itself), key order and
    whitespace aside."""
    fields = {k: v for k, v in header.items() if k != "meta_sha256"}
    text = json.dumps(fields, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _canonical(blob: bytes) -> bytes:
    """The safetensors bytes with the JSON header's keys sorted.

    safetensors writes its ``__metadata__`` map in hash order, which changes from one process to
    the next: the same tensors gave files with different bytes (and checksums). The header is
    rewritten with sorted keys, in the same compact form and padded with spaces to its original
    length, so offsets and the data are untouched and any safetensors reader loads it as before.
    """
    size = int.from_bytes(blob[:8], "little")
    header = json.loads(blob[8 : 8 + size])
    text = json.dumps(header, sort_keys=True, separators=(",", ":")).encode()
    if len(text) > size:  # never expected: sorting keeps every character; keep the original
        return blob
    return blob[:8] + text.ljust(size, b" ") + blob[8 + size :]


def load_pair(
    path: str | os.PathLike[str],
    fmt: str,
    version: int,
    what: str,
    error: type[ValueError] = TensorFileError,
    *,
    unchecked_before: int | None = None,
) -> tuple[dict[str, torch.Tensor], dict[str, Any], Path]:
    """Read a pair written by :func:`save_pair`: ``(tensors, meta, json path)``.

    Args:
        fmt: The format the JSON file must declare.
        version: The version the JSON file must declare.
        what: Words for the kind of file in messages ("LMMSE statistics").
        error: The exception class raised (a subclass of ``ValueError``).
        unchecked_before: Where the format's versions tell files with the field checksum from
            files written before it existed: files of a version below this one are read too,
            and only they may lack ``meta_sha256`` (``version`` must then be at least this).

    Raises:
        error: A file is missing or unreadable, the JSON is damaged or of another format or
            version, or the tensor file does not match the recorded checksum or is damaged.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load

    tensors_path, meta_path = paired_paths(path)
    try:
        meta = json.loads(meta_path.read_text())
    except OSError as exc:
        raise error(f"cannot read {what} '{meta_path}': {exc}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise error(f"'{meta_path}' is not valid JSON (damaged?): {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != fmt:
        raise error(f"'{meta_path}' is not a {what} file ({fmt})")
    older = range(1, unchecked_before) if unchecked_before else range(0)
    if meta.get("version") != version and meta.get("version") not in older:
        raise error(
            f"'{meta_path}': expected format version {version}, got {meta.get('version')!r}"
        )
    if unchecked_before and meta["version"] >= unchecked_before and "meta_sha256" not in meta:
        raise error(
            f"'{meta_path}' lacks the checksum of its fields (meta_sha256), which every file of "
            f"its version carries: it was edited; export it again rather than editing it"
        )
    if "meta_sha256" in meta and meta_checksum(meta) != meta["meta_sha256"]:
        raise error(
            f"'{meta_path}' was changed after it was written (its fields do not match their "
            f"recorded checksum): export it again rather than editing it"
        )
    try:
        blob = tensors_path.read_bytes()
    except OSError as exc:
        raise error(f"cannot read {what} tensors '{tensors_path}': {exc}") from None
    if hashlib.sha256(blob).hexdigest() != meta.get("sha256"):
        raise error(
            f"'{tensors_path}' does not match the checksum recorded in '{meta_path}' "
            f"(damaged, or from another file)"
        )
    try:
        tensors = load(blob)
    except SafetensorError as exc:
        raise error(f"damaged {what} '{tensors_path}': {exc}") from None
    return tensors, meta, meta_path
