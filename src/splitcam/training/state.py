"""A training run's state and what its checkpoint holds.

:class:`Run` is what stays fixed while a run trains (its settings, device, processes, data for
validation); :class:`TrainState` is what the steps change (the model, the optimiser, the
divergence guard, the random generators, the step and the time spent). A checkpoint saves the
latter with the record of the former that provenance needs, and a resume restores it exactly:
the same weights, optimiser moments, generator states (of every rank) and guard scale.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from .. import patterns
from ..data.patches import PatchSampler
from ..io import atomic_path
from ..io import checkpoints as ckpt_io
from ..patterns.random import PatternMix
from ..physics.noise import Exposure, TrainingNoise
from ..physics.system import ImagingSystem
from . import seeds
from .adapters import BASE_PREFIX, folded_state, restore_base
from .checkpoint import load_optimizer, optimizer_tensors
from .config import TrainConfig
from .distributed import DistInfo, gather
from .ema import EMA_PREFIX, WeightAverage
from .guard import DivergenceGuard
from .teachers import Teachers


@dataclass
class Run:
    """What stays fixed while a run trains."""

    config: TrainConfig
    run_dir: Path
    device: torch.device
    dist: DistInfo
    #: bfloat16 autocast (else float32 throughout).
    fast: bool
    #: What the checkpoints record as the device (:func:`~splitcam.training.setup.device_name`).
    device_label: str
    #: The pattern the run started from (``Pattern.to_dict``).
    start_pattern: dict[str, Any]
    #: The patterns of a run over many (one per step), or None.
    mix: PatternMix | None = None
    #: What ``run.init_from`` started the run from (name, provenance), or None.
    init_from: dict[str, Any] | None = None
    train_images: int = 0
    val_images: list[tuple[str, torch.Tensor]] = field(default_factory=list)
    val_levels: list[float] | list[Exposure] = field(default_factory=list)
    val_patterns: list[patterns.Pattern] | None = None

    @property
    def checkpoint_path(self) -> Path:
        return self.run_dir / ckpt_io.CHECKPOINT_NAME

    @property
    def time_limit_s(self) -> float | None:
        limit = self.config.run.time_limit
        return 60 * limit if limit else None


@dataclass
class TrainState:
    """What the training steps change."""

    system: ImagingSystem
    optimizer: torch.optim.Optimizer
    guard: DivergenceGuard
    sampler: PatchSampler
    noise: TrainingNoise
    #: Steps done (of the whole schedule, for a run continued from another's weights).
    step: int
    #: The step this run's optimiser began at (its moments warm up from there).
    start_step: int = 0
    #: Training time of the run so far, all processes (validation not included).
    train_seconds: float = 0.0
    #: The latest batch drawn (its fingerprint goes into the checkpoint).
    last_batch: torch.Tensor | None = None
    #: The latest logged values (the training window's and the latest validation's).
    last_metrics: dict[str, float] = field(default_factory=dict)
    timed_out: bool = False
    #: The average of the network's weights (``optim.ema``), or None.
    ema: WeightAverage | None = None
    #: The per-pattern networks whose estimates are a second target (``optim.teacher_weight``),
    #: or None.
    teachers: Teachers | None = None
    #: The best validation PSNR (mean over levels) so far, whose weights are in
    #: ``best.safetensors`` (:func:`save_best`).
    best_val: float = float("-inf")
    #: The divergence guard gave up: the run ends without saving its (diverged) state.
    gave_up: bool = False
    #: The step of the resumable checkpoint on disk (None: none saved yet).
    saved_step: int | None = None


def restore(state: TrainState, loaded: ckpt_io.Checkpoint, run: Run) -> None:
    """Continue from a checkpoint: weights, optimiser, step, time spent and generators.

    The peak learning rates and Adam's betas are settings, not state: those of this run's
    configuration apply (a changed ``--lr`` too).
    """
    peaks = [group["peak_lr"] for group in state.optimizer.param_groups]
    ckpt_io.load_module(state.system, loaded)
    try:
        restore_base(state.system, loaded.section(BASE_PREFIX))
    except ValueError as exc:
        raise ckpt_io.CheckpointError(f"checkpoint {str(loaded.path)!r}: {exc}") from None
    load_optimizer(state.optimizer, loaded)
    state.step = int(loaded.meta["step"])
    state.train_seconds = float(loaded.meta.get("train_seconds", 0.0))
    best = loaded.meta.get("best_val")
    state.best_val = float(best) if best is not None else float("-inf")
    restore_rng(loaded, state.sampler, state.noise, run.dist)
    if state.ema is not None:
        saved = {k[len("network.") :]: v for k, v in loaded.section(EMA_PREFIX).items()}
        if saved:
            state.ema.load(saved, int(loaded.meta.get("ema_updates") or 0))
        else:  # an average switched on at a resume starts from the restored weights
            state.ema.reset()
    for group, peak in zip(state.optimizer.param_groups, peaks, strict=True):
        group["peak_lr"] = peak
        group["betas"] = tuple(run.config.optim.betas)


def save_checkpoint(state: TrainState, run: Run) -> None:
    """Write the checkpoint (on the main process; every rank takes part in the gathers), and for
    a learned pattern its ``pattern.toml`` (and a metasurface's height map)."""
    rng = gather_rng(state.sampler, state.noise, run.dist)
    replicas = replica_report(state.system, state.last_batch, run.dist)
    if not run.dist.is_main:
        return
    opt_tensors, opt_meta = optimizer_tensors(state.optimizer)
    model, base = folded_state(state.system)
    tensors = {f"model/{k}": v for k, v in model.items()}
    tensors.update({f"{BASE_PREFIX}/{k}": v for k, v in base.items()})
    tensors.update(opt_tensors)
    if state.ema is not None:
        tensors.update({f"{EMA_PREFIX}/network.{k}": v for k, v in state.ema.shadow.items()})
    tensors.update(rng)
    ckpt_io.save(run.checkpoint_path, _meta(state, run, opt_meta, replicas), tensors)
    state.saved_step = state.step
    _export_pattern(state.system, run)


def save_best(state: TrainState, run: Run, val: float) -> None:
    """Keep the weights that scored ``val``, the best validation so far, as ``best.safetensors``
    beside the latest checkpoint (main process only: validation runs there; no optimiser or
    generator state, so it needs no other rank). Readers of the run folder use the latest
    checkpoint and say where this one is (:func:`~splitcam.io.checkpoints.which_checkpoint`)."""
    state.best_val = val
    tensors = {f"model/{k}": v for k, v in folded_state(state.system)[0].items()}
    if state.ema is not None:
        tensors.update({f"{EMA_PREFIX}/network.{k}": v for k, v in state.ema.shadow.items()})
    meta = _meta(state, run, {}, {})
    ckpt_io.save(run.run_dir / ckpt_io.BEST_NAME, meta, tensors)


def _meta(
    state: TrainState, run: Run, opt_meta: dict[str, Any], replicas: dict[str, Any]
) -> dict[str, Any]:
    """The checkpoint's JSON header."""
    system = state.system
    return {
        "config": run.config.to_dict(),
        "step": state.step,
        "start_step": state.start_step,
        "network": system.network.config(),
        "pattern": system.sensor.to_pattern().to_dict(),
        "start_pattern": run.start_pattern,
        "optimizer": opt_meta,
        "world_size": run.dist.world_size,
        "train_seconds": state.train_seconds,
        "lr_scale": state.guard.lr_scale,
        "ema_updates": state.ema.updates if state.ema is not None else None,
        "best_val": state.best_val if state.best_val > float("-inf") else None,
        "device": run.device_label,
        "precision": "bf16" if run.fast else "fp32",
        "train_images": run.train_images,
        "init_from": run.init_from,
        "replicas": replicas,
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def _export_pattern(system: ImagingSystem, run: Run) -> None:
    """A learned pattern as ``pattern.toml``; a metasurface's height map too."""
    settings = run.config.pattern
    if settings.learn or settings.metasurface:
        patterns.save(
            system.sensor.to_pattern(f"{run.start_pattern['name']}-learned"),
            run.run_dir / "pattern.toml",
        )
    if settings.metasurface:
        export_profile(system.sensor, run.run_dir)


def export_profile(sensor: Any, run_dir: Path) -> None:
    """A metasurface run's learned height map: ``height.npy`` (µm) and ``height.png``."""
    import numpy as np

    from ..viz.patterns import draw_height_maps

    height = sensor.height().detach().cpu().to(torch.float64).numpy()
    with atomic_path(run_dir / "height.npy") as tmp:
        np.save(tmp, height)
    draw_height_maps(
        [("learned height map", height)],
        run_dir / "height.png",
        period=tuple(sensor.period),
        pitch=sensor.optics.pitch,
        max_height=sensor.optics.max_height,
    )


def replica_report(
    system: ImagingSystem, batch: torch.Tensor | None, info: DistInfo
) -> dict[str, Any]:
    """Per rank: a fingerprint of the model (network + sensor) and of the last batch drawn.

    Under DistributedDataParallel the models must be identical on every rank and the batches
    different; recording both in the checkpoint makes that checkable after the fact.
    """
    with torch.no_grad():
        params = [p.detach().double().flatten() for p in system.parameters()]
        weights = system.sensor.weights().detach().double().flatten()
        vec = torch.cat([*params, weights])
        ramp = torch.arange(1, vec.numel() + 1, dtype=torch.float64, device=vec.device)
        drawn = batch.double().sum() if batch is not None else vec.new_zeros(())
        fingerprint = torch.stack([vec.sum(), (vec * ramp).sum(), drawn.to(vec.device)]).cpu()
    rows = gather(fingerprint, info)
    return {
        "model_fingerprints": [[float(r[0]), float(r[1])] for r in rows],
        "batch_sums": [float(r[2]) for r in rows],
    }


def gather_rng(
    sampler: PatchSampler, noise: TrainingNoise, info: DistInfo
) -> dict[str, torch.Tensor]:
    """RNG states of every rank (collected on rank 0) so a resume draws the same batches: the
    patch sampler's, the noise's CPU generator's and, for noise drawn on an accelerator, its
    device generator's (``rng/noise-field/<rank>``)."""
    parts = {"sampler": sampler.generator.get_state(), **noise.state_dict()}
    sizes = {name: state.numel() for name, state in parts.items()}
    out = {"rng/torch": torch.get_rng_state()}
    keys = {"sampler": "sampler", "generator": "noise", "field": "noise-field"}
    for rank, state in enumerate(gather(torch.cat(list(parts.values())), info)):
        for name, chunk in zip(sizes, state.split(list(sizes.values())), strict=True):
            out[f"rng/{keys[name]}/{rank}"] = chunk.clone()
    return out


def restore_rng(
    loaded: ckpt_io.Checkpoint,
    sampler: PatchSampler,
    noise: TrainingNoise,
    info: DistInfo,
) -> None:
    """Set this rank's generators (and torch's) to the checkpoint's; a rank it holds none for
    (a run resumed with more processes than it had) is reseeded from the step. A device
    generator saved on another kind of device (or none saved) keeps its seed, said once."""
    key = f"rng/sampler/{info.rank}"
    if key in loaded.tensors:
        sampler.generator.set_state(loaded.tensors[key])
        state = {"generator": loaded.tensors[f"rng/noise/{info.rank}"]}
        if (field := loaded.tensors.get(f"rng/noise-field/{info.rank}")) is not None:
            state["field"] = field
        if not noise.load_state_dict(state):
            warnings.warn(
                f"the checkpoint holds no noise state for {noise.device.type}: the noise "
                "continues from a fresh stream",
                stacklevel=2,
            )
    else:
        warnings.warn(f"checkpoint has no RNG state for rank {info.rank}; reseeding", stacklevel=2)
        patches, sensor_noise = seeds.reseeded(sampler.seed, info.rank, int(loaded.meta["step"]))
        sampler.generator.manual_seed(patches)
        noise.generator.manual_seed(sensor_noise)
        noise.field.manual_seed(sensor_noise)
    torch.set_rng_state(loaded.tensors["rng/torch"])
