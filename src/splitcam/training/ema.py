"""An exponential moving average of the network's weights (``optim.ema``).

With a batch of 8 the weights at the last step carry the noise of the last few batches; their
average over the last ``1 / (1 - decay)`` steps does not. :class:`WeightAverage` keeps that
average in float32 beside the network and is what a run validates and exports when it is on:
the checkpoint holds it as ``ema/<name>`` next to the trained ``model/<name>`` (which a resume
continues from), and :func:`splitcam.recon.loading.load_network` (hence ``evaluate
--checkpoint`` and ``models export``) prefers it. Only the network is averaged; learned kernels
are taken as they are at the step (they move slowly and the pattern file must match what the
network saw).

The decay warms up as ``min(decay, (1 + n) / (10 + n))`` after ``n`` updates, so an average
started from fresh weights does not remember them for ``1 / (1 - decay)`` steps. When the
divergence guard rolls the weights back, the average restarts from the restored weights: an
average that had taken in the steps before the divergence would carry their damage.

Our own, not ``torch.optim.swa_utils.AveragedModel``: that keeps a deep copy of the module
(parameters in the module's dtype) and has no notion of the checkpoint's named sections or of the
guard's roll-backs; here the average is a dict of named float32 tensors, which is what the
checkpoint stores.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch
from torch import nn

from ..io.checkpoints import EMA_PREFIX

__all__ = ["EMA_PREFIX", "WeightAverage"]


class WeightAverage:
    """The running average of ``module``'s parameters (buffers are copied as they are).

    Args:
        module: The network whose weights are averaged.
        decay: Weight of the old average at each update, in (0, 1).
        updates: Updates done so far (from a checkpoint; drives the warm-up).
    """

    def __init__(self, module: nn.Module, decay: float, updates: int = 0) -> None:
        if not 0 < decay < 1:
            raise ValueError(f"expected an average decay in (0, 1), got {decay!r}")
        self.module = module
        self.decay = float(decay)
        self.updates = int(updates)
        #: The names averaged (the rest of the state, buffers, is copied).
        self._averaged = {n for n, p in module.named_parameters() if p.is_floating_point()}
        self.shadow: dict[str, torch.Tensor] = {}
        self.reset()

    def reset(self) -> None:
        """Start the average afresh from the module's current weights."""
        self.shadow = {
            k: v.detach().float().clone() if v.is_floating_point() else v.detach().clone()
            for k, v in self.module.state_dict().items()
        }
        self.updates = 0

    def rate(self) -> float:
        """The decay of the next update (warmed up)."""
        return min(self.decay, (1 + self.updates) / (10 + self.updates))

    @torch.no_grad()
    def update(self) -> None:
        """Fold the module's current weights into the average."""
        d = self.rate()
        for k, v in self.module.state_dict().items():
            if k in self._averaged:
                self.shadow[k].mul_(d).add_(v.detach().float(), alpha=1 - d)
            else:
                self.shadow[k].copy_(v)
        self.updates += 1

    def load(self, state: dict[str, torch.Tensor], updates: int) -> None:
        """Take an average saved in a checkpoint (its names must be the module's)."""
        own = self.module.state_dict()
        if set(state) != set(own):
            raise ValueError("the saved weight average belongs to another network")
        self.shadow = {k: v.detach().to(own[k].device).clone() for k, v in state.items()}
        self.updates = int(updates)

    @contextlib.contextmanager
    def applied(self) -> Iterator[None]:
        """The module with the averaged weights inside the block, its own after it."""
        own = {k: v.detach().clone() for k, v in self.module.state_dict().items()}
        self.module.load_state_dict({k: v.to(own[k].dtype) for k, v in self.shadow.items()})
        try:
            yield
        finally:
            self.module.load_state_dict(own)
