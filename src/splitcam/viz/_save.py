"""Writing a figure: the one place every drawing function saves through."""

from __future__ import annotations

import os
from pathlib import Path

from ..io import atomic_path


def save_figure(fig, path: str | os.PathLike[str], dpi: int = 120) -> Path:
    """Write ``fig`` as a PNG at ``path`` (folders created; written to a temporary name and
    renamed, so a killed process never leaves half a figure). The image is cut to what the
    figure draws (``bbox_inches="tight"``): a title, a colour-bar label or an annotation wider
    than the figure widens the image instead of being clipped. Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", pad_inches=0.1)
    return path
