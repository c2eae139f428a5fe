"""Sensor noise (SPEC section 3): additive Gaussian noise in 8-bit units on the raw image's scale.

Training noise comes from :class:`GaussianNoise`, which owns its seeded ``torch.Generator`` (so a
resumed run draws the same noise as an uninterrupted one); evaluation noise comes from
:func:`evaluation_noise`, seeded from the image's name and sigma, so that every pattern and every
method is scored on identical noise. Nothing here touches Python's ``random`` or global RNGs.
"""

from __future__ import annotations

import hashlib
import math
from numbers import Real
from typing import Any

import torch

__all__ = [
    "GaussianNoise",
    "add_evaluation_noise",
    "check_sigma",
    "evaluation_noise",
    "evaluation_seed",
]


def check_sigma(sigma: Any) -> float:
    """A noise level in 8-bit units: a finite number ``>= 0``.

    Raises:
        TypeError: Not a number.
        ValueError: Negative, infinite or NaN.
    """
    if isinstance(sigma, bool) or not isinstance(sigma, Real):
        raise TypeError(f"expected sigma as a number (8-bit units), got {type(sigma).__name__}")
    if not (math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"expected a finite sigma >= 0 (8-bit units), got {sigma}")
    return float(sigma)


class GaussianNoise:
    """``raw + n`` with ``n ~ N(0, (sigma / 255)^2)``; sigma fixed or drawn from ``U[lo, hi]``.

    Args:
        sigma: A fixed sigma, or a ``(lo, hi)`` range to draw from (the paper: ``(0, 30)``).
        per_sample: Draw one sigma per sample instead of one per batch (the paper's choice).
        seed: Seed of the generator that draws sigmas and noise.

    Shape:
        - raw: ``(N, 1, H, W)``; returns the noisy raw image and the sigmas ``(N,)`` used.
    """

    def __init__(
        self,
        sigma: float | tuple[float, float] = (0.0, 30.0),
        *,
        per_sample: bool = False,
        seed: int = 0,
    ) -> None:
        lo, hi = (sigma, sigma) if isinstance(sigma, (int, float)) else tuple(sigma)
        if not 0 <= lo <= hi < float("inf"):
            raise ValueError(f"expected 0 <= sigma_lo <= sigma_hi, got {sigma!r}")
        self.range = (float(lo), float(hi))
        self.per_sample = per_sample
        self.generator = torch.Generator().manual_seed(seed)

    def __call__(self, raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        lo, hi = self.range
        n = raw.shape[0] if self.per_sample else 1
        sigma = lo + (hi - lo) * torch.rand(n, generator=self.generator, dtype=torch.float64)
        sigma = sigma.expand(raw.shape[0]) if n == 1 else sigma
        # Drawn on the CPU generator then moved: the same stream on every device.
        noise = torch.randn(raw.shape, generator=self.generator, dtype=torch.float32)
        noise = noise.to(device=raw.device, dtype=raw.dtype)
        scale = (sigma / 255.0).to(device=raw.device, dtype=raw.dtype).view(-1, 1, 1, 1)
        return raw + scale * noise, sigma.float()

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {"generator": self.generator.get_state()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.generator.set_state(state["generator"])


def evaluation_seed(image_name: str, sigma: float) -> int:
    """A 63-bit seed from the image name and sigma (stable across runs, machines and methods)."""
    digest = hashlib.sha256(f"splitcam-eval|{image_name}|{float(sigma):g}".encode()).digest()
    return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)


def evaluation_noise(
    shape: tuple[int, ...],
    image_name: str,
    sigma: float,
    *,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str = "cpu",
) -> torch.Tensor:
    """The deterministic evaluation noise ``N(0, (sigma/255)^2)`` of one image at one sigma.

    The same for every pattern and method (it depends only on the name, sigma and shape), so
    differences in scores come from the methods, not from the draw.
    """
    sigma = check_sigma(sigma)
    gen = torch.Generator().manual_seed(evaluation_seed(image_name, sigma))
    noise = torch.randn(shape, generator=gen, dtype=torch.float64) * (float(sigma) / 255.0)
    return noise.to(device=device, dtype=dtype)


def add_evaluation_noise(raw: torch.Tensor, image_name: str, sigma: float) -> torch.Tensor:
    """``raw`` plus :func:`evaluation_noise` (returned unchanged for ``sigma == 0``)."""
    if check_sigma(sigma) == 0:
        return raw
    return raw + evaluation_noise(
        tuple(raw.shape), image_name, sigma, dtype=raw.dtype, device=raw.device
    )
