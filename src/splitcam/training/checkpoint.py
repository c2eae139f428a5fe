"""What training adds to the checkpoint format (:mod:`splitcam.io.checkpoints`): the
optimiser's state as tensors and back, and the trained system of a run (its sensor fixed to the
pattern it had at that step) for continuing from it.
"""

from __future__ import annotations

import os

import torch

from ..io.checkpoints import Checkpoint, CheckpointError, require
from ..physics.sensor import SplitterSensor
from ..physics.system import ImagingSystem
from ..recon.loading import load_network

__all__ = ["CheckpointError", "load_optimizer", "load_system", "optimizer_tensors"]


def optimizer_tensors(optimizer: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], dict]:
    """Split an optimiser state into tensors and JSON-able hyper-parameters."""
    state = optimizer.state_dict()
    tensors = {}
    for index, slots in state["state"].items():
        for key, value in slots.items():
            value = value if isinstance(value, torch.Tensor) else torch.tensor(value)
            tensors[f"optim/{index}/{key}"] = value
    return tensors, {"param_groups": state["param_groups"]}


def load_optimizer(optimizer: torch.optim.Optimizer, ckpt: Checkpoint) -> None:
    state: dict[int, dict[str, torch.Tensor]] = {}
    for key, value in ckpt.section("optim").items():
        index, name = key.split("/", 1)
        state.setdefault(int(index), {})[name] = value
    require(ckpt, "optimizer", purpose="its optimiser state cannot be restored")
    try:
        groups = ckpt.meta["optimizer"]["param_groups"]
        optimizer.load_state_dict({"state": state, "param_groups": groups})
    except (ValueError, KeyError, TypeError) as exc:
        raise CheckpointError(
            f"checkpoint {ckpt.path!r}: optimiser state does not fit this run: {exc}"
        ) from None


def load_system(path: str | os.PathLike, device: str | torch.device = "cpu") -> ImagingSystem:
    """The trained system of a run folder or checkpoint, with the sensor fixed to the pattern
    it had at that step (a learned pattern is loaded as a fixed one), in eval mode."""
    network, pattern, _ = load_network(path)
    system = ImagingSystem(SplitterSensor(pattern), network)
    return system.to(device).eval()
