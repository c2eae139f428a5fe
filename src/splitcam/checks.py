"""The argument checks every part of splitcam uses: counts, periods and image tensors.

Messages read "expected ..., got ..." or "<name> must be ..., got ...", so a user's mistake is
named where it enters the library. This is the lowest layer: it imports nothing of splitcam.
"""

from __future__ import annotations

from numbers import Integral
from typing import Any

import torch

__all__ = ["check_count", "check_image", "check_period", "check_raw", "is_int"]


def is_int(value: Any) -> bool:
    """Whether ``value`` is an integer (``bool`` is not)."""
    return isinstance(value, Integral) and not isinstance(value, bool)


def check_count(value: Any, name: str, minimum: int = 0) -> int:
    """``value`` as an ``int`` if it is an integer ``>= minimum``.

    Raises:
        ValueError: Anything else (the message names ``name``).
    """
    if not is_int(value) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_period(period: Any) -> tuple[int, int]:
    """A period: two positive integers ``(Ph, Pw)`` (a tuple, list or ``torch.Size``).

    >>> check_period([2, 3])
    (2, 3)
    >>> check_period((0, 2))
    Traceback (most recent call last):
        ...
    ValueError: period must be two positive integers (Ph, Pw), got (0, 2)

    Raises:
        ValueError: Anything else.
    """
    if (
        not isinstance(period, (tuple, list, torch.Size))
        or len(period) != 2
        or not all(is_int(p) and p >= 1 for p in period)
    ):
        raise ValueError(f"period must be two positive integers (Ph, Pw), got {period!r}")
    return int(period[0]), int(period[1])


def check_image(x: Any, channels: int, what: str) -> None:
    """Raise unless ``x`` is a floating-point ``(N, channels, H, W)`` tensor with N, H, W >= 1.

    Raises:
        TypeError: Not a tensor, or not floating point.
        ValueError: Another shape.
    """
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"expected {what} as a torch.Tensor, got {type(x).__name__}")
    if x.ndim != 4 or x.shape[1] != channels:
        raise ValueError(f"expected {what} of shape (N, {channels}, H, W), got {tuple(x.shape)}")
    if not x.is_floating_point():
        raise TypeError(f"expected {what} with a floating dtype (float32/float64), got {x.dtype}")
    if x.shape[0] == 0 or x.shape[2] == 0 or x.shape[3] == 0:
        raise ValueError(f"expected {what} with N, H, W >= 1, got {tuple(x.shape)}")


def check_raw(raw: Any) -> None:
    """Raise if ``raw`` is not a floating-point raw image batch ``(N, 1, H, W)``, H, W >= 1.

    Raises:
        TypeError: ``raw`` is not a tensor, or its dtype is not floating point.
        ValueError: ``raw`` is not of shape ``(N, 1, H, W)`` with ``H, W >= 1``.
    """
    if not isinstance(raw, torch.Tensor):
        raise TypeError(f"expected a torch.Tensor of shape (N, 1, H, W), got {type(raw).__name__}")
    shape = tuple(raw.shape)
    if raw.ndim != 4 or shape[1] != 1:
        raise ValueError(f"expected (N, 1, H, W), got {shape}")
    if shape[2] < 1 or shape[3] < 1:
        raise ValueError(f"expected (N, 1, H, W) with H, W >= 1, got {shape}")
    if not raw.is_floating_point():
        raise TypeError(f"expected a floating-point raw image, got dtype {raw.dtype}")
