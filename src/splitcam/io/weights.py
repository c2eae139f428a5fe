"""Where the weights shipped with splitcam lie (the package folder ``splitcam/weights``): the one
place that computes these paths."""

from __future__ import annotations

from pathlib import Path

__all__ = ["IMAGE_STATISTICS", "IMAGE_STATISTICS_LINEAR", "LMMSE_DIR", "MODELS_DIR", "WEIGHTS_DIR"]

#: The package's weights folder.
WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
#: Shipped networks: ``<name>.safetensors`` + ``<name>.json``.
MODELS_DIR = WEIGHTS_DIR / "models"
#: Shipped LMMSE fits of the built-in patterns: ``<pattern>.safetensors`` + ``.json``.
LMMSE_DIR = WEIGHTS_DIR / "lmmse"
#: The pattern-independent image statistics of the closed-form LMMSE (``.json`` + tensors).
IMAGE_STATISTICS = WEIGHTS_DIR / "image_statistics.json"
#: The same statistics of linear radiance (training images decoded from sRGB, model.md §13).
IMAGE_STATISTICS_LINEAR = WEIGHTS_DIR / "image_statistics_linear.json"
