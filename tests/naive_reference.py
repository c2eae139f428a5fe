"""Literal implementations of the paper's algorithms, independent of splitcam's fast paths.

Used by the tests as the reference and by ``benchmarks/bench_sensor.py`` as the baseline.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F


def naive_splitter_forward(rgb: torch.Tensor, weights: torch.Tensor, layout) -> torch.Tensor:
    """Paper Eq. 1 as written: for each splitter, sample the image at its sites (zeros
    elsewhere), scatter with a transposed convolution, crop to the sensor, and sum."""
    n, _, h, w = rgb.shape
    layout = torch.tensor(np.asarray(layout))
    ph, pw = layout.shape
    kh, kw = weights.shape[-2:]
    yy = torch.arange(h) % ph
    xx = torch.arange(w) % pw
    site = layout[yy[:, None], xx[None, :]]
    raw = rgb.new_zeros(n, 1, h, w)
    for s in range(weights.shape[0]):
        sampled = rgb * (site == s).to(rgb.dtype)
        # conv_transpose2d scatters in[y, x] * w[a, b] onto out[y + a, x + b] (no flip).
        full = F.conv_transpose2d(sampled, weights[s].to(rgb.dtype).unsqueeze(1))
        raw = raw + full[:, :, kh // 2 : kh // 2 + h, kw // 2 : kw // 2 + w]
    return raw


def loop_splitter_forward(rgb: torch.Tensor, weights: torch.Tensor, layout) -> torch.Tensor:
    """Eq. 1 by explicit loops over pixels and taps (tiny images only)."""
    n, _, h, w = rgb.shape
    ph, pw = len(layout), len(layout[0])
    kh, kw = weights.shape[-2:]
    raw = torch.zeros(n, 1, h, w, dtype=rgb.dtype)
    for y in range(h):
        for x in range(w):
            s = int(layout[y % ph][x % pw])
            for c in range(3):
                for a in range(kh):
                    for b in range(kw):
                        ty, tx = y + a - kh // 2, x + b - kw // 2
                        if 0 <= ty < h and 0 <= tx < w:
                            raw[:, 0, ty, tx] += weights[s, c, a, b] * rgb[:, c, y, x]
    return raw
