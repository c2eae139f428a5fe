"""Distributed training under ``torchrun``: joining and leaving the process group, and the few
collectives the training loop needs (every rank calls each of them on the same step).

With one process (no ``WORLD_SIZE`` above 1) every helper is a no-op that returns its input, so
the training loop reads the same with and without DistributedDataParallel.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch


@dataclass
class DistInfo:
    """This process's place in the run: its rank, the number of processes, its local rank."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def init_distributed(device_kind: str) -> DistInfo:
    """Join the process group ``torchrun`` set up (gloo on CPU, nccl on CUDA), if any."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return DistInfo()
    import torch.distributed as dist

    if not dist.is_initialized():
        dist.init_process_group(backend="nccl" if device_kind == "cuda" else "gloo")
    return DistInfo(dist.get_rank(), dist.get_world_size(), int(os.environ.get("LOCAL_RANK", 0)))


def is_main_process() -> bool:
    """Whether this is rank 0 (or the only process), known before the process group exists."""
    return int(os.environ.get("RANK", "0")) == 0


def distributed_initialized() -> bool:
    import torch.distributed as dist

    return dist.is_available() and dist.is_initialized()


def end_distributed(destroy: bool) -> None:
    """The one end of a distributed run, the same on every rank: a barrier after the last
    collective (the final checkpoint's gathers), so that no rank leaves while another still
    communicates, then the process group's teardown, if this run started it. Left to
    interpreter shutdown, gloo's worker threads can outlive Python and abort the process
    ("terminate called without an active exception") after the work is done."""
    if not distributed_initialized():
        return
    import gc

    import torch.distributed as dist

    # DistributedDataParallel's reducer holds the process group; collect it (it can sit in a
    # reference cycle) so the group is torn down here, not at interpreter exit.
    gc.collect()
    dist.barrier()
    if destroy:
        dist.destroy_process_group()


def wrap_model(module: torch.nn.Module, device: torch.device, info: DistInfo) -> torch.nn.Module:
    """``module`` itself, or under several processes its DistributedDataParallel wrapper (which
    averages the gradients of every rank in ``backward``)."""
    if info.world_size <= 1:
        return module
    from torch.nn.parallel import DistributedDataParallel

    return DistributedDataParallel(
        module, device_ids=[device.index] if device.type == "cuda" else None
    )


def max_over_ranks(value: float, info: DistInfo) -> float:
    """The largest ``value`` of all ranks."""
    if info.world_size == 1:
        return value
    import torch.distributed as dist

    t = torch.tensor([value], dtype=torch.float64)
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return float(t.item())


def agree(flag: bool, info: DistInfo) -> bool:
    """Whether ``flag`` is set on any rank: all ranks stop (or roll back) on the same step, else
    the others would wait forever in all-reduce."""
    if info.world_size == 1:
        return flag
    import torch.distributed as dist

    t = torch.tensor([1.0 if flag else 0.0])
    dist.all_reduce(t)
    return bool(t.item() > 0)


def gather(tensor: torch.Tensor, info: DistInfo) -> list[torch.Tensor]:
    """``tensor`` of every rank, in rank order (each rank gets them all)."""
    if info.world_size == 1:
        return [tensor]
    import torch.distributed as dist

    rows = [torch.empty_like(tensor) for _ in range(info.world_size)]
    dist.all_gather(rows, tensor)
    return rows
