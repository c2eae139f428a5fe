"""``optim.teacher_weight``: the shipped per-pattern networks as a second target.

On the steps whose pattern has a shipped network of its own (a one-pattern physics network of
the run's light domain), that network's estimate from the same noisy raw image is a second
target: the objective becomes ``loss(estimate, truth) + w * loss(estimate, teacher's)``. The
per-pattern networks are stronger than the network for any pattern on their own patterns, and
their estimates carry what they learnt with far more training per pattern (multi-teacher
distillation: Hinton et al., *Distilling the Knowledge in a Neural Network*, 2015; in image
restoration, e.g. He et al., *FAKD*, ICIP 2020).

:class:`Teachers` reads the network's inputs with a forward pre-hook, so the raw image the
teacher sees is exactly the student's (same patch, same noise draw) and nothing in the system
or its forward changes.
"""

from __future__ import annotations

import logging
from typing import Any

import torch
from torch import nn

from ..patterns import Pattern
from ..recon.loading import load_model, model_names
from ..recon.networks import serves_any_pattern
from ..recon.registry import trained_domain

__all__ = ["Teachers"]

logger = logging.getLogger(__name__)


class Teachers:
    """Per-pattern networks (``(pattern, network)`` pairs) and the student's latest inputs.

    Args:
        pairs: Each teacher's pattern and network (physics networks, called as
            ``net(raw, sigma, kernels)``).
    """

    def __init__(self, pairs: list[tuple[Pattern, nn.Module]]) -> None:
        self.pairs = pairs
        self._inputs: tuple[Any, ...] | None = None
        self._hook: Any = None

    @classmethod
    def shipped(cls, candidates: list[Pattern], domain: str, device: torch.device) -> Teachers:
        """The shipped one-pattern networks of the light ``domain`` for the patterns among
        ``candidates`` that have one."""
        pairs = []
        for name in model_names():
            loaded = load_model(name)
            if serves_any_pattern(loaded.network):
                continue
            if trained_domain(loaded.meta.get("config")) != domain:
                continue
            if any(loaded.pattern.equals(p) for p in candidates):
                network = loaded.network.to(device).eval().requires_grad_(False)
                pairs.append((loaded.pattern, network))
        return cls(pairs)

    @property
    def names(self) -> list[str]:
        return [pattern.name for pattern, _ in self.pairs]

    def watch(self, network: nn.Module) -> None:
        """Keep the inputs of each call of ``network`` (the student)."""

        def keep(module: nn.Module, args: tuple[Any, ...]) -> None:
            del module
            self._inputs = tuple(a.detach() if torch.is_tensor(a) else a for a in args)

        self._hook = network.register_forward_pre_hook(keep)

    def estimate(self, pattern: Pattern | None = None) -> torch.Tensor | None:
        """The teacher of ``pattern``'s estimate from the student's latest raw image and noise
        level, or None where ``pattern`` has no teacher. ``None``: a run of one pattern, whose
        teachers are that pattern's own (at most one)."""
        for own, network in self.pairs:
            if pattern is None or own.equals(pattern):
                if self._inputs is None:
                    raise RuntimeError("no input seen yet: call watch() and run the student")
                raw, sigma, kernels = self._inputs[:3]
                with torch.no_grad(), torch.autocast(raw.device.type, enabled=False):
                    return network(raw.float(), sigma, kernels.float())
        return None
