"""A divergence guard for training: roll back and lower the learning rate when the loss explodes.

Measured here (docs/results/divergence/): the default recipe (Adam peaking at 1e-3, batch 8,
bfloat16) trained patterns A and D stably for 1160 and 2160 steps, then the gradient norm grew
five-fold within 20 steps and the loss jumped from 1e-3 to 1e4-1e10 and never recovered: the
learning rate had become too large for the network where training had taken it (an Adam
instability, not one bad batch). Skipping the update of the exploding steps does not help (the
damage is done by the updates just before the loss shows it), and clipping the gradient norm
does not either (Adam's step is about the learning rate whatever the gradient's scale). What does
is what one would do by hand: go back to weights from before the instability and continue with a
smaller learning rate.

:class:`DivergenceGuard` keeps two in-memory snapshots of the model and optimizer (taken every
``every`` healthy steps, so the older one predates the last ``every`` to ``2 * every`` steps), a
window of recent losses, and a learning-rate scale. A step whose loss is not finite or exceeds
``factor`` times the median of the window is a divergence: its update is not applied, the older
snapshot is restored and the scale is multiplied by ``drop``. The scale is part of the run's
state (checkpoints record it, a resumed run keeps it); the snapshots and the window are not. A
run takes its first snapshot before its first update (:meth:`DivergenceGuard.start`), so even
an update that wrecks the network at once can be undone, and a resumed run seeds the window
with the losses it logged before (:meth:`DivergenceGuard.seed`), so a resumed run at a
learning rate far too high is caught at its first exploding step rather than after 20.

While the guard is rolling back (:attr:`DivergenceGuard.settled` is false) the run saves no
resumable checkpoint, and a run whose guard gives up saves none at all: the resumable state on
disk stays the last one saved while training was healthy.
"""

from __future__ import annotations

import collections
import copy
import math
import statistics
from typing import Any

import torch

__all__ = ["DivergenceGuard"]


class DivergenceGuard:
    """See the module docstring.

    Args:
        factor: Divergence threshold over the median recent loss (None: the guard only catches
            non-finite losses).
        every: Healthy steps between snapshots.
        history: Losses in the median's window.
        min_history: Losses needed before ``factor`` applies.
        drop: Learning-rate scale factor at each divergence.
        lr_scale: The scale so far (from a checkpoint).
    """

    def __init__(
        self,
        factor: float | None,
        *,
        every: int = 50,
        history: int = 100,
        min_history: int = 20,
        drop: float = 0.5,
        lr_scale: float = 1.0,
    ) -> None:
        if factor is not None and not (math.isfinite(factor) and factor > 0):
            raise ValueError(f"expected a divergence factor > 0, got {factor!r}")
        self.factor = factor
        self.every = every
        self.min_history = min_history
        self.drop = drop
        self.lr_scale = float(lr_scale)
        self.recent: collections.deque[float] = collections.deque(maxlen=history)
        self._snapshots: list[tuple[dict[str, Any], dict[str, Any]]] = []
        self._healthy = 0
        self._unsettled = False

    def start(self, model: torch.nn.Module, optimizer: torch.optim.Optimizer) -> None:
        """Snapshot the state before the first update (the one a roll-back can always reach)."""
        self._snapshots = [_state(model, optimizer)]
        self._healthy = 1

    def seed(self, losses: list[float]) -> None:
        """Start the window from losses logged before (a resumed run's last logged ones); the
        factor then applies from the first step."""
        finite = [x for x in losses if math.isfinite(x)]
        if finite:
            self.recent.extend(finite)
            self.min_history = min(self.min_history, len(self.recent))

    @property
    def settled(self) -> bool:
        """No roll-back yet, or ``every`` healthy steps since the last one: the state is one
        to save."""
        return not self._unsettled or self._healthy > self.every

    def diverged(self, loss: float) -> bool:
        """Whether a step with this loss diverged (not finite, or ``factor`` times the median)."""
        if not math.isfinite(loss):
            return True
        return (
            self.factor is not None
            and len(self.recent) >= self.min_history
            and loss > self.factor * statistics.median(self.recent)
        )

    def applied(self, loss: float, model: torch.nn.Module, optimizer: torch.optim.Optimizer):
        """Record a healthy step (its update applied); snapshot every ``every`` of them."""
        self.recent.append(loss)
        if self._healthy % self.every == 0:
            self._snapshots = [*self._snapshots[-1:], _state(model, optimizer)]
        self._healthy += 1

    def roll_back(self, model: torch.nn.Module, optimizer: torch.optim.Optimizer) -> None:
        """Restore the older snapshot (if any), lower the learning-rate scale, forget the
        window; the caller applies :attr:`lr_scale` to the schedule."""
        if self._snapshots:
            model_state, optimizer_state = self._snapshots[0]
            model.load_state_dict(model_state)
            optimizer.load_state_dict(optimizer_state)
            self._snapshots = self._snapshots[:1]
        self.lr_scale *= self.drop
        self.recent.clear()
        self._healthy = 1  # the restored state is the newest snapshot
        self._unsettled = True


def _state(model: torch.nn.Module, optimizer: torch.optim.Optimizer):
    return (
        {k: v.detach().clone() for k, v in model.state_dict().items()},
        copy.deepcopy(optimizer.state_dict()),
    )
