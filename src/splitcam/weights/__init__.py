"""Weights shipped with splitcam (safetensors + JSON; never pickles).

- ``lmmse/<pattern>.safetensors``: LMMSE statistics of each built-in pattern, fitted on the
  432 BSDS500 training images (CBSD432) with :func:`splitcam.baselines.fit_lmmse`'s defaults;
  regenerate with ``python scripts/fit_shipped_lmmse.py``.
"""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent


def shipped_lmmse(pattern: str):
    """The shipped LMMSE fit of a built-in pattern."""
    from ..baselines import LMMSE
    from ..patterns import get

    name = get(pattern).name
    path = HERE / "lmmse" / f"{name}.safetensors"
    if not path.is_file():
        raise FileNotFoundError(
            f"no shipped LMMSE fit for pattern {name!r}; fit one with --lmmse-train DIR"
        )
    return LMMSE.load(path)
