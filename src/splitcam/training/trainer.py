"""The training loop: fixed or joint (pattern + network) optimisation, checkpoints, resume,
validation, logs, and DistributedDataParallel when started by ``torchrun``."""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F

from .. import patterns
from ..data.patches import ImageCache, PatchSampler, list_images
from ..data.testsets import centre_crop
from ..evaluation.protocol import mean_psnr
from ..io import appending, atomic_path, stale_temporaries, write_text
from ..patterns.random import PatternMix
from ..physics.noise import Exposure, GaussianNoise, PhotonNoise
from ..physics.sensor import LearnableSplitterSensor, SplitterSensor, SwitchingSensor
from ..physics.system import ImagingSystem
from ..recon.base import NetworkReconstructor, fast_precision
from ..recon.design import design_pattern
from ..recon.networks import UniversalReconNet, build_network
from . import checkpoint as ckpt_io
from .config import ConfigError, TrainConfig, read_config_file
from .guard import DivergenceGuard
from .schedule import learning_rate
from .schedule import progress as progress_of

METRICS_NAME = "metrics.jsonl"


@dataclass
class DistInfo:
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


def resolve_device(name: str, local_rank: int = 0) -> torch.device:
    if name == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda", local_rank)
        mps = getattr(torch.backends, "mps", None)
        if mps is not None and mps.is_available():
            return torch.device("mps")
        return torch.device("cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        raise ConfigError(f"unknown device {name!r}; use auto, cpu, cuda, cuda:N or mps") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError("device 'cuda' requested but no CUDA device is available")
    if device.type == "cuda" and device.index is None:
        device = torch.device("cuda", local_rank)
    return device


def build_system(
    config: TrainConfig, pattern: patterns.Pattern | None = None, *, design: bool = True
) -> ImagingSystem:
    """Sensor + network from a configuration (network weights freshly initialised).

    A learned pattern with ``pattern.design_steps`` starts from the kernels that
    :func:`~splitcam.recon.design.design_pattern` finds from its initialisation (unless
    ``design`` is false: a resumed run loads its own kernels).
    """
    mix = pattern_mix(config)
    pattern = pattern or (mix.pattern(0) if mix else patterns.get(config.pattern.name))
    if mix is not None:
        sensor: SplitterSensor = SwitchingSensor(pattern)
    elif config.pattern.learn:
        gen = torch.Generator().manual_seed(config.run.seed + 17)
        sensor = LearnableSplitterSensor(pattern, init=config.pattern.init, generator=gen)
        if design and config.pattern.design_steps:
            designed = design_pattern(
                pattern,
                init=config.pattern.init,
                steps=config.pattern.design_steps,
                seed=config.run.seed + 17,
            )
            with torch.no_grad():
                sensor.logits.copy_(designed.logits)
    elif config.pattern.metasurface:
        sensor = _metasurface_sensor(config.pattern.metasurface, pattern.period, config.run.seed)
    else:
        sensor = SplitterSensor(pattern)
    net = build_network(
        {
            "arch": config.network.arch,
            "period": list(pattern.period),
            "features": config.network.features,
            "blocks": config.network.blocks,
        }
    )
    return ImagingSystem(sensor, net)


def pattern_mix(config: TrainConfig) -> PatternMix | None:
    """The patterns of a ``--pattern random`` run (one per step), or None for one pattern."""
    if config.pattern.name.strip().lower() != "random":
        return None
    named = [patterns.get(name) for name in config.pattern.mix]
    return PatternMix(named, config.pattern.mix_fraction, seed=config.run.seed + 31)


def _metasurface_sensor(spec: str, period: tuple[int, int], seed: int) -> SplitterSensor:
    """A :class:`~splitcam.optics.MetasurfaceSensor` of the default geometry starting from
    :func:`~splitcam.optics.profile` ``spec`` (``random``, ``lens``, ``flat`` or a .npy file)."""
    from ..optics import MetasurfaceSensor, Optics, profile

    optics = Optics()
    try:
        return MetasurfaceSensor(profile(spec, period, optics, seed + 17), period, optics)
    except ValueError as exc:
        raise ConfigError(f"pattern.metasurface: {exc}") from None


def _export_profile(sensor: Any, run_dir: Path) -> None:
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


def device_name(device: torch.device) -> str:
    """What the run trained on, for provenance: ``cuda (NVIDIA H100 ...)`` or ``cpu (<model>,
    <instruction set>, N threads)``."""
    if device.type == "cuda":
        return f"cuda ({torch.cuda.get_device_name(device)})"
    import platform

    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    # The instruction set matters as much as the name: one "AMD EPYC" did 7.0 steps/s with
    # AVX512 (native bfloat16), another 2.4 with AVX2 only.
    capability = torch.backends.cpu.get_cpu_capability()
    threads = torch.get_num_threads()
    return f"{device.type} ({cpu}, {capability}, {threads} thread{'s' if threads != 1 else ''})"


def _start_from(system: ImagingSystem, spec: str) -> dict[str, Any]:
    """Load the weights of a model or run into a new run's system (``run.init_from``).

    The network must have the same architecture (and period); a learned pattern starts from the
    source's kernels (logits ``log k``); a fixed one may be another pattern of that period (a
    head start: most of what the network learnt is not specific to the pattern). Returns what the
    checkpoints record: the source's name, its pattern if another, and accumulated provenance.
    """
    from .models import ModelError, check_unambiguous, load_model, provenance_of

    try:
        check_unambiguous(spec, "--init-from")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None
    path = Path(spec)
    if path.is_dir() or path.name == ckpt_io.CHECKPOINT_NAME:
        checkpoint = ckpt_io.resolve(path)
        if not checkpoint.is_file():
            raise ConfigError(f"--init-from {spec}: no checkpoint there")
        source = ckpt_io.load_system(checkpoint)
        record = {
            "name": str(spec),
            "provenance": provenance_of(ckpt_io.load(checkpoint), checkpoint.parent),
        }
    else:
        try:
            source, meta = load_model(spec)
        except ModelError as exc:
            raise ConfigError(f"--init-from: {exc}; or a run folder") from None
        record = {"name": meta.get("name", str(spec)), "provenance": meta.get("provenance")}
    own_device = next(system.network.parameters()).device
    if isinstance(system.network, UniversalReconNet):
        return _start_universal(system.network, source.network, spec, record, own_device)
    if source.network.config() != system.network.config():
        raise ConfigError(
            f"--init-from {spec}: its network {source.network.config()} differs from this "
            f"run's {system.network.config()}"
        )
    kernels = source.sensor.pixel_kernels().detach()
    own = system.sensor
    if isinstance(own, LearnableSplitterSensor):
        if tuple(own.logits.shape) != tuple(source.sensor.kernels.shape):
            raise ConfigError(f"--init-from {spec}: its pattern has another layout or kernel size")
        exact = LearnableSplitterSensor(source.sensor.to_pattern(), init="exact")
        with torch.no_grad():
            own.logits.copy_(exact.logits)
    elif not torch.allclose(own.pixel_kernels().detach().double(), kernels.double(), atol=1e-6):
        # Another pattern of the same period: what the network learnt (denoising, detail,
        # colour) is mostly not specific to the pattern, so it is a head start (the network
        # config, period included, matched above). Said, and recorded.
        record["pattern"] = source.sensor.to_pattern().name
        print(
            f"--init-from {spec}: its network was trained for pattern {record['pattern']}; "
            f"training it on for {own.to_pattern().name}"
        )
    system.network.load_state_dict(source.network.to(own_device).state_dict())
    return record


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


def source_network(spec: str) -> dict[str, Any] | None:
    """The network config of what ``run.init_from`` names (a shipped model, a model file, a run
    folder or a checkpoint), read from its JSON header; None where there is none to read."""
    from .models import ModelError, resolve_model

    path = Path(spec)
    if path.is_dir() or path.name == ckpt_io.CHECKPOINT_NAME:
        try:
            return ckpt_io.read_meta(ckpt_io.resolve(path)).get("network")
        except (OSError, ValueError):
            return None
    try:
        return json.loads(resolve_model(spec).read_text(encoding="utf-8")).get("network")
    except (ModelError, OSError, ValueError):
        return None


def _continue_point(init_from: dict[str, Any], config: TrainConfig) -> tuple[int, float]:
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


def val_split(config: TrainConfig) -> int:
    """How many images (the last, sorted by name) the training folder holds out: the set
    ``data.val_split``, none with a ``data.val`` folder, else ``min(32, max(1, n // 10))`` of
    ``n >= 2`` images (so validation curves come by default)."""
    data = config.data
    if data.val or not data.train:
        return 0
    if data.val_split is not None:
        return data.val_split
    n = len(list_images(data.train))
    return min(32, max(1, n // 10)) if n >= 2 else 0


def _short_side(path: Path) -> int:
    """An image file's smaller side, from its header (an unreadable file counts as large:
    decoding reports it later, naming it)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return min(im.size)
    except OSError:
        return 1 << 30


def held_out(config: TrainConfig) -> list[Path]:
    """The training folder's validation images: the last ``val_split`` (sorted by name) of those
    that fit the validation crop (or, in a folder of smaller images, that are as large as its
    largest), so a tiny image sorting last is never the whole validation set.

    Raises:
        ConfigError: The split would leave no training image.
    """
    data = config.data
    split = val_split(config)
    if not split:
        return []
    files = list_images(data.train)
    sides = {f: _short_side(f) for f in files}
    need = min(data.val_crop or 1, max(sides.values()))
    chosen = [f for f in files if sides[f] >= need][-split:]
    if len(chosen) >= len(files):
        raise ConfigError(
            f"data.val_split {split} leaves no training images (the folder has {len(files)})"
        )
    return chosen


def _val_images(config: TrainConfig) -> list[tuple[str, torch.Tensor]]:
    """Validation images: the held-out split or the --val folder, centre-cropped."""
    data = config.data
    if data.val:
        source: Any = data.val
    elif val_split(config) and data.train:
        source = held_out(config)
    else:
        return []
    cache = ImageCache(source, min_size=1, max_images=data.val_max_images, progress=False)
    images = []
    for i, name in enumerate(cache.names):
        img = cache.image(i)
        if data.val_crop:
            img = centre_crop(img, data.val_crop, multiple=1)
        images.append((name, img.contiguous()))
    return images


def _train_source(config: TrainConfig) -> Any:
    if not config.data.train:
        raise ConfigError("no training data: give --data DIR (or data.train in the config)")
    held = set(held_out(config))
    if held:
        return [f for f in list_images(config.data.train) if f not in held]
    return config.data.train


def validate(
    system: ImagingSystem,
    images: list[tuple[str, torch.Tensor]],
    sigmas: list[float] | list[Exposure],
    val_patterns: list[patterns.Pattern] | None = None,
) -> dict[str, float]:
    """Mean PSNR per noise level (a sigma, or a photon-model exposure: ``val_psnr_N<photons>``)
    on the validation images, by the evaluation protocol itself
    (:func:`splitcam.evaluation.protocol.mean_psnr`): the pattern as a run's checkpoint records
    it, the same simulation, noise, reconstruction, rounding and averaging as ``splitcam
    evaluate``, so the logged value is what ``evaluate`` reports for this step.

    With ``val_patterns`` (a run over many patterns) each of them is scored
    (``val_psnr_<pattern>_<level>``) and the plain keys hold the means over the patterns."""
    was_training = system.training
    system.eval()
    targets = val_patterns or [system.sensor.to_pattern()]
    per_pattern = {}
    for pattern in targets:
        method = NetworkReconstructor(system.network, pattern, "validation")
        per_pattern[pattern.name] = mean_psnr(method, images, sigmas)
    system.train(was_training)

    def key(s: float | Exposure) -> str:
        return f"N{s.photons:g}" if isinstance(s, Exposure) else f"{s:g}"

    means = {s: sum(m[s] for m in per_pattern.values()) / len(per_pattern) for s in sigmas}
    out = {f"val_psnr_{key(s)}": value for s, value in means.items()}
    if val_patterns:
        for name, scores in per_pattern.items():
            out.update({f"val_psnr_{name}_{key(s)}": v for s, v in scores.items()})
    out["val_psnr"] = sum(means.values()) / len(means)
    return out


class _StopFlag:
    """Ctrl-C (SIGINT) or SIGTERM: finish the current step, save, and exit cleanly."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> _StopFlag:
        def handler(signum, frame):  # noqa: ARG001
            if self.requested:  # a second Ctrl-C stops at once
                raise KeyboardInterrupt
            self.requested = True

        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(ValueError):  # not in the main thread
                self._previous[sig] = signal.signal(sig, handler)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)


LOCK_NAME = ".lock"
CHANGES_NAME = "changes.jsonl"


def _last_metrics(path: Path) -> dict[str, float]:
    """The last logged row of a run's metrics (validation included where it was logged)."""
    last: dict[str, float] = {}
    if path.is_file():
        for line in path.read_text(encoding="utf-8").splitlines():
            with contextlib.suppress(ValueError):
                last.update(json.loads(line))
    return last


def _truncate_metrics(path: Path, step: int) -> None:
    """Drop log lines after ``step`` (steps a killed run did after its last checkpoint)."""
    if not path.is_file():
        return
    kept = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            if json.loads(line).get("step", 0) <= step:
                kept.append(line)
        except json.JSONDecodeError:
            continue  # a line cut by a kill
    write_text(path, "".join(k + "\n" for k in kept))


@dataclass
class TrainResult:
    run_dir: Path
    step: int
    interrupted: bool
    last_metrics: dict[str, float]
    #: Why the run failed (diverged past the guard, or ended far below where it started), or None.
    failure: str | None = None


#: The divergence guard gives up once it has halved the learning rate this many times.
GUARD_GIVES_UP = 10
#: A run that ends this many dB below its start in validation PSNR has failed.
FAILED_DROP_DB = 3.0


def failure_of(metrics_path: Path, last: dict[str, float], lr_scale: float) -> str | None:
    """Why a finished run failed, or None: its loss is not finite, the guard halved the learning
    rate :data:`GUARD_GIVES_UP` times, or its final validation PSNR is :data:`FAILED_DROP_DB`
    below the first one logged (the untrained network, or where a resumed run began)."""
    loss = last.get("loss")
    if loss is not None and not math.isfinite(loss):
        return f"the loss is {loss}: training diverged"
    if lr_scale <= 0.5**GUARD_GIVES_UP:
        return (
            f"the divergence guard halved the learning rate {GUARD_GIVES_UP} times and gave up: "
            f"training diverges at this learning rate (lower --lr)"
        )
    first, first_loss = None, None
    if metrics_path.is_file():
        for line in metrics_path.read_text(encoding="utf-8").splitlines():
            with contextlib.suppress(ValueError):
                row = json.loads(line)
                first = first or (row if "val_psnr" in row else None)
                first_loss = first_loss or row.get("loss")
    if first_loss and loss is not None and loss > 10 * first_loss:
        return (
            f"the training loss rose from {first_loss:.3g} to {loss:.3g}: training diverged "
            f"(lower --lr)"
        )
    if first is not None and "val_psnr" in last:
        drop = first["val_psnr"] - last["val_psnr"]
        if drop >= FAILED_DROP_DB:
            return (
                f"validation PSNR fell from {first['val_psnr']:.2f} dB at step {first['step']} "
                f"to {last['val_psnr']:.2f} dB: training diverged or the settings are wrong"
            )
    return None


def train(config: TrainConfig, *, resume: bool = False, progress: bool = True) -> TrainResult:
    """Train (or resume) a run; see :class:`~splitcam.training.config.TrainConfig`.

    The run folder gets ``config.json`` (the resolved configuration), ``metrics.jsonl`` (one
    JSON object per logged step), ``checkpoint.safetensors`` (+ ``.json``), for a learned
    pattern ``pattern.toml``, and, when a resume changed settings, ``changes.jsonl`` (step, old
    and new values; changed settings apply from there, those that define the model are
    refused). The folder is locked while the run trains: a second run on it is refused.

    Raises:
        ConfigError: Invalid settings, another run holds the folder, or nothing to resume.
        CheckpointError: The checkpoint to resume is damaged or of another model.
    """
    config.validate()
    run_dir = Path(config.run.out)
    ckpt_path = run_dir / ckpt_io.CHECKPOINT_NAME
    if resume:
        _resumable(run_dir)  # before the lock, so that a refused resume creates no folder
    # Under torchrun only rank 0 locks; the others wait for it in init_process_group.
    is_main = int(os.environ.get("RANK", "0")) == 0
    started_group = not _distributed_initialized()
    lock = _lock_run(run_dir) if is_main else None
    try:
        result = _train(config, run_dir, ckpt_path, resume, progress)
        _end_distributed(destroy=started_group)
        return result
    finally:
        if lock is not None:
            lock.close()


def _distributed_initialized() -> bool:
    import torch.distributed as dist

    return dist.is_available() and dist.is_initialized()


def _end_distributed(destroy: bool) -> None:
    """The one end of a distributed run, the same on every rank: a barrier after the last
    collective (the final checkpoint's gathers), so that no rank leaves while another still
    communicates, then the process group's teardown, if this run started it. Left to
    interpreter shutdown, gloo's worker threads can outlive Python and abort the process
    ("terminate called without an active exception") after the work is done."""
    if not _distributed_initialized():
        return
    import gc

    import torch.distributed as dist

    # DistributedDataParallel's reducer holds the process group; collect it (it can sit in a
    # reference cycle) so the group is torn down here, not at interpreter exit.
    gc.collect()
    dist.barrier()
    if destroy:
        dist.destroy_process_group()


def _resumable(run_dir: Path) -> None:
    """Refuse ``--resume`` of a folder with neither a checkpoint nor a ``config.json``."""
    if not (run_dir / ckpt_io.CHECKPOINT_NAME).exists() and not (run_dir / "config.json").is_file():
        raise ConfigError(f"no run to resume in {str(run_dir)!r}; drop --resume to start one there")


def resume_config(run_dir: str | Path) -> TrainConfig:
    """The settings of the run in ``run_dir`` (what ``--resume`` continues with): its
    checkpoint's, or, for a run that ended before its first checkpoint, its ``config.json``.

    Raises:
        ConfigError: Nothing to resume there.
        CheckpointError: The checkpoint is damaged or records no configuration.
    """
    run_dir = Path(run_dir)
    _resumable(run_dir)
    ckpt_path = run_dir / ckpt_io.CHECKPOINT_NAME
    if ckpt_path.exists():
        loaded = ckpt_io.load(ckpt_path)
        ckpt_io.require(loaded, "config", purpose="its run cannot be resumed")
        return TrainConfig.from_saved(loaded.meta["config"], source=str(ckpt_path))
    path = run_dir / "config.json"
    return TrainConfig.from_saved(read_config_file(path), source=str(path))


def _lock_run(run_dir: Path) -> Any:
    """Hold an exclusive OS lock on the run folder for the whole run: a second run on the same
    folder is refused at once. The OS drops the lock when the process ends, however it ends, so
    a killed run never leaves the folder locked. Without ``fcntl`` (Windows) there is no lock."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover
        return None
    run_dir.mkdir(parents=True, exist_ok=True)
    handle = open(run_dir / LOCK_NAME, "a+")  # noqa: SIM115 (held until the run ends)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        raise ConfigError(
            f"another training run is using {str(run_dir)!r} (its lock is held); wait for it "
            f"to end or choose another --out"
        ) from None
    return handle


def _train(
    config: TrainConfig, run_dir: Path, ckpt_path: Path, resume: bool, progress: bool
) -> TrainResult:
    loaded = None
    changes: dict[str, list[Any]] = {}
    restarted = False
    if resume and not ckpt_path.exists():
        _resumable(run_dir)
        # Killed before its first checkpoint: nothing to continue but its settings.
        restarted, resume = True, False
    elif resume:
        # A process killed while writing leaves a partial temporary file beside the intact
        # checkpoint; it is rewritten by the next save, but clear it now so nothing stale lingers.
        for stale in [*run_dir.glob("*.tmp"), *stale_temporaries(run_dir)]:
            stale.unlink(missing_ok=True)
        loaded = ckpt_io.load(ckpt_path)
        ckpt_io.require(
            loaded, "config", "step", "start_pattern", "optimizer", purpose="it cannot be resumed"
        )
        saved = TrainConfig.from_saved(loaded.meta["config"], source=str(ckpt_path))
        _check_resume_compatible(saved, config)
        changes = _changed_settings(saved, config)
    elif ckpt_path.exists():
        raise ConfigError(
            f"{str(run_dir)!r} already holds a checkpoint; use --resume to continue it or "
            f"choose another --out"
        )
    train_source = _train_source(config)  # its errors before the process group exists
    if config.run.threads:
        torch.set_num_threads(config.run.threads)
    # torchrun sets LOCAL_RANK: the device comes first, it decides the backend (nccl or gloo).
    device = resolve_device(config.run.device, int(os.environ.get("LOCAL_RANK", "0")))
    dist_info = init_distributed(device.type)
    torch.manual_seed(config.run.seed)

    pattern = patterns.Pattern.from_dict(loaded.meta["start_pattern"]) if loaded else None
    system = build_system(config, pattern, design=loaded is None).to(device)
    mix = pattern_mix(config)
    val_patterns = [patterns.get(p) for p in config.pattern.val_patterns] if mix else None
    start_pattern = system.sensor._meta.to_dict()
    fast = config.run.bf16 or fast_precision(config.run.precision, device)
    if config.run.channels_last or fast:
        system.channels_last = True
        system.network.to(memory_format=torch.channels_last)
    if config.run.compile:
        system.compile_network()
    net_params = list(system.network.parameters())
    # "peak_lr": what the schedule scales, per group (network, pattern).
    groups = [{"params": net_params, "lr": config.optim.lr, "peak_lr": config.optim.lr}]
    sensor_params = list(system.sensor.parameters())
    if sensor_params:
        pattern_lr = config.pattern.lr or config.optim.lr
        groups.append({"params": sensor_params, "lr": pattern_lr, "peak_lr": pattern_lr})
    optimizer = torch.optim.Adam(groups, lr=config.optim.lr, betas=tuple(config.optim.betas))

    init_from = loaded.meta.get("init_from") if loaded is not None else None
    if loaded is None and config.run.init_from:
        init_from = _start_from(system, config.run.init_from)
    # A run continued from a weights snapshot (run.continue_schedule) starts where the
    # snapshot's run stopped: step numbers, the schedule and the budget are those of the whole.
    start_step = int(loaded.meta.get("start_step", 0)) if loaded is not None else 0
    lr_scale = float(loaded.meta.get("lr_scale", 1.0)) if loaded is not None else 1.0
    if loaded is None and config.run.continue_schedule:
        start_step, lr_scale = _continue_point(init_from, config)

    cache = ImageCache(
        train_source,
        min_size=config.data.patch_size,
        max_images=config.data.max_images,
        progress=progress and dist_info.is_main,
    )
    sampler = PatchSampler(
        cache,
        patch_size=config.data.patch_size,
        seed=config.run.seed + start_step,  # a continued run must not replay the first patches
        rank=dist_info.rank,
        world_size=dist_info.world_size,
        partial=config.data.partial_periods,
        # A new pattern every step: cut into periods of up to 4 (the largest drawn) instead.
        period=(4, 4) if mix is not None else system.sensor.period,
    )
    noise_seed = (config.run.seed + start_step) * 7919 + 1 + 104729 * dist_info.rank
    if config.noise.model == "photon":
        noise: GaussianNoise | PhotonNoise = PhotonNoise(
            tuple(config.noise.photons),
            per_sample=config.optim.per_sample_sigma,
            seed=noise_seed,
            **config.noise.sensor(),
        )
    else:
        noise = GaussianNoise(
            (config.optim.sigma_min, config.optim.sigma_max),
            per_sample=config.optim.per_sample_sigma,
            seed=noise_seed,
        )
    val_images = _val_images(config) if dist_info.is_main else []
    if val_images and progress and dist_info.is_main and not config.data.val:
        names = [name for name, _ in val_images]
        shown = ", ".join(names[:4]) + (", ..." if len(names) > 4 else "")
        crop = f" (of those at least {config.data.val_crop} px)" if config.data.val_crop else ""
        print(
            f"validation: {len(names)} of the last {val_split(config)} images of "
            f"{config.data.train}{crop}, held out of training: {shown}"
        )
    val_levels: list = list(config.data.val_sigmas)
    if config.noise.model == "photon":
        val_levels = [Exposure(n, **config.noise.sensor()) for n in config.noise.val_photons]

    step = start_step
    train_seconds = 0.0  # training time of the run so far, all processes (not validation)
    if loaded is not None:
        ckpt_io.load_module(system, loaded)
        ckpt_io.load_optimizer(optimizer, loaded)
        step = int(loaded.meta["step"])
        train_seconds = float(loaded.meta.get("train_seconds", 0.0))
        _restore_rng(loaded, sampler, noise, dist_info)
        # The peaks are settings, not state: those of this config apply (a changed --lr too).
        for group, peak in zip(optimizer.param_groups, (g["peak_lr"] for g in groups), strict=True):
            group["peak_lr"] = peak
            group["betas"] = tuple(config.optim.betas)

    guard = DivergenceGuard(config.optim.divergence_factor, lr_scale=lr_scale)

    spent = config.run.time_limit is not None and train_seconds >= 60 * config.run.time_limit
    if loaded is not None and (step >= config.optim.steps or spent):
        # Nothing to train: the run's record (config, changes, checkpoint) stays as it is, so a
        # changed setting is never recorded for steps that did not run under it.
        if dist_info.is_main:
            budget = "its time limit" if spent else f"{config.optim.steps} steps"
            print(f"{run_dir} is already at step {step} ({budget}): nothing to train")
        return TrainResult(run_dir, step, False, _last_metrics(run_dir / METRICS_NAME))

    model: torch.nn.Module = system
    if dist_info.world_size > 1:
        from torch.nn.parallel import DistributedDataParallel

        model = DistributedDataParallel(
            system, device_ids=[device.index] if device.type == "cuda" else None
        )

    metrics_path = run_dir / METRICS_NAME
    writer = None
    if dist_info.is_main:
        run_dir.mkdir(parents=True, exist_ok=True)
        if resume:
            _truncate_metrics(metrics_path, step)
        else:
            # A new run in this folder (which holds no checkpoint): the logs of an earlier one
            # that ended before its first checkpoint describe nothing that survives.
            stale = [n for n in (METRICS_NAME, CHANGES_NAME) if (run_dir / n).exists()]
            for name in stale:
                (run_dir / name).unlink()
            if restarted:
                print(f"{run_dir} has no checkpoint yet: starting it again from step 0")
            elif stale:
                print(f"{run_dir}: cleared {' and '.join(stale)} of a run with no checkpoint")
        config.write(run_dir / "config.json")
        if config.run.tensorboard:
            writer = _tensorboard(run_dir)

    if changes and dist_info.is_main:
        # Settings changed on resume apply from here on; the record says when and what.
        for key, (old, new) in changes.items():
            print(f"resume at step {step}: {key} {old!r} -> {new!r}")
        with appending(run_dir / CHANGES_NAME) as fh:
            fh.write(json.dumps({"step": step, "time": time.time(), "changes": changes}) + "\n")

    def save() -> None:
        rng = _gather_rng(sampler, noise, dist_info)
        replicas = _replica_report(system, last_batch, dist_info)
        if not dist_info.is_main:
            return
        opt_tensors, opt_meta = ckpt_io.optimizer_tensors(optimizer)
        tensors = {f"model/{k}": v for k, v in system.state_dict().items()}
        tensors.update(opt_tensors)
        tensors.update(rng)
        meta = {
            "config": config.to_dict(),
            "step": step,
            "start_step": start_step,
            "network": system.network.config(),
            "pattern": system.sensor.to_pattern().to_dict(),
            "start_pattern": start_pattern,
            "optimizer": opt_meta,
            "world_size": dist_info.world_size,
            "train_seconds": train_seconds,
            "lr_scale": guard.lr_scale,
            "device": device_name(device),
            "precision": "bf16" if fast else "fp32",
            "train_images": len(cache),
            "init_from": init_from,
            "replicas": replicas,
            "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        }
        ckpt_io.save(ckpt_path, meta, tensors)
        if config.pattern.learn or config.pattern.metasurface:
            patterns.save(
                system.sensor.to_pattern(f"{start_pattern['name']}-learned"),
                run_dir / "pattern.toml",
            )
        if config.pattern.metasurface:
            _export_profile(system.sensor, run_dir)

    bar = None
    if progress and dist_info.is_main:
        from tqdm import tqdm

        bar = tqdm(
            total=config.optim.steps,
            initial=step,
            unit="step",
            dynamic_ncols=True,
            desc=f"train {Path(config.run.out).name}",
        )
    autocast = (
        torch.autocast(device.type, dtype=torch.bfloat16) if fast else contextlib.nullcontext()
    )
    time_limit_s = 60 * config.run.time_limit if config.run.time_limit else None
    last: dict[str, float] = {}
    last_batch: torch.Tensor | None = None
    window_loss, window_n, data_time = 0.0, 0, 0.0
    window_grad, window_rollbacks = 0.0, 0  # largest gradient norm, divergences rolled back
    trainable = [p for g in optimizer.param_groups for p in g["params"]]
    t_window = time.perf_counter()
    interrupted = False
    # A resumed run whose time limit is already spent does no more steps.
    timed_out = time_limit_s is not None and train_seconds >= time_limit_s
    with _StopFlag() as stop:
        if step == 0 and val_images and dist_info.is_main:
            start = validate(system, val_images, val_levels, val_patterns)
            with appending(metrics_path) as fh:
                fh.write(json.dumps({"step": 0, **start, "time": time.time()}) + "\n")
        while step < config.optim.steps and not timed_out:
            t0 = time.perf_counter()
            run_progress = progress_of(step, config.optim.steps, train_seconds, time_limit_s)
            for group in optimizer.param_groups:
                group["lr"] = learning_rate(
                    config.optim.schedule,
                    group["peak_lr"] * guard.lr_scale,
                    step - start_step,  # fresh Adam moments warm up again
                    config.optim.warmup_steps,
                    run_progress,
                )
            batch = sampler.sample(config.data.batch_size).to(device, non_blocking=True)
            last_batch = batch
            if mix is not None:
                system.sensor.set_pattern(mix.pattern(step))
            data_time += time.perf_counter() - t0
            with autocast:
                pred = model(batch, noise)
            loss = F.mse_loss(pred.float(), batch)
            objective = loss.clamp_min(1e-12).log() if config.optim.loss == "log_mse" else loss
            optimizer.zero_grad(set_to_none=True)
            objective.backward()
            value = loss.item()
            grad_norm = float(
                torch.nn.utils.clip_grad_norm_(
                    trainable, config.optim.clip_grad or math.inf, foreach=True
                )
            )
            if _agree(guard.diverged(value), dist_info):
                # Not applied; back to weights from before the instability, at a lower rate.
                guard.roll_back(system, optimizer)
                window_rollbacks += 1
                if dist_info.is_main:
                    print(
                        f"step {step + 1}: loss {value:.3g} diverged; rolled back and scaled "
                        f"the learning rate by {guard.lr_scale:g}",
                        file=sys.stderr,
                    )
                if guard.lr_scale <= 0.5**GUARD_GIVES_UP:
                    step += 1
                    break
            else:
                optimizer.step()
                guard.applied(value, system, optimizer)
            step += 1
            train_seconds += time.perf_counter() - t0
            if dist_info.world_size > 1:
                # Every rank must use the same learning rate, which depends on the time.
                train_seconds = _max_over_ranks(train_seconds)
            window_loss += value if math.isfinite(value) else 0.0
            window_n += 1
            window_grad = max(window_grad, grad_norm)
            if bar is not None:
                bar.update(1)
            if time_limit_s is not None and train_seconds >= time_limit_s:
                timed_out = True
            final = step == config.optim.steps or timed_out
            log_now = step % config.run.log_every == 0 or final
            val_now = val_images and (step % config.run.val_every == 0 or final)
            if log_now and dist_info.is_main:
                elapsed = time.perf_counter() - t_window
                mean = window_loss / window_n
                last = {
                    "step": step,
                    "loss": mean,
                    "train_psnr": 10 * math.log10(1 / max(mean, 1e-12)),
                    "steps_per_s": window_n / elapsed,
                    "patches_per_s": window_n
                    * config.data.batch_size
                    * dist_info.world_size
                    / elapsed,
                    "data_frac": data_time / elapsed,
                    "lr": optimizer.param_groups[0]["lr"],
                    "grad_norm_max": window_grad,
                    "rollbacks": window_rollbacks,
                    "lr_scale": guard.lr_scale,
                }
            if val_now and dist_info.is_main:
                t_val = time.perf_counter()
                last.update(validate(system, val_images, val_levels, val_patterns))
                last["step"] = step
                t_window += time.perf_counter() - t_val  # keep steps/s about training only
            if (log_now or val_now) and dist_info.is_main:
                last["time"] = time.time()
                with appending(metrics_path) as fh:
                    fh.write(json.dumps(last) + "\n")
                if writer is not None:
                    for key, value in last.items():
                        if key not in ("step", "time"):
                            writer.add_scalar(key, value, step)
                if bar is not None:
                    post = {"loss": f"{last['loss']:.2e}", "psnr": f"{last['train_psnr']:.2f}"}
                    if "val_psnr" in last:
                        post["val"] = f"{last['val_psnr']:.2f}"
                    bar.set_postfix(post, refresh=False)
            if log_now:
                window_loss, window_n, data_time = 0.0, 0, 0.0
                window_grad, window_rollbacks = 0.0, 0
                t_window = time.perf_counter()
            if _agree(stop.requested or timed_out, dist_info):
                interrupted = not timed_out
                break
            if step % config.run.checkpoint_every == 0 and step < config.optim.steps:
                save()
        save()
    if bar is not None:
        bar.close()
    if writer is not None:
        writer.close()
    if (interrupted or timed_out) and dist_info.is_main:
        why = "time limit reached" if timed_out else "interrupted"
        print(f"{why}: saved step {step} to {ckpt_path}; continue with --resume")
    failure = None
    if dist_info.is_main and not interrupted:
        failure = failure_of(metrics_path, last, guard.lr_scale)
    return TrainResult(run_dir, step, interrupted, last, failure)


def _max_over_ranks(value: float) -> float:
    import torch.distributed as dist

    t = torch.tensor([value], dtype=torch.float64)
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return float(t.item())


def _agree(flag: bool, dist_info: DistInfo) -> bool:
    """All ranks stop on the same step (else the others would wait forever in all-reduce)."""
    if dist_info.world_size == 1:
        return flag
    import torch.distributed as dist

    t = torch.tensor([1.0 if flag else 0.0])
    dist.all_reduce(t)
    return bool(t.item() > 0)


def _replica_report(
    system: ImagingSystem, batch: torch.Tensor | None, dist_info: DistInfo
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
    rows = [fingerprint]
    if dist_info.world_size > 1:
        import torch.distributed as dist

        rows = [torch.empty_like(fingerprint) for _ in range(dist_info.world_size)]
        dist.all_gather(rows, fingerprint)
    return {
        "model_fingerprints": [[float(r[0]), float(r[1])] for r in rows],
        "batch_sums": [float(r[2]) for r in rows],
    }


def _gather_rng(sampler: PatchSampler, noise: GaussianNoise, dist_info: DistInfo):
    """RNG states of every rank (collected on rank 0) so a resume draws the same batches."""
    mine = torch.cat([sampler.generator.get_state(), noise.generator.get_state()])
    n_sampler = sampler.generator.get_state().numel()
    states = [mine]
    if dist_info.world_size > 1:
        import torch.distributed as dist

        states = [torch.empty_like(mine) for _ in range(dist_info.world_size)]
        dist.all_gather(states, mine)
    out = {"rng/torch": torch.get_rng_state()}
    for rank, state in enumerate(states):
        out[f"rng/sampler/{rank}"] = state[:n_sampler].clone()
        out[f"rng/noise/{rank}"] = state[n_sampler:].clone()
    return out


def _restore_rng(
    loaded: ckpt_io.Checkpoint, sampler: PatchSampler, noise: GaussianNoise, dist_info: DistInfo
) -> None:
    key = f"rng/sampler/{dist_info.rank}"
    if key in loaded.tensors:
        sampler.generator.set_state(loaded.tensors[key])
        noise.generator.set_state(loaded.tensors[f"rng/noise/{dist_info.rank}"])
    else:
        # Resumed with more processes than the run had: reseed this rank from the step.
        warnings.warn(
            f"checkpoint has no RNG state for rank {dist_info.rank}; reseeding", stacklevel=2
        )
        step = int(loaded.meta["step"])
        sampler.generator.manual_seed(sampler.seed + 1_000_003 * dist_info.rank + 7919 * step)
        noise.generator.manual_seed(sampler.seed + 2_000_003 * dist_info.rank + 7919 * step)
    torch.set_rng_state(loaded.tensors["rng/torch"])


#: Settings that define the model or the random streams: a resumed run must keep them.
FIXED_ON_RESUME = (
    "pattern.name",
    "pattern.learn",
    "pattern.init",
    "pattern.design_steps",
    "pattern.metasurface",
    "network.arch",
    "network.features",
    "network.blocks",
    "run.seed",
    "run.out",
)


def _flat(config: TrainConfig) -> dict[str, Any]:
    return {f"{s}.{k}": v for s, sec in config.to_dict().items() for k, v in sec.items()}


def _check_resume_compatible(saved: TrainConfig, new: TrainConfig) -> None:
    """Settings that define the model must not change on resume."""
    a, b = _flat(saved), _flat(new)
    for key in FIXED_ON_RESUME:
        if key == "run.out":
            continue  # the folder may have been moved
        if a[key] != b[key]:
            raise ckpt_io.CheckpointError(
                f"cannot resume: the checkpoint was trained with {key}={a[key]!r}, got "
                f"{b[key]!r}; this setting defines the model, so start a new run instead"
            )


def _changed_settings(saved: TrainConfig, new: TrainConfig) -> dict[str, list[Any]]:
    """``{key: [old, new]}`` of every other setting changed on resume (they all apply)."""
    a, b = _flat(saved), _flat(new)
    return {k: [a[k], b[k]] for k in a if a[k] != b[k] and k not in FIXED_ON_RESUME}


def _tensorboard(run_dir: Path):
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        warnings.warn("TensorBoard is not installed; logging to metrics.jsonl only", stacklevel=2)
        return None
    return SummaryWriter(str(run_dir / "tensorboard"))
