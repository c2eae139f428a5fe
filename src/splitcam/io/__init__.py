"""Writing files so that nothing a user has is damaged: the lowest layer of the package.

Every file splitcam writes goes through :func:`atomic_path`: it is written under a temporary
name in the same folder (same suffix, so writers that pick a format by suffix still do) and
renamed over the target only once complete. An interrupted or failed write (a full disk, a
killed process) leaves the earlier file as it was and no partial file behind, and fails with one
``OSError`` line that names the file.

Appending logs (``metrics.jsonl``, ``per_image.csv`` row by row) are the exception: they grow by
whole lines and are rewritten through :func:`atomic_path` when trimmed. :func:`read_json_lines` is
the one reader of the JSON-lines logs.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

__all__ = [
    "appending",
    "atomic_path",
    "read_json_lines",
    "stale_temporaries",
    "write_bytes",
    "write_text",
]


_TMP = ".tmp-"


def stale_temporaries(folder: str | os.PathLike[str]) -> list[Path]:
    """Temporary files that a killed process left in ``folder`` (the targets are intact)."""
    return sorted(Path(folder).glob(f".*{_TMP}*"))


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path to write ``path``'s content to; renamed to ``path`` on success.

    Raises:
        OSError: Writing or renaming failed; the message names ``path`` (the temporary file is
            removed, ``path`` untouched). Other exceptions of the writer pass through, after the
            same clean-up.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}{_TMP}{os.getpid()}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        _discard(tmp)
        # The user's path, never the temporary one, in the message.
        reason = (exc.strerror or str(exc)).replace(str(tmp), str(path))
        raise OSError(
            exc.errno, f"cannot write {path}: {reason.replace(tmp.name, path.name)}"
        ) from None
    except BaseException:
        _discard(tmp)
        raise


def _discard(tmp: Path) -> None:
    """Remove a temporary file if it is there (its folder may not even exist: then nothing)."""
    with suppress(OSError):
        tmp.unlink(missing_ok=True)


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`); returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (:func:`atomic_path`); returns the path."""
    return write_bytes(path, text.encode("utf-8"))


@contextmanager
def appending(path: str | os.PathLike[str], **options) -> Iterator:
    """``open(path, "a")`` for a log that grows by whole lines; a failed write (a full disk)
    raises one ``OSError`` that names the file. ``options`` go to :func:`open`."""
    path = Path(path)
    try:
        with open(path, "a", encoding="utf-8", **options) as fh:
            yield fh
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OSError(exc.errno, f"cannot write {path}: {reason}") from None


def read_json_lines(
    path: str | os.PathLike[str],
) -> tuple[list[tuple[int, str, dict]], list[int]]:
    """The rows of a JSON-lines log (``metrics.jsonl``, ``changes.jsonl``): ``(number, line,
    row)`` for every line that holds a JSON object, and the numbers of the other non-blank lines
    (cut short by a killed process, or edited by hand); lines are numbered from 1. A missing
    file has no rows.
    """
    path = Path(path)
    if not path.is_file():
        return [], []
    rows, damaged = [], []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        try:
            row = json.loads(line)
        except ValueError:
            row = None
        if isinstance(row, dict):
            rows.append((number, line, row))
        elif line.strip():
            damaged.append(number)
    return rows, damaged
