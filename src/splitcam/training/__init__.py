"""Training: typed configuration, checkpoints, and the training loop.

The names below load on first use, so ``splitcam.training.config`` (from which the CLI builds
the ``train`` flags) imports no torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "CheckpointError": "checkpoint",
    "load_system": "checkpoint",
    "ConfigError": "config",
    "TrainConfig": "config",
    "TrainResult": "trainer",
    "build_system": "trainer",
    "train": "trainer",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'splitcam.training' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)


def __dir__() -> list[str]:
    return __all__
