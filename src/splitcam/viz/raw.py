"""Pictures of raw sensor images."""

from __future__ import annotations

import numpy as np
import torch

from ..patterns import Pattern, pixel_response


def false_colour(raw: np.ndarray | torch.Tensor, pattern: Pattern, *, scale: float | None = None):
    """A false-colour preview of a raw image: each pixel tinted by the colour mixture it records.

    Every pixel's value is multiplied by its phase's response to white light (normalised to a
    maximum of 1 per phase), so a Bayer raw looks like the familiar RGGB mosaic and a splitter raw
    shows which pixels carry which colours. Values are divided by ``scale`` (default: the 99.5th
    percentile, so that one hot pixel does not darken the picture) and clipped to [0, 1].

    Shape:
        - raw: ``(H, W)``.
        - output: ``(H, W, 3)`` float32 in [0, 1].
    """
    raw = raw.detach().cpu().numpy() if isinstance(raw, torch.Tensor) else np.asarray(raw)
    if raw.ndim != 2:
        raise ValueError(f"expected a raw image of shape (H, W), got {raw.shape}")
    ph, pw = pattern.period
    response = pixel_response(pattern)
    tint = response / np.maximum(response.max(axis=-1, keepdims=True), 1e-12)
    h, w = raw.shape
    tiles = np.tile(tint, (-(-h // ph), -(-w // pw), 1))[:h, :w]
    if scale is None:
        scale = float(np.percentile(raw, 99.5)) if raw.size else 1.0
    out = np.clip(raw / max(scale, 1e-12), 0, 1)[..., None] * tiles
    return out.astype(np.float32)
