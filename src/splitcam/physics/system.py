"""The whole imaging system: splitter sensor, noise, reconstruction network (paper Fig. 6a), and
:func:`simulate`, the one way every command turns a test scene into the raw image a method sees."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

from .noise import NoiseModel, as_noise
from .sensor import SplitterSensor

__all__ = ["ImagingSystem", "simulate"]

NoiseFn = Callable[[torch.Tensor], tuple[torch.Tensor, list[NoiseModel]]]


class ImagingSystem(nn.Module):
    """``network(noise(sensor(rgb)))``: what the joint optimisation trains end to end.

    One module holds both the sensor (whose kernels may be learnable) and the network, so one
    optimiser, one ``state_dict`` and one DistributedDataParallel wrapper cover both.

    Args:
        sensor: The splitter sensor (fixed or learnable).
        network: A reconstruction network whose ``period`` matches the sensor's.

    Shape:
        - rgb: ``(N, 3, H, W)``; output ``(N, 3, H, W)``.
    """

    def __init__(self, sensor: SplitterSensor, network: nn.Module) -> None:
        super().__init__()
        period = getattr(network, "period", sensor.period)
        if period is not None and tuple(period) != sensor.period:  # None: any period
            raise ValueError(
                f"expected a network for the sensor's period {sensor.period}, got {period}"
            )
        self.sensor = sensor
        self.network = network
        #: Feed the network channels-last tensors (faster convolutions on some CPUs).
        self.channels_last = False
        self._compiled: nn.Module | None = None

    def compile_network(self) -> None:
        """Run the network through ``torch.compile`` from now on.

        The compiled wrapper is kept outside the module tree, so ``state_dict`` keys (and hence
        checkpoints) are the same with and without compilation.
        """
        object.__setattr__(self, "_compiled", torch.compile(self.network))

    def forward(self, rgb: torch.Tensor, noise: NoiseFn | None = None) -> torch.Tensor:
        # The physics stays in full precision under a mixed-precision autocast: only the
        # network runs in reduced precision.
        with torch.autocast(rgb.device.type, enabled=False):
            raw = self.sensor(rgb)
        sigma: float | list = 0.0
        if noise is not None:
            raw, sigma = noise(raw)
        if self.channels_last:
            raw = raw.contiguous(memory_format=torch.channels_last)
        network = self._compiled if self._compiled is not None else self.network
        if getattr(self.network, "uses_physics", False):
            # A network that is told the physics: the noise level and the sensor's current
            # kernels (through which gradients reach a learned pattern).
            with torch.autocast(rgb.device.type, enabled=False):
                kernels = self.sensor.pixel_kernels()
            return network(raw, sigma, kernels)
        return network(raw)


#: Rows per strip in :func:`simulate`: bounds the float64 copy of a large scene.
SIMULATE_STRIP = 256


def simulate(
    sensor: SplitterSensor,
    rgb: torch.Tensor,
    image_name: str,
    sigma: float | NoiseModel,
    *,
    strip: int = SIMULATE_STRIP,
) -> torch.Tensor:
    """The noisy raw image of a test scene: the protocol of ``evaluate``, validation,
    ``simulate`` and ``reconstruct`` alike.

    The sensor runs in float64 (the raw image is then float32), in strips of ``strip`` rows so
    that a large scene never exists in float64 at once; the strips overlap by the kernel's reach
    rounded up to whole periods, so the result equals the sensor on the whole image exactly.
    Noise is the deterministic evaluation noise of ``image_name`` at the level ``sigma``, the
    same for every method: a :class:`~splitcam.physics.noise.NoiseModel`'s
    :meth:`~splitcam.physics.noise.NoiseModel.add` (a number is a Gaussian sigma; an
    :class:`~splitcam.physics.noise.Exposure` is the photon model).

    Shape:
        - rgb: ``(N, 3, H, W)``; output ``(N, 1, H, W)`` float32 on ``rgb``'s device.

    >>> import torch
    >>> from splitcam.physics import SplitterSensor, simulate
    >>> sensor, grey = SplitterSensor("D"), torch.full((1, 3, 4, 4), 0.5)
    >>> clean = simulate(sensor, grey, "photo", 0.0)
    >>> clean.shape, clean.dtype
    (torch.Size([1, 1, 4, 4]), torch.float32)
    >>> noisy = simulate(sensor, grey, "photo", 10.0)
    >>> torch.equal(noisy, simulate(sensor, grey, "photo", 10.0))  # the same noise every time
    True
    >>> torch.equal(noisy, simulate(sensor, grey, "other", 10.0))  # each image its own
    False
    """
    noise = as_noise(sigma)
    ph = sensor.period[0]
    kh = sensor.kernels.shape[-2] if hasattr(sensor, "kernels") else sensor.weights().shape[-2]
    halo = -(-(kh // 2) // ph) * ph
    step = max(ph, strip // ph * ph)
    h = rgb.shape[-2]
    out = torch.empty((rgb.shape[0], 1, *rgb.shape[-2:]), dtype=torch.float32, device=rgb.device)
    with torch.no_grad(), torch.autocast(rgb.device.type, enabled=False):
        for top in range(0, h, step):
            lo, hi = max(0, top - halo), min(h, top + step + halo)
            raw = sensor(rgb[:, :, lo:hi].double())
            out[:, :, top : min(h, top + step)] = raw[:, :, top - lo : top - lo + step].float()
        return noise.add(out, image_name)
