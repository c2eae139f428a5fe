"""Setting a training run up from its configuration: the device and processes, the imaging
system (sensor + network), the optimiser, where the weights start, the training patches, the
noise, and the validation images; :func:`prepare` does it all in order, for a new run or for
one that resumes a checkpoint.

A run works in one light domain (``data.domain``, model.md §13): a network that solves the
LMMSE inside (``physics``, ``universal``) holds the shipped image statistics of that domain,
also when its weights start from a network of the other one (``run.init_from``)."""

from __future__ import annotations

import logging
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from .. import patterns
from ..data.colour import ColourMix, chroma_moved_copies
from ..data.patches import ImageCache, PatchSampler, list_images
from ..design.kernels import design_pattern
from ..io import checkpoints as ckpt_io
from ..patterns.random import PatternMix
from ..physics.noise import TrainingNoise
from ..physics.sensor import LearnableSplitterSensor, SplitterSensor, SwitchingSensor
from ..physics.system import ImagingSystem
from ..recon.base import fast_precision, strict_float32
from ..recon.closed_form import estimate_image_statistics, shipped_image_statistics
from ..recon.networks import build_network
from . import adapters, noise, seeds
from .config import ConfigError, TrainConfig
from .distributed import DistInfo, init_distributed
from .ema import WeightAverage
from .guard import DivergenceGuard
from .init_from import continue_point, start_from
from .mining import mined_windows
from .state import Run, TrainState, restore
from .teachers import Teachers
from .validation import say_held_out, train_source, val_images, val_levels

logger = logging.getLogger(__name__)


def prepare(
    config: TrainConfig, run_dir: Path, loaded: ckpt_io.Checkpoint | None, progress: bool
) -> tuple[Run, TrainState]:
    """Everything a run trains with, at its first step or at the checkpoint ``loaded``.

    The order matters: errors in the data settings come before the process group exists, and
    torch's global generator is seeded before the network is built.
    """
    source = train_source(config)
    if loaded is not None:
        _check_resume_domain(config, loaded)
    device, dist = _processes(config)
    torch.manual_seed(seeds.global_seed(config))
    start = patterns.Pattern.from_dict(loaded.meta["start_pattern"]) if loaded else None
    named = config_patterns(config, start)
    system = build_system(config, start, design=loaded is None, named=named).to(device)
    run = Run(
        config,
        run_dir,
        device,
        dist,
        fast=config.run.bf16 or fast_precision(config.run.precision, device),
        device_label=device_name(device),
        start_pattern=system.sensor._meta.to_dict(),
        mix=named.mix,
    )
    if not run.fast:
        strict_float32(device)
    if run.mix is not None:
        run.val_patterns = list(named.validation)
    if config.optim.adapter != "none" and dist.world_size > 1:
        raise ConfigError("optim.adapter trains in one process; leave it out under torchrun")
    adapters.attach(system, config.optim.adapter)
    _speed_up(system, run)
    run.init_from, start_step, lr_scale = _origin(config, system, loaded)
    optimizer = build_optimizer(config, system)
    sampler = _patch_sampler(run, source, start_step, system, progress)
    if config.data.colour_mined > 0:
        sampler.use_mined(
            mined_windows(
                run_dir,
                system,
                sampler,
                config,
                device=run.device,
                progress=progress and dist.is_main,
                save=dist.is_main,
            )
        )
    if loaded is None and (config.data.colour_statistics or config.data.photo_statistics):
        _use_own_statistics(system, sampler.cache, config)
    run.train_images = sampler.cache.files
    state = TrainState(
        system,
        optimizer,
        DivergenceGuard(config.optim.divergence_factor, lr_scale=lr_scale),
        sampler,
        build_noise(config, start_step, dist.rank, device=sampler.device),
        step=start_step,
        start_step=start_step,
        ema=WeightAverage(system.network, config.optim.ema) if config.optim.ema else None,
        teachers=_teachers(run, system),
    )
    _validation(run, progress)
    if loaded is not None:
        restore(state, loaded, run)
    return run, state


def _teachers(run: Run, system: ImagingSystem) -> Teachers | None:
    """The shipped per-pattern networks of the run's patterns (``optim.teacher_weight``),
    watching the run's network; None when off."""
    config = run.config
    if not config.optim.teacher_weight:
        return None
    own = run.mix.named if run.mix is not None else [system.sensor.to_pattern()]
    teachers = Teachers.shipped(own, config.data.domain, run.device)
    if not teachers.pairs:
        raise ConfigError(
            "optim.teacher_weight: none of the run's patterns has a shipped per-pattern network "
            f"of {config.data.domain} light"
        )
    if run.dist.is_main:
        logger.info(f"teachers: the shipped networks of {', '.join(teachers.names)}")
    teachers.watch(system.network)
    return teachers


def _check_resume_domain(config: TrainConfig, loaded: ckpt_io.Checkpoint) -> None:
    """A run continues in the light domain it trained in: its network estimates that domain's
    values and holds that domain's image statistics.

    Raises:
        CheckpointError: ``data.domain`` differs from the checkpoint's.
    """
    saved = TrainConfig.from_saved(loaded.meta["config"]).data.domain
    if saved != config.data.domain:
        raise ckpt_io.CheckpointError(
            f"cannot resume: the checkpoint was trained with data.domain={saved!r}, got "
            f"{config.data.domain!r}; this setting defines the model, so start a new run "
            f"instead (--init-from the run starts one from its weights)"
        )


def _processes(config: TrainConfig) -> tuple[torch.device, DistInfo]:
    """The device, and under ``torchrun`` the process group joined."""
    if config.run.threads:
        torch.set_num_threads(config.run.threads)
    # torchrun sets LOCAL_RANK: the device comes first, it decides the backend (nccl or gloo).
    device = resolve_device(config.run.device, int(os.environ.get("LOCAL_RANK", "0")))
    return device, init_distributed(device.type)


def _validation(run: Run, progress: bool) -> None:
    """The validation images (on the main process: the others do not validate) and levels."""
    if run.dist.is_main:
        run.val_images = val_images(run.config)
        if progress:
            say_held_out(run.config, run.val_images)
    run.val_levels = val_levels(run.config)


def _use_own_statistics(system: ImagingSystem, cache: ImageCache, config: TrainConfig) -> None:
    """The network's LMMSE solved from the statistics of the run's training photos as its
    cache keeps them (``data.photo_statistics``; at ``data.scales``), and with
    ``data.colour_statistics`` of a copy of each with its chroma moved too: channels reordered,
    hue turned and chroma scaled as :class:`~splitcam.data.colour.ColourMix` moves patches,
    drawn from the run's seed, in the run's light domain."""
    setting = "colour_statistics" if config.data.colour_statistics else "photo_statistics"
    if not hasattr(system.network, "use_statistics"):
        raise ConfigError(
            f"data.{setting} sets the statistics of the LMMSE inside the physics and "
            f"universal networks; the {config.network.arch} network has none"
        )
    photos = [cache.image(i) for i in range(len(cache))]
    moved = []
    if config.data.colour_statistics:
        generator = torch.Generator().manual_seed(seeds.global_seed(config))
        moved = chroma_moved_copies(
            photos, generator, chroma_max=config.data.colour_chroma_max, space=config.data.domain
        )
    sizes = ", ".join(f"{s:g}" for s in config.data.scales)
    try:
        stats = estimate_image_statistics(
            photos + moved,
            max_offset=system.network.stat_second.shape[-1] // 2,
            domain=config.data.domain,
        )
    except ValueError as exc:  # no photo larger than the statistics' window
        raise ConfigError(f"data.{setting}: {exc} (the photos at {sizes} of their size)") from None
    system.network.use_statistics(stats)
    logger.info(
        f"the LMMSE inside the network uses the statistics of {len(photos)} photos (at "
        f"{sizes} of their size){' and their chroma-moved copies' if moved else ''} "
        f"(data.{setting})"
    )


def _speed_up(system: ImagingSystem, run: Run) -> None:
    """Channels-last memory (with bfloat16, or asked for) and ``torch.compile`` (if asked for)."""
    if run.config.run.channels_last or run.fast:
        system.channels_last = True
        system.network.to(memory_format=torch.channels_last)
    if run.config.run.compile:
        system.compile_network()


def _origin(
    config: TrainConfig, system: ImagingSystem, loaded: ckpt_io.Checkpoint | None
) -> tuple[dict[str, Any] | None, int, float]:
    """``(init_from record, start step, learning-rate scale)``: a resumed run's own; a new run
    loads ``run.init_from`` (if any) into ``system`` and, continuing that run's schedule
    (``run.continue_schedule``), starts where it stopped: step numbers, the schedule and the
    budget are those of the whole."""
    if loaded is not None:
        meta = loaded.meta
        start_step = int(meta.get("start_step", 0))
        return meta.get("init_from"), start_step, float(meta.get("lr_scale", 1.0))
    init_from = None
    if config.run.init_from:
        init_from = start_from(system, config.run.init_from, config.data.domain)
    if config.run.continue_schedule:
        return (init_from, *continue_point(init_from, config))
    return init_from, 0, 1.0


def resolve_device(name: str, local_rank: int = 0) -> torch.device:
    """The device ``run.device`` names (``auto``: CUDA, else MPS, else the CPU).

    Raises:
        ConfigError: An unknown or unavailable device.
    """
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


def device_name(device: torch.device) -> str:
    """What the run trained on, for provenance: ``cuda (NVIDIA H100 ...)`` or ``cpu (<model>,
    <instruction set>, N threads)``."""
    if device.type == "cuda":
        return f"cuda ({torch.cuda.get_device_name(device)})"
    from ..recon.precision import cpu_model

    cpu = cpu_model()
    # The instruction set matters as much as the name: one "AMD EPYC" did 7.0 steps/s with
    # AVX512 (native bfloat16), another 2.4 with AVX2 only.
    capability = torch.backends.cpu.get_cpu_capability()
    threads = torch.get_num_threads()
    return f"{device.type} ({cpu}, {capability}, {threads} thread{'s' if threads != 1 else ''})"


def build_system(
    config: TrainConfig,
    pattern: patterns.Pattern | None = None,
    *,
    design: bool = True,
    named: ConfigPatterns | None = None,
) -> ImagingSystem:
    """Sensor + network from a configuration (network weights freshly initialised; the LMMSE
    inside a ``physics`` or ``universal`` network from the image statistics of ``data.domain``).

    A learned pattern with ``pattern.design_steps`` starts from the kernels that
    :func:`~splitcam.design.design_pattern` finds from its initialisation (unless
    ``design`` is false: a resumed run loads its own kernels). ``named``: the configuration's
    patterns, where the caller has read them (:func:`config_patterns`).
    """
    named = named or config_patterns(config, pattern)
    pattern = pattern or named.first()
    sensor = _sensor(config, pattern, named.mix, design)
    net = build_network(
        {
            "arch": config.network.arch,
            "period": list(pattern.period),
            "features": config.network.features,
            "blocks": config.network.blocks,
        },
        statistics=shipped_image_statistics(config.data.domain),
    )
    return ImagingSystem(sensor, net)


def _sensor(
    config: TrainConfig, pattern: patterns.Pattern, mix: PatternMix | None, design: bool
) -> SplitterSensor:
    """The sensor: switching between patterns, learned (from designed kernels), a metasurface,
    or fixed."""
    if mix is not None:
        return SwitchingSensor(pattern)
    if config.pattern.learn:
        gen = torch.Generator().manual_seed(seeds.pattern_seed(config))
        sensor = LearnableSplitterSensor(pattern, init=config.pattern.init, generator=gen)
        if design and config.pattern.design_steps:
            designed = design_pattern(
                pattern,
                init=config.pattern.init,
                steps=config.pattern.design_steps,
                seed=seeds.pattern_seed(config),
            )
            with torch.no_grad():
                sensor.logits.copy_(designed.logits)
        return sensor
    if config.pattern.metasurface:
        return _metasurface_sensor(config.pattern.metasurface, pattern.period, config)
    return SplitterSensor(pattern)


@dataclass(frozen=True)
class ConfigPatterns:
    """The patterns a training configuration names, read once."""

    #: A one-pattern run's pattern (None for a run over many patterns).
    start: patterns.Pattern | None
    #: The patterns of a ``--pattern random`` run, one per step (None for one pattern).
    mix: PatternMix | None
    #: What a run over many patterns is validated on.
    validation: tuple[patterns.Pattern, ...]

    def first(self) -> patterns.Pattern:
        """The pattern of the first step."""
        return self.mix.pattern(0) if self.mix is not None else self.start


def config_patterns(config: TrainConfig, start: patterns.Pattern | None = None) -> ConfigPatterns:
    """Read the pattern names and files of a configuration: the one place in training where
    they become :class:`~splitcam.patterns.Pattern` objects. ``start``: the pattern a resumed
    run recorded, used instead of reading its name or file again."""
    random = config.pattern.name.strip().lower() == "random"
    if not random and start is not None:
        return ConfigPatterns(start, None, ())
    names = [*config.pattern.mix, *config.pattern.val_patterns] if random else [config.pattern.name]
    read = [patterns.get(name) for name in names]
    if not random:
        return ConfigPatterns(_behind_stack(read[0], config.pattern.stack), None, ())
    mixed = len(config.pattern.mix)
    mix = PatternMix(read[:mixed], config.pattern.mix_fraction, seed=seeds.mix_seed(config))
    return ConfigPatterns(None, mix, tuple(read[mixed:]))


def _behind_stack(pattern: patterns.Pattern, text: str | None) -> patterns.Pattern:
    """``pattern`` behind the optical stack ``pattern.stack`` names, if any (the stacked
    pattern records the stack in its metadata, and so in every checkpoint)."""
    if text is None:
        return pattern
    from ..physics.stack import stack_of

    try:
        return stack_of(text).apply(pattern)
    except ValueError as exc:
        raise ConfigError(f"pattern.stack: {exc}") from None


def _metasurface_sensor(spec: str, period: tuple[int, int], config: TrainConfig) -> SplitterSensor:
    """A :class:`~splitcam.physics.optics.MetasurfaceSensor` of the default geometry starting
    from :func:`~splitcam.physics.optics.profile` ``spec`` (``random``, ``lens``, ``flat`` or a
    .npy file)."""
    from ..physics.optics import MetasurfaceSensor, Optics, profile

    optics = Optics()
    try:
        return MetasurfaceSensor(
            profile(spec, period, optics, seeds.pattern_seed(config)), period, optics
        )
    except ValueError as exc:
        raise ConfigError(f"pattern.metasurface: {exc}") from None


def build_optimizer(config: TrainConfig, system: ImagingSystem) -> torch.optim.Optimizer:
    """Adam over the network (and a learned pattern, at ``pattern.lr``); with an adapter
    (``optim.adapter``), over the adapter and the network at ``optim.base_lr_scale`` of the
    rate. Each parameter group keeps its ``peak_lr``: what the schedule scales."""
    lr = config.optim.lr
    network = list(system.network.parameters())
    adapter = getattr(system, "adapter", None)
    if adapter is None:
        groups = [{"params": network, "lr": lr, "peak_lr": lr}]
    else:
        # The adapter at the rate; the network's own weights slower, or frozen (no gradients
        # computed for them: a frozen network's backward skips their weight gradients).
        groups = [{"params": list(adapter.parameters()), "lr": lr, "peak_lr": lr}]
        base = lr * config.optim.base_lr_scale
        if base > 0:
            groups.append({"params": network, "lr": base, "peak_lr": base})
        else:
            for p in network:
                p.requires_grad_(False)
    sensor_params = list(system.sensor.parameters())
    if sensor_params:
        pattern_lr = config.pattern.lr or config.optim.lr
        groups.append({"params": sensor_params, "lr": pattern_lr, "peak_lr": pattern_lr})
    return torch.optim.Adam(groups, lr=config.optim.lr, betas=tuple(config.optim.betas))


def _patch_sampler(
    run: Run, source: Any, start_step: int, system: ImagingSystem, progress: bool
) -> PatchSampler:
    """This rank's training patches of the images ``source``, cut at whole periods of the
    pattern."""
    config = run.config
    cache = decoded(
        source,
        min_size=config.data.patch_size,
        max_images=config.data.max_images,
        progress=progress and run.dist.is_main,
        scales=config.data.scales,
    )
    settings = {
        "patch_size": config.data.patch_size,
        "seed": seeds.sampler_seed(config, start_step),
        "rank": run.dist.rank,
        "world_size": run.dist.world_size,
        "partial": config.data.partial_periods,
        "hard": config.data.hard_patches,
        "colour": ColourMix(
            chroma=config.data.colour_chroma,
            chroma_max=config.data.colour_chroma_max,
            leaves=config.data.colour_leaves,
            swap=config.data.colour_swap,
            space=config.data.domain,
        ),
        # A new pattern every step: cut into periods of up to 4 (the largest drawn) instead.
        "period": (4, 4) if run.mix is not None else system.sensor.period,
    }
    device = images_device(run.device)
    if device is None:
        return PatchSampler(cache, **settings)
    try:
        return PatchSampler(cache, **settings, device=device)
    except torch.OutOfMemoryError:
        warnings.warn(
            f"the {cache.nbytes / 2**20:.0f} MiB of training images do not fit on "
            f"{run.device}: batches are built on the host and copied there",
            stacklevel=2,
        )
        return PatchSampler(cache, **settings)


_LAST_CACHE: dict[tuple, ImageCache] = {}


def decoded(source: Any, **options: Any) -> ImageCache:
    """The :class:`ImageCache` of ``source``, reused when the run before it in this process
    decoded the same files the same way (the GPU relay trains several networks on one folder:
    decoding the 432 photos and their copies again took 20-30 s each time). Only the latest is
    kept, and only while none of its files changed (size and modification time)."""
    files = tuple(list_images(source) if isinstance(source, (str, os.PathLike)) else source)
    stats = [(str(f), Path(f).stat()) for f in files]
    stamp = tuple((name, st.st_size, st.st_mtime_ns) for name, st in stats)
    key = (stamp, options["min_size"], options["max_images"], tuple(options["scales"]))
    if key not in _LAST_CACHE:
        _LAST_CACHE.clear()
        _LAST_CACHE[key] = ImageCache(list(files), **options)
    return _LAST_CACHE[key]


def images_device(device: torch.device) -> torch.device | None:
    """Where a run holds its training photos: on an accelerator, the accelerator (one gather per
    batch, no host copy); on a CPU nowhere but the cache's arrays (None), whose numpy path is
    the faster one there (benchmarks/bench_throughput.py)."""
    return None if device.type == "cpu" else device


def build_noise(
    config: TrainConfig, start_step: int, rank: int, device: torch.device | None = None
) -> TrainingNoise:
    """This rank's simulated sensor noise (:data:`~splitcam.training.noise.TRAINING_NOISE`
    of ``noise.model``), drawn on ``device`` (the batches' device; default the CPU)."""
    return noise.build_noise(config, seeds.noise_seed(config, start_step, rank), device)
