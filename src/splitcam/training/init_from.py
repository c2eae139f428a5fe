"""``run.init_from``: a new run that starts from the weights of a model or of another run, and
``run.continue_schedule``: one that continues that run's schedule where it stopped."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import torch

from ..io import checkpoints as ckpt_io
from ..io.domains import SRGB
from ..physics.sensor import LearnableSplitterSensor, SplitterSensor
from ..physics.system import ImagingSystem
from ..recon.closed_form import shipped_image_statistics
from ..recon.loading import LoadedNetwork, ModelError, check_unambiguous, load_model, load_network
from ..recon.networks import UniversalReconNet
from .config import ConfigError, TrainConfig

logger = logging.getLogger(__name__)


def start_from(system: ImagingSystem, spec: str, domain: str = SRGB) -> dict[str, Any]:
    """Load the weights of a model or run into a new run's system (``run.init_from``).

    The network must have the same architecture (and period); a learned pattern starts from the
    source's kernels (logits ``log k``); a fixed one may be another pattern of that period (a
    head start: most of what the network learnt is not specific to the pattern). The statistics
    the network's LMMSE solves from come with the weights (``data.photo_statistics`` may have
    made them the photos' own); for a run in another light ``domain`` than the source's, they
    are the shipped ones of the run's. Returns what the checkpoints record: the source's name,
    its pattern if another, and accumulated provenance.
    """
    source, record = _load_source(spec)
    own_device = next(system.network.parameters()).device
    if isinstance(system.network, UniversalReconNet):
        _start_universal(system.network, source.network, spec, record, own_device)
    else:
        if source.network.config() != system.network.config():
            raise ConfigError(
                f"--init-from {spec}: its network {source.network.config()} differs from this "
                f"run's {system.network.config()}"
            )
        _start_pattern(system, source, spec, record)
        system.network.load_state_dict(source.network.to(own_device).state_dict())
    saved = (source.meta.get("config") or {}).get("data") or {}
    if hasattr(system.network, "use_statistics") and saved.get("domain", SRGB) != domain:
        system.network.use_statistics(shipped_image_statistics(domain))
    return record


def _load_source(spec: str) -> tuple[LoadedNetwork, dict[str, Any]]:
    """The network ``spec`` names (a run folder, a checkpoint, a shipped model or a model file)
    and the record of it a run keeps: its name and provenance."""
    from .models import provenance_of

    try:
        check_unambiguous(spec, "--init-from")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None
    path = Path(spec)
    if path.is_dir() or ckpt_io.run_folder_of(path) is not None:
        checkpoint = ckpt_io.resolve(path)
        if (note := ckpt_io.which_checkpoint(path)) is not None:
            logger.info(note)
        if not checkpoint.is_file():
            raise ConfigError(f"--init-from {spec}: no checkpoint there")
        source = load_network(checkpoint)
        return source, {
            "name": str(spec),
            "provenance": provenance_of(ckpt_io.load(checkpoint), checkpoint.parent),
        }
    try:
        source = load_model(spec)
    except ModelError as exc:
        raise ConfigError(f"--init-from: {exc}; or a run folder") from None
    meta = source.meta
    return source, {"name": meta.get("name", str(spec)), "provenance": meta.get("provenance")}


def _start_pattern(
    system: ImagingSystem, source: LoadedNetwork, spec: str, record: dict[str, Any]
) -> None:
    """A learned pattern starts from the source's kernels; a fixed one that differs from the
    source's is recorded (``record["pattern"]``) and said."""
    theirs = SplitterSensor(source.pattern)
    kernels = theirs.pixel_kernels().detach()
    own = system.sensor
    if isinstance(own, LearnableSplitterSensor):
        if tuple(own.logits.shape) != tuple(theirs.kernels.shape):
            raise ConfigError(f"--init-from {spec}: its pattern has another layout or kernel size")
        exact = LearnableSplitterSensor(source.pattern, init="exact")
        with torch.no_grad():
            own.logits.copy_(exact.logits)
    elif not torch.allclose(
        own.pixel_kernels().detach().cpu().double(), kernels.double(), atol=1e-6
    ):
        # Another pattern of the same period: what the network learnt (denoising, detail,
        # colour) is mostly not specific to the pattern, so it is a head start (the network
        # config, period included, matched by the caller).
        record["pattern"] = source.pattern.name
        logger.info(
            f"--init-from {spec}: its network was trained for pattern {record['pattern']}; "
            f"training it on for {own.to_pattern().name}"
        )


def _start_universal(
    own: UniversalReconNet, source: torch.nn.Module, spec: str, record: dict, device: Any
) -> dict[str, Any]:
    """``run.init_from`` for a universal network: another universal network of the same shape
    (for any pattern: fine-tuning), or a 2x2-period physics network whose trunk it starts from
    (:meth:`~splitcam.recon.networks.UniversalReconNet.load_physics_trunk`)."""
    state = source.to(device).state_dict()
    if isinstance(source, UniversalReconNet):
        if source.config() != own.config():
            raise ConfigError(
                f"--init-from {spec}: its network {source.config()} differs from this run's "
                f"{own.config()}"
            )
        own.load_state_dict(state)
    elif getattr(source, "arch", "") == "physics" and tuple(source.period) == (2, 2):
        try:
            own.load_physics_trunk(state)
        except ValueError as exc:
            raise ConfigError(f"--init-from {spec}: {exc}") from None
    else:
        raise ConfigError(
            f"--init-from {spec}: a universal network starts from a universal network or from a "
            f"2x2-period physics network, not from {source.config()}"
        )
    return record


def source_header(spec: str) -> dict[str, Any]:
    """The JSON header of what ``run.init_from`` names (a shipped model, a model file, a run
    folder or a checkpoint): its ``network`` and training ``config`` among others; empty where
    there is none to read."""
    from ..recon.loading import resolve_model

    path = Path(spec)
    if path.is_dir() or ckpt_io.run_folder_of(path) is not None:
        try:
            return ckpt_io.read_meta(ckpt_io.resolve(path))
        except (OSError, ValueError):
            return {}
    try:
        return json.loads(resolve_model(spec).read_text(encoding="utf-8"))
    except (ModelError, OSError, ValueError):
        return {}


def source_network(spec: str) -> dict[str, Any] | None:
    """The network config of what ``run.init_from`` names (:func:`source_header`); None where
    there is none to read."""
    return source_header(spec).get("network")


def continue_point(init_from: dict[str, Any], config: TrainConfig) -> tuple[int, float]:
    """Where a ``run.continue_schedule`` run begins: the source's total steps and the divergence
    guard's learning-rate scale at its end (from its provenance)."""
    provenance = init_from.get("provenance") or {}
    done = int(provenance.get("total_steps", 0))
    if not 0 < done < config.optim.steps:
        raise ConfigError(
            f"run.continue_schedule: {init_from['name']} has {done} steps of training; it must be "
            f"between 0 and optim.steps ({config.optim.steps}), the budget of the whole"
        )
    segments = provenance.get("segments") or [{}]
    return done, float(segments[-1].get("lr_scale", 1.0))
