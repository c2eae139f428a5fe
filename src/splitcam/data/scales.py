"""The rule for the sizes a training image is kept at (``data.scales``, :class:`.ImageCache`).

Standard library only, so the configuration can check it without importing torch.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["valid_scales"]


def valid_scales(scales: Sequence[float]) -> bool:
    """Whether ``scales`` can be :class:`~splitcam.data.patches.ImageCache`'s (and so
    ``data.scales``): one or more distinct factors in ``(0, 1]``.

    >>> valid_scales([1.0, 0.5]), valid_scales([1.0, 1.0]), valid_scales([]), valid_scales([1.5])
    (True, False, False, False)
    """
    factors = [float(f) for f in scales]
    return bool(factors) and all(0 < f <= 1 for f in factors) and len(set(factors)) == len(factors)
