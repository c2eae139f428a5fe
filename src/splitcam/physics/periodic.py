"""Tensor helpers for anything laid out on the period of a pattern, written once.

A pattern repeats with period ``(Ph, Pw)``; a pixel ``(y, x)`` has *phase*
``p = (y mod Ph) * Pw + (x mod Pw)``, counted from the top-left pixel. Three operations recur
across the sensor, the reconstruction networks and the LMMSE filters:

- :func:`phase_map`: the phase of every pixel;
- :func:`period_unshuffle` / :func:`period_shuffle`: move each ``Ph x Pw`` cell into channels and
  back (:func:`torch.nn.functional.pixel_unshuffle` for rectangular periods, zero-padding sizes
  that are not whole periods);
- :func:`phase_conv`: a convolution whose kernel depends on the phase of the output pixel (the
  gather form of the sensor, paper Eq. 2, and the per-phase LMMSE filters).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F

from ..checks import check_period

__all__ = ["period_shuffle", "period_unshuffle", "phase_conv", "phase_map"]


def phase_map(
    height: int, width: int, period: Sequence[int], device: torch.device | str | None = None
) -> torch.Tensor:
    """The phase ``(y mod Ph) * Pw + (x mod Pw)`` of every pixel.

    >>> phase_map(2, 3, (2, 2)).tolist()
    [[0, 1, 0], [2, 3, 2]]

    Shape:
        - output: ``(H, W)``, int64.
    """
    ph, pw = check_period(period)
    rows = torch.arange(height, device=device) % ph
    cols = torch.arange(width, device=device) % pw
    return rows[:, None] * pw + cols[None, :]


def period_unshuffle(x: torch.Tensor, period: Sequence[int]) -> torch.Tensor:
    """Move each period cell into channels, zero-padding H and W up to whole periods.

    Channel ``c * Ph * Pw + i * Pw + j`` of cell ``(u, v)`` is pixel ``(u * Ph + i, v * Pw + j)``
    of channel ``c``: the order of :func:`torch.nn.functional.pixel_unshuffle`, which it equals
    for square periods and whole cells.

    Shape:
        - x: ``(N, C, H, W)``.
        - output: ``(N, C * Ph * Pw, ceil(H / Ph), ceil(W / Pw))``.
    """
    ph, pw = check_period(period)
    if x.ndim != 4:
        raise ValueError(f"expected (N, C, H, W), got {tuple(x.shape)}")
    n, c, h, w = x.shape
    if h % ph or w % pw:
        x = F.pad(x, (0, -w % pw, 0, -h % ph))
        h, w = x.shape[-2:]
    if ph == pw:
        return F.pixel_unshuffle(x, ph)
    x = x.reshape(n, c, h // ph, ph, w // pw, pw).permute(0, 1, 3, 5, 2, 4)
    return x.reshape(n, c * ph * pw, h // ph, w // pw)


def period_shuffle(
    x: torch.Tensor, period: Sequence[int], size: Sequence[int] | None = None
) -> torch.Tensor:
    """Inverse of :func:`period_unshuffle`, cropped to ``size = (H, W)`` if given.

    Shape:
        - x: ``(N, C * Ph * Pw, h, w)``.
        - output: ``(N, C, h * Ph, w * Pw)``, or ``(N, C, H, W)`` with ``size``.
    """
    ph, pw = check_period(period)
    if x.ndim != 4 or x.shape[1] % (ph * pw):
        raise ValueError(
            f"expected (N, C * {ph * pw}, h, w) for the period {(ph, pw)}, got {tuple(x.shape)}"
        )
    n, cp, h, w = x.shape
    if ph == pw:
        out = F.pixel_shuffle(x, ph)
    else:
        c = cp // (ph * pw)
        out = x.reshape(n, c, ph, pw, h, w).permute(0, 1, 4, 2, 5, 3).reshape(n, c, h * ph, w * pw)
    if size is not None:
        out = out[..., : size[0], : size[1]]
    return out


def phase_conv(x: torch.Tensor, weight: torch.Tensor, period: Sequence[int]) -> torch.Tensor:
    """A zero-padded 'same' correlation whose kernel is chosen by the output pixel's phase.

    ``out[n, o, y, x] = sum_{c,a,b} weight[p(y, x), o, c, a, b] * x[n, c, y + a - kh//2,
    x + b - kw//2]``. Computed as one convolution with every phase's kernels followed by a
    per-pixel pick of the pixel's own phase: the convolution reads the input once in an optimised
    library call, and the pick is a gather.

    Shape:
        - x: ``(N, C, H, W)``.
        - weight: ``(Ph * Pw, O, C, kh, kw)``, odd ``kh``, ``kw``.
        - output: ``(N, O, H, W)``.
    """
    ph, pw = check_period(period)
    p, o, c, kh, kw = weight.shape
    if p != ph * pw:
        raise ValueError(f"expected {ph * pw} phase kernels for period {(ph, pw)}, got {p}")
    n, _, h, w = x.shape
    out = F.conv2d(x, weight.reshape(p * o, c, kh, kw), padding=(kh // 2, kw // 2))
    index = phase_map(h, w, (ph, pw), x.device).expand(n, 1, o, h, w)
    return out.view(n, p, o, h, w).gather(1, index).squeeze(1)
