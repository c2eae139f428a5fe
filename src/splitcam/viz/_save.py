"""Writing a figure: the one place every drawing function saves through."""

from __future__ import annotations

import os
from pathlib import Path

from ..io import atomic_path


def save_figure(fig, path: str | os.PathLike[str], dpi: int = 120) -> Path:
    """Write ``fig`` as a PNG at ``path`` (folders created; written to a temporary name and
    renamed, so a killed process never leaves half a figure). Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return path
