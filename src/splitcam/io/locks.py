"""An output folder held by one process at a time.

A training run and an evaluation both continue what an earlier process left in their folder
(a checkpoint, the rows of ``per_image.csv``). Two processes on one folder would each continue
it and write over each other's results, so each holds an exclusive OS lock on the folder's
``.lock`` file for as long as it writes there, and a second is refused at once. The OS drops
the lock when its process ends, however it ends, so a killed process never leaves the folder
locked. Without ``fcntl`` (Windows) there is no lock.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO

LOCK_NAME = ".lock"


class FolderBusy(ValueError):
    """Another process holds the folder's lock."""


def lock_folder(folder: Path, user: str) -> IO | None:
    """Take the folder's lock (creating the folder) for ``user`` (what writes there: "training
    run", "evaluation"), or raise :class:`FolderBusy` with one line naming the folder.

    Returns:
        The open lock file (close it to release the lock), or None where there is no ``fcntl``.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover
        return None
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    handle = open(folder / LOCK_NAME, "a+")  # noqa: SIM115 (held until the work ends)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        raise FolderBusy(
            f"another {user} is using {str(folder)!r} (its lock is held); wait for it to end "
            "or choose another --out"
        ) from None
    return handle


@contextmanager
def folder_held(folder: Path, user: str) -> Iterator[None]:
    """:func:`lock_folder` for the block; the lock file is removed at the end, so a results
    folder keeps only results."""
    handle = lock_folder(folder, user)
    try:
        yield
    finally:
        if handle is not None:
            with suppress(OSError):
                (Path(folder) / LOCK_NAME).unlink()
            handle.close()
