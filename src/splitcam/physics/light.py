"""Linear light: the sRGB transfer function between display values and radiance (model.md §13).

Test and training images are 8-bit sRGB display values. In the ``linear`` domain a scene is
decoded to linear radiance (:func:`srgb_to_linear`) before the sensor and the noise act on it,
and a reconstruction (an estimate of radiance) is encoded back (:func:`linear_to_srgb`), clipped
to [0, 1] and rounded to 8 bits to be scored against the original image. The ``srgb`` domain is
the paper's protocol: the display values themselves are taken as light.

The transfer function is IEC 61966-2-1's: with ``u = v / 255``,

    L = u / 12.92                        for u <= 0.04045
    L = ((u + 0.055) / 1.055) ** 2.4     otherwise

and its inverse ``u = 12.92 L`` for ``L <= 0.0031308``, else ``1.055 L ** (1 / 2.4) - 0.055``.
Both are defined for every real input (the straight segment continues below 0, the power law
above 1), so unclipped estimates encode without NaNs, and differentiable (the power is taken of
an input clamped to its own branch, so the other branch's gradient is never NaN).
"""

from __future__ import annotations

import torch

from ..io.domains import DEFAULT_DOMAIN, DOMAINS, LINEAR

__all__ = [
    "DEFAULT_DOMAIN",
    "DOMAINS",
    "check_domain",
    "decode_scene",
    "encode_estimate",
    "linear_to_srgb",
    "srgb_to_linear",
]

#: Display value (in [0, 1]) below which sRGB is a straight line.
SRGB_BREAK = 0.04045
#: Linear value below which the encoding is a straight line (IEC 61966-2-1).
LINEAR_BREAK = 0.0031308
_SLOPE = 12.92
_GAMMA = 2.4


def check_domain(domain: object) -> str:
    """``domain`` as one of :data:`DOMAINS` (any case, surrounding spaces ignored).

    Raises:
        ValueError: Not a known domain (the message lists them).
    """
    key = domain.strip().lower() if isinstance(domain, str) else domain
    if key not in DOMAINS:
        raise ValueError(f"unknown light domain {domain!r}; expected one of {', '.join(DOMAINS)}")
    return key  # type: ignore[return-value]


def _check_float(x: torch.Tensor) -> None:
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"expected a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise TypeError(f"expected a floating-point tensor, got dtype {x.dtype}")


def srgb_to_linear(u: torch.Tensor) -> torch.Tensor:
    """Decode sRGB display values ``u`` (8-bit value / 255) to linear radiance.

    Any shape and floating dtype; the result has ``u``'s shape, dtype and device.

    >>> import torch
    >>> srgb_to_linear(torch.tensor([0.0, 0.04045, 0.5, 1.0], dtype=torch.float64)).tolist()
    [0.0, 0.0031308, 0.2140411, 1.0]
    >>> u = torch.linspace(0, 1, 256, dtype=torch.float64)
    >>> torch.allclose(linear_to_srgb(srgb_to_linear(u)), u)  # the pair round-trips
    True
    """
    _check_float(u)
    curve = ((u.clamp_min(SRGB_BREAK) + 0.055) / 1.055) ** _GAMMA
    return torch.where(u <= SRGB_BREAK, u / _SLOPE, curve)


def linear_to_srgb(lin: torch.Tensor) -> torch.Tensor:
    """Encode linear radiance to sRGB display values (not clipped: values outside [0, 1] stay
    outside). Any shape and floating dtype; the result has ``lin``'s shape, dtype and device."""
    _check_float(lin)
    curve = 1.055 * lin.clamp_min(LINEAR_BREAK) ** (1.0 / _GAMMA) - 0.055
    return torch.where(lin <= LINEAR_BREAK, lin * _SLOPE, curve)


def decode_scene(rgb: torch.Tensor, domain: str) -> torch.Tensor:
    """The light the sensor sees of a scene of display values ``rgb`` in ``domain``: ``rgb``
    itself in ``srgb``, its linear radiance in ``linear``."""
    return srgb_to_linear(rgb) if check_domain(domain) == LINEAR else rgb


def encode_estimate(estimate: torch.Tensor, domain: str) -> torch.Tensor:
    """Display values of a reconstruction made in ``domain`` (the estimate itself in ``srgb``,
    encoded in ``linear``), not clipped."""
    return linear_to_srgb(estimate) if check_domain(domain) == LINEAR else estimate
