"""The whole imaging system: splitter sensor, noise, reconstruction network (paper Fig. 6a)."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

from .sensor import SplitterSensor

NoiseFn = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]]


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
        period = tuple(getattr(network, "period", sensor.period))
        if period != sensor.period:
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
        if noise is not None:
            raw, _ = noise(raw)
        if self.channels_last:
            raw = raw.contiguous(memory_format=torch.channels_last)
        network = self._compiled if self._compiled is not None else self.network
        return network(raw)
