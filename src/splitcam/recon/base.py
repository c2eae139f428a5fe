"""The one reconstruction interface, and its implementation for a trained network.

A *reconstruction method* is anything with a ``name``, the ``pattern`` whose raw images it
reconstructs, and ``reconstruct(raw, sigma) -> rgb`` (:class:`Reconstructor`): classical
demosaicking (:mod:`splitcam.recon.demosaic`), the LMMSE filters (:mod:`splitcam.recon.lmmse`)
and trained networks (:class:`NetworkReconstructor`) alike. The evaluation protocol, the CLI and
the Python API only ever talk to this interface; :mod:`splitcam.recon.registry` builds one from a
name.

A method also works in a light domain (model.md §13), its ``domain`` attribute: ``srgb`` (the
raw image is of display values and the estimate is of display values, the paper's protocol) or
``linear`` (the raw image is of linear radiance and so is the estimate). A method without the
attribute is of ``srgb`` (:func:`method_domain`).
"""

from __future__ import annotations

import copy
from typing import Protocol, runtime_checkable

import torch
from torch import nn

from ..io.domains import SRGB
from ..patterns import Pattern
from ..physics.light import check_domain
from ..physics.noise import check_level, check_sigma
from ..physics.sensor import pattern_pixel_kernels

__all__ = [
    "PRECISIONS",
    "NetworkReconstructor",
    "Reconstructor",
    "check_level",
    "check_sigma",
    "fast_precision",
    "method_domain",
    "strict_float32",
]

#: Network precision settings: ``auto`` (bfloat16 + channels-last where a measurement on this
#: machine found it faster, float32 elsewhere), ``fp32`` (bit-exact float32) and ``bf16``
#: (bfloat16 + channels-last everywhere; slow on CPUs without native bfloat16).
PRECISIONS = ("auto", "fp32", "bf16")


def fast_precision(precision: str, device: torch.device | str) -> bool:
    """Whether a network runs in bfloat16 + channels-last for this ``precision`` on ``device``.

    ``auto`` takes whichever a short measurement on this machine found faster, remembered per
    device model and torch version (:func:`~splitcam.recon.precision.choose_precision`):
    bfloat16 was 4x faster on an AMD EPYC with AVX512-BF16 and 1.4x slower on an Intel Xeon with
    the same flag; CPUs without native bfloat16 take float32 without measuring.

    Raises:
        ValueError: An unknown ``precision``.
    """
    if precision not in PRECISIONS:
        known = ", ".join(PRECISIONS)
        raise ValueError(f"unknown precision {precision!r}; expected one of {known}")
    if precision != "auto":
        return precision == "bf16"
    from .precision import choose_precision

    return choose_precision(device).fast


def strict_float32(device: torch.device | str) -> None:
    """Make float32 on a CUDA ``device`` full float32: PyTorch lets cuDNN convolutions use
    TensorFloat-32 (a 10-bit mantissa) by default, so a network asked to run in ``fp32`` there
    would not be. Process-wide (the backends' own switches); nothing changes on a CPU."""
    if torch.device(device).type == "cuda":
        torch.backends.cudnn.allow_tf32 = False
        torch.backends.cuda.matmul.allow_tf32 = False


@runtime_checkable
class Reconstructor(Protocol):
    """A reconstruction method: raw image of ``pattern`` plus noise level in, RGB estimate out.

    Attributes:
        name: Short label for tables, e.g. ``"lmmse"`` or ``"malvar2004"``.
        pattern: The sensor pattern whose raw images the method reconstructs.

    An optional ``domain`` attribute (``"srgb"`` or ``"linear"``, read by
    :func:`method_domain`; ``"srgb"`` where absent) says whether raw images and estimates are
    of display values or of linear radiance.
    """

    name: str
    pattern: Pattern

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        """Estimate the scene.

        Args:
            raw: Raw sensor image (noise included).
            sigma: The noise level in 8-bit units (methods may ignore it).

        Returns:
            RGB estimate, float, not clamped, same dtype as ``raw``.

        Shape:
            - raw: ``(N, 1, H, W)``.
            - output: ``(N, 3, H, W)``.
        """
        ...


def method_domain(method: object) -> str:
    """The light domain a reconstruction method works in: its ``domain`` attribute, ``srgb``
    where it has none.

    Raises:
        ValueError: The attribute is not a known domain.
    """
    return check_domain(getattr(method, "domain", None) or SRGB)


class NetworkReconstructor:
    """A trained network (with the pattern it was trained for) as a :class:`Reconstructor`.

    Reconstruction is tiled (:func:`splitcam.recon.tiling.reconstruct`), so memory stays bounded
    on large images; the result equals the untiled network's up to float error.

    Args:
        network: A reconstruction network (``period`` and ``receptive_radius`` attributes).
        pattern: The pattern whose raw images it reconstructs (learned kernels included).
        name: Label in tables.
        tile: Tile size in pixels (``None``: whole images).
        precision: ``auto`` (bfloat16 + channels-last where the hardware runs it natively, see
            :func:`fast_precision`; about 3x faster on such CPUs), ``fp32`` (bit-exact float32)
            or ``bf16``. Resolved for the device of each raw image.
        domain: The light domain the network was trained in (``srgb`` or ``linear``).
        any_pattern: The network reconstructs whatever pattern it is told (a network of any
            pattern not fine-tuned on one): :meth:`for_pattern` gives it another.
        fingerprint: What, beyond the weights, identifies its results (the model file, the
            pattern's values; :mod:`splitcam.evaluation.protocol`).
    """

    def __init__(
        self,
        network: nn.Module,
        pattern: Pattern,
        name: str,
        *,
        tile: int | None = 512,
        precision: str = "auto",
        domain: str = SRGB,
        any_pattern: bool = False,
        fingerprint: str | None = None,
    ) -> None:
        fast_precision(precision, "cpu")  # an unknown precision fails here, not at first use
        self.domain = check_domain(domain)
        self.network = network
        self.pattern = pattern
        self.name = name
        self.tile = tile
        self.precision = precision
        #: Show a progress bar over the tiles (what the CLI turns on for large images).
        self.progress = False
        self.any_pattern = any_pattern
        self.fingerprint = fingerprint
        self._kernels = pattern_pixel_kernels(pattern)

    def for_pattern(self, pattern: Pattern) -> NetworkReconstructor:
        """The same network told another pattern (the flipped looks of
        :class:`~splitcam.recon.ensemble.SelfEnsemble`); only where :attr:`any_pattern`."""
        if not self.any_pattern:
            raise ValueError(f"{self.name} reconstructs the raw images of its own pattern only")
        other = copy.copy(self)
        other.pattern = pattern
        other._kernels = pattern_pixel_kernels(pattern)
        return other

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        from .tiling import reconstruct

        check_level(sigma)
        fast = fast_precision(self.precision, raw.device)
        if not fast:
            strict_float32(raw.device)
        return reconstruct(
            self.network,
            raw,
            tile=self.tile,
            bf16=fast,
            channels_last=fast,
            sigma=sigma,
            kernels=self._kernels,
            progress=self.progress,
        )

    def __repr__(self) -> str:
        return f"NetworkReconstructor({self.name!r}, pattern={self.pattern.name!r})"
