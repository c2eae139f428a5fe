"""Training: typed configuration, checkpoints, and the training loop.

The names below load on first use, so ``splitcam.training.config`` (from which the CLI builds
the ``train`` flags) imports no torch.
"""

from __future__ import annotations

from ..io.lazy import lazy_exports

_EXPORTS = {
    "CheckpointError": "checkpoint",
    "load_system": "checkpoint",
    "ConfigError": "config",
    "TrainConfig": "config",
    "TrainResult": "trainer",
    "build_system": "setup",
    "train": "trainer",
}

__all__ = sorted(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
