"""Training: typed configuration, checkpoints, and the training loop."""

from .checkpoint import CheckpointError, load_system
from .config import ConfigError, TrainConfig
from .trainer import TrainResult, build_system, train

__all__ = [
    "CheckpointError",
    "ConfigError",
    "TrainConfig",
    "TrainResult",
    "build_system",
    "load_system",
    "train",
]
