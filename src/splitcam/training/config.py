"""Typed training configuration: dataclasses that load from TOML/YAML/JSON, take command-line
overrides, and are written resolved into every run folder.

Defaults follow the paper's recipe (model.md §6: batch 80 of 64x64 patches, Adam, MSE,
``sigma ~ U[0, 30]``, 10^6 steps, 10 blocks of 64 features) except where measurement chose
better per CPU-hour (docs/results/convergence/): the physics-informed network and Adam peaking
at 1e-3 after 100 warm-up steps with cosine decay. ``--arch paper --schedule constant --lr 1e-4``
is the paper's.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


from ..data.scales import valid_scales
from ..io import write_text
from ..io.domains import DEFAULT_DOMAIN, DOMAINS, SRGB
from ..io.paper import PAPER_PATTERNS

#: The smallest training patch: two periods of the largest patterns (4x4).
MIN_PATCH = 8
#: What ``data.colour_mined`` can score windows by (:data:`splitcam.training.mining.SCORES`)
MINE_SCORES = ("chroma", "rgb")

#: Training losses (``optim.loss``); :func:`splitcam.training.trainer.training_loss` computes them.
LOSSES = ("mse", "log_mse", "l1", "charbonnier")
ADAPTERS = ("none", "film")


class ConfigError(ValueError):
    """A configuration file or override is invalid; the message names the key."""


def _opt(
    default: Any,
    help: str,
    *,
    flag: str | None = None,
    choices: tuple[str, ...] | None = None,
) -> Any:
    """A setting: its default, its help text, (if not the field name) its command-line flag and
    (for a setting of a few names) the values it takes.

    The one place each setting is described: ``splitcam train``'s flags are generated from these
    (:func:`train_flags`), with the default shown in their help.
    """
    metadata = {"help": help, "flag": flag, "choices": choices}
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata=metadata)
    return field(default=default, metadata=metadata)


@dataclass
class PatternConfig:
    name: str = _opt(
        "D",
        "pattern name (`splitcam patterns` lists them), pattern file or router(eta=..;chi=..); "
        "random: a new pattern every step, drawn by splitcam.patterns.random and mixed with "
        "--mix (for --arch universal, best with --loss log_mse: experiments/universal.toml)",
        flag="pattern",
    )
    mix: list[str] = _opt(
        list(PAPER_PATTERNS),
        "with --pattern random: the named patterns (or files) mixed with the random draws",
    )
    mix_fraction: float = _opt(
        0.3, "with --pattern random: the fraction of steps that use one of --mix"
    )
    val_patterns: list[str] = _opt(
        ["D", "E"], "with --pattern random: the patterns validation scores (mean over them)"
    )
    learn: bool = _opt(
        False,
        "optimise the splitter kernels jointly with the network (paper Eq. 5-6)",
        flag="learn_pattern",
    )
    init: str = _opt("support", "initialisation of learned kernels: support, exact or random")
    lr: float | None = _opt(
        None, "learning rate of the pattern logits (default: the network's)", flag="pattern_lr"
    )
    metasurface: str | None = _opt(
        None,
        "learn a metasurface instead of free kernels (splitcam.physics.optics, default "
        "geometry): its starting height map, random, lens or a .npy file (µm); the period is "
        "the pattern's",
    )
    design_steps: int = _opt(
        0,
        "with --learn-pattern: first design the kernels for the closed-form LMMSE for this many "
        "steps (`splitcam design`, seconds), then train them jointly with the network",
    )

    stack: str | None = _opt(
        None,
        "train behind an optical stack in front of every pixel, as `splitcam study exposure "
        "--stack` puts its sensors (comma-separated: silicon, ir-cut, lens or a CSV file of "
        "wavelength_nm,transmission); the run's pattern records it, and the exposure study "
        "takes the network only behind the same stack",
    )

    def checks(self) -> list[tuple[bool, str]]:
        """``(holds, message)`` of every range and choice of this section."""
        fixed = self.name.strip().lower() != "random" and not self.learn and not self.metasurface
        stack_problem = _stack_problem(self.stack)
        return [
            (
                self.stack is None or fixed,
                "pattern.stack puts one pattern's kernels behind the stack: leave it out with "
                "--pattern random, --learn-pattern or --metasurface",
            ),
            (not stack_problem, stack_problem),
            (
                self.init in ("support", "exact", "random"),
                f"pattern.init must be support, exact or random, got {self.init!r}",
            ),
            (
                0 <= self.mix_fraction <= 1 and (self.mix_fraction == 0 or bool(self.mix)),
                "pattern.mix_fraction must be in [0, 1], and > 0 only with patterns in pattern.mix",
            ),
            (self.lr is None or self.lr > 0, "pattern.lr must be > 0"),
            (
                self.design_steps >= 0,
                f"pattern.design_steps must be >= 0, got {self.design_steps}",
            ),
        ]


def _stack_problem(text: str | None) -> str:
    """Why ``pattern.stack`` names no optical stack ("" when it does)."""
    if text is None:
        return ""
    from ..physics.stack import stack_of

    try:
        stack_of(text)
    except ValueError as exc:
        return f"pattern.stack: {exc}"
    return ""


@dataclass
class NetworkConfig:
    arch: str = _opt(
        "physics",
        "physics (corrects the closed-form LMMSE estimate for the sensor's kernels and noise "
        "level; the default because it wins at equal CPU time, see docs/results), universal "
        "(the same for any pattern, told each pixel's kernel; model.md §16), packed "
        "(blind, at 1/(Ph*Pw) of the positions) or paper (full resolution, model.md §5)",
    )
    features: int = _opt(64, "channels of the hidden layers")
    blocks: int = _opt(10, "residual blocks")

    def checks(self) -> list[tuple[bool, str]]:
        """``(holds, message)`` of every range and choice of this section."""
        return [
            (
                self.arch in ("paper", "packed", "physics", "universal"),
                f"network.arch must be physics, universal, packed or paper, got {self.arch!r}",
            ),
            (
                self.features >= 1 and self.blocks >= 0,
                "network.features must be >= 1 and network.blocks >= 0",
            ),
        ]


@dataclass
class DataConfig:
    train: str | None = _opt(None, "folder of training images", flag="data")
    val: str | None = _opt(
        None, "folder of validation images (default: a held-out split of the training folder)"
    )
    val_split: int | None = _opt(
        None,
        "hold out the last N training images (sorted by name) for validation; default: "
        "min(32, max(1, n // 10)) of n >= 2 images; 0: no validation",
    )
    val_max_images: int | None = _opt(8, "validate on at most this many images", flag="val_images")
    val_crop: int | None = _opt(
        256, "centre-crop validation images to this size (bounds validation time)"
    )
    val_scale: float = _opt(
        1.0,
        "validate on the images at this fraction of their size (in (0, 1], antialiased, before "
        "the crop); 0.5 scores as the ship gate does (splitcam.training.gate: the JPEG photos' "
        "chroma is stored at half resolution), the setting for runs that train at half size",
    )
    val_sigmas: list[float] = _opt([0.0, 15.0], "validation noise levels")
    patch_size: int = _opt(64, "training patch size")
    partial_periods: float = _opt(
        0.5,
        "probability that a batch's patches end part-way through a period (rows, and "
        "independently columns), as images of odd size do; teaches the network that edge "
        "(0.5 against 0: +0.63 dB on odd-sized whole images, +0.12 on whole periods, "
        "docs/results/convergence/30min_partial.md)",
    )
    batch_size: int = _opt(
        8,
        "patches per step (the paper: 80; 8 learns most per CPU-hour, "
        "docs/results/convergence/5min_lr.md)",
    )
    max_images: int | None = _opt(None, "use at most this many training images")
    hard_patches: float = _opt(
        0.0,
        "weight of detail in choosing patches: each patch is picked among 4 drawn at random "
        "with probability (1 - h) / 4 + h times its share of their gradient energy (0: "
        "uniform; splitcam.data.patches.PatchSampler)",
    )
    scales: list[float] = _opt(
        [1.0],
        "train on each image at each of these sizes (factors in (0, 1], antialiased; e.g. "
        "1 0.5: the photos and copies at half size, which pack more detail into a patch; "
        "splitcam.data.downscale)",
    )
    colour_chroma: float = _opt(
        0.0,
        "probability that a patch's chroma is moved: channels reordered, hue rotated, chroma "
        "scaled by up to --colour-chroma-max in an opponent space (in linear light for "
        "data.domain linear); shows the network saturated colour the photos lack "
        "(splitcam.data.colour)",
    )
    colour_chroma_max: float = _opt(2.2, "largest chroma factor of --colour-chroma (>= 1)")
    colour_swap: float = _opt(
        0.0,
        "probability that a patch keeps its luma and takes the chroma of another patch of the "
        "batch, scaled by up to --colour-chroma-max: colour edges where the luma has none "
        "(splitcam.data.colour)",
    )
    colour_statistics: bool = _opt(
        False,
        "a new run's LMMSE inside the physics and universal networks uses image statistics of "
        "the training photos together with a chroma-moved copy of each (the moves of "
        "--colour-chroma, at its --colour-chroma-max), instead of the photos' alone: a prior "
        "that expects saturated colour (splitcam.training.setup)",
    )
    photo_statistics: bool = _opt(
        False,
        "a new run's LMMSE inside the physics and universal networks uses image statistics of "
        "its own training photos as it keeps them (data.scales; at half size their JPEG chroma "
        "is as fine as their luma) instead of the shipped ones (the photos at full size); "
        "--colour-statistics adds chroma-moved copies to them (splitcam.training.setup)",
    )
    colour_leaves: float = _opt(
        0.0,
        "probability that a patch is replaced by a colour dead-leaves scene (discs with "
        "radii ~ r^-3 and colours uniform in the RGB cube; splitcam.data.colour)",
    )
    colour_mined: float = _opt(
        0.0,
        "probability that a patch is drawn from windows mined where the starting network's "
        "colour error is largest: of --mine-candidates windows drawn at random, the "
        "--mine-keep share with the largest error of its estimate at σ 0, by --mine-score "
        "(demosaicnet's hard-patch mining; mined once at the run's start and kept in the "
        "run folder; splitcam.training.mining)",
    )
    mine_candidates: int = _opt(8192, "windows scored when --colour-mined mines")
    mine_keep: float = _opt(0.1, "share of the scored windows --colour-mined keeps, in (0, 1]")
    mine_score: str = _opt(
        "chroma",
        "what --colour-mined scores a window by: chroma (the error of its Cb and Cr colour "
        "differences) or rgb (of its three channels: fine structure as well as colour)",
    )
    domain: str = _opt(
        DEFAULT_DOMAIN,
        "light domain (model.md §13): srgb (the paper's: the 8-bit values / 255 are the "
        "light) or linear (patches decoded to linear radiance before the sensor and the noise; "
        "the network estimates radiance, the loss compares it with the patch's radiance, and "
        "the LMMSE inside the physics and universal networks uses the linear image statistics); "
        "saved with the run and its exported models, which reconstruct only this domain",
        choices=DOMAINS,
    )

    def checks(self) -> list[tuple[bool, str]]:
        """``(holds, message)`` of every range and choice of this section."""
        return [
            (
                0 <= self.hard_patches <= 1,
                f"data.hard_patches must be in [0, 1], got {self.hard_patches}",
            ),
            (
                self.patch_size >= MIN_PATCH,
                f"data.patch_size must be >= {MIN_PATCH} (a few periods of the largest "
                f"patterns, 4x4, and context for the network), got {self.patch_size}",
            ),
            (
                self.domain in DOMAINS,
                f"data.domain must be one of {', '.join(DOMAINS)}, got {self.domain!r}",
            ),
            (self.batch_size >= 1, "data.batch_size must be >= 1"),
            (
                all(
                    0 <= p <= 1 for p in (self.colour_chroma, self.colour_leaves, self.colour_swap)
                ),
                "data.colour_chroma, data.colour_leaves and data.colour_swap must be "
                f"probabilities in [0, 1], got {self.colour_chroma}, {self.colour_leaves} and "
                f"{self.colour_swap}",
            ),
            (
                0 <= self.colour_mined <= 1 and 0 < self.mine_keep <= 1,
                "data.colour_mined must be a probability in [0, 1] and data.mine_keep a share "
                f"in (0, 1], got {self.colour_mined} and {self.mine_keep}",
            ),
            (
                self.mine_score in MINE_SCORES,
                f"data.mine_score must be one of {', '.join(MINE_SCORES)}, got {self.mine_score!r}",
            ),
            (
                self.mine_candidates >= 1,
                f"data.mine_candidates must be >= 1, got {self.mine_candidates}",
            ),
            (
                self.colour_chroma_max >= 1,
                f"data.colour_chroma_max must be >= 1, got {self.colour_chroma_max}",
            ),
            (
                valid_scales(self.scales),
                f"data.scales must be distinct factors in (0, 1], got {self.scales}",
            ),
            (
                0 < self.val_scale <= 1,
                f"data.val_scale must be in (0, 1], got {self.val_scale}",
            ),
            (
                0 <= self.partial_periods <= 1,
                f"data.partial_periods must be in [0, 1], got {self.partial_periods}",
            ),
            (self.val_split is None or self.val_split >= 0, "data.val_split must be >= 0"),
        ]


#: Settings added after runs were saved without them, and the value that reproduces those runs.
SAVED_BEFORE: dict[tuple[str, str], Any] = {
    ("data", "partial_periods"): 0.0,
    ("data", "domain"): SRGB,
}


@dataclass
class OptimConfig:
    steps: int = _opt(1_000_000, "training steps")
    lr: float = _opt(
        1e-3,
        "peak Adam learning rate (the paper: 1e-4, constant; 1e-3 with warm-up and cosine "
        "decay measured best per CPU-hour, docs/results/convergence/5min_lr.md)",
    )
    schedule: str = _opt(
        "cosine", "constant (the paper's) or cosine: decay to 0 over the steps or time limit"
    )
    warmup_steps: int = _opt(100, "linear learning-rate warm-up steps (0: none)")
    betas: list[float] = _opt([0.9, 0.999], "Adam betas")
    loss: str = _opt(
        "mse",
        "mse (the paper's); log_mse: the logarithm of each batch's MSE, which weighs every "
        "batch by its own error (a PSNR loss): over many patterns, hard ones do not drown the "
        "rest; l1 (mean absolute error) or charbonnier (sqrt(e^2 + 1e-6), a smooth l1), which "
        "weigh small errors, that is fine detail, more than the MSE does",
        choices=LOSSES,
    )
    ema: float | None = _opt(
        None,
        "decay of an exponential moving average of the network's weights, which validation, "
        "checkpoints' readers and exports then use instead of the last step's (e.g. 0.999: "
        "about the last 1000 steps; none: off; splitcam.training.ema)",
    )
    adapter: str = _opt(
        "none",
        "fine-tune through an adapter: none (every weight at optim.lr) or film (a scale and "
        "shift per output channel of every convolution at optim.lr, folded into the weights "
        "when saved; the network's own weights at optim.lr times optim.base_lr_scale; "
        "splitcam.training.adapters)",
        choices=ADAPTERS,
    )
    base_lr_scale: float = _opt(
        0.0,
        "with an adapter: the network's own weights train at optim.lr times this (0: frozen)",
    )
    teacher_weight: float = _opt(
        0.0,
        "on steps whose pattern has a shipped per-pattern network of the run's light domain, "
        "add this weight times the loss between the estimate and that network's estimate from "
        "the same raw image (0: off; splitcam.training.teachers)",
    )
    clip_grad: float | None = _opt(
        None, "clip the global gradient norm to this (none: no clipping)"
    )
    divergence_factor: float | None = _opt(
        20.0,
        "a step whose loss exceeds this many times the median of the last 100 (or is not "
        "finite) diverged: roll back 50-100 steps and halve the learning rate (none: only "
        "non-finite losses; see docs/results/divergence/)",
    )
    sigma_min: float = _opt(0.0, "smallest training noise sigma (8-bit units)")
    sigma_max: float = _opt(30.0, "largest training noise sigma (8-bit units)")
    per_sample_sigma: bool = _opt(
        False, "one noise sigma per patch instead of one per batch (the paper: per batch)"
    )

    def checks(self) -> list[tuple[bool, str]]:
        """``(holds, message)`` of every range and choice of this section."""
        return [
            (
                self.schedule in ("constant", "cosine"),
                f"optim.schedule must be constant or cosine, got {self.schedule!r}",
            ),
            (self.warmup_steps >= 0, "optim.warmup_steps must be >= 0"),
            (
                self.loss in LOSSES,
                f"optim.loss must be one of {', '.join(LOSSES)}, got {self.loss!r}",
            ),
            (
                self.ema is None or 0 < self.ema < 1,
                f"optim.ema must be in (0, 1) or none, got {self.ema!r}",
            ),
            (
                self.adapter in ADAPTERS,
                f"optim.adapter must be one of {', '.join(ADAPTERS)}, got {self.adapter!r}",
            ),
            (
                self.adapter == "none" or self.ema is None,
                "optim.adapter and optim.ema: an average of the frozen weights means nothing; "
                "use one of them",
            ),
            (
                self.base_lr_scale >= 0,
                f"optim.base_lr_scale must be >= 0, got {self.base_lr_scale}",
            ),
            (self.steps >= 1, f"optim.steps must be >= 1, got {self.steps}"),
            (self.lr > 0, f"optim.lr must be > 0, got {self.lr}"),
            (
                0 <= self.sigma_min <= self.sigma_max,
                "expected 0 <= optim.sigma_min <= optim.sigma_max",
            ),
            (
                len(self.betas) == 2 and all(0 <= b < 1 for b in self.betas),
                f"optim.betas must be two numbers in [0, 1), got {self.betas}",
            ),
        ]


def _noise_types() -> list[str]:
    from .noise import TRAINING_NOISE

    return list(TRAINING_NOISE)


def _noise_check(config: TrainConfig) -> None:
    from .noise import TRAINING_NOISE

    TRAINING_NOISE[config.noise.model].check(config)


@dataclass
class NoiseConfig:
    model: str = _opt(
        "gaussian",
        "gaussian (the paper's: sigma ~ U[optim.sigma_min, optim.sigma_max]) or photon (shot "
        "and read noise at an exposure drawn log-uniformly from --photons, model.md §11)",
        flag="noise",
    )
    photons: list[float] = _opt(
        [10.0, 10000.0],
        "photon model: range of full-light exposures (photo-electrons of a lossless pixel)",
    )
    read_noise: float = _opt(2.0, "photon model: read noise in electrons")
    full_well: float | None = _opt(None, "photon model: full-well capacity in electrons")
    gain: float | None = _opt(None, "photon model: ADC gain in electrons per DN (none: no ADC)")
    bits: int = _opt(12, "photon model: ADC bits")
    val_photons: list[float] = _opt(
        [30.0, 1000.0], "photon model: exposures of the validation (val_psnr_N<photons>)"
    )

    def sensor(self) -> dict[str, Any]:
        """The :class:`~splitcam.physics.noise.Exposure` settings besides the exposure."""
        return {
            "read_noise": self.read_noise,
            "full_well": self.full_well,
            "gain": self.gain,
            "bits": self.bits,
        }

    def checks(self) -> list[tuple[bool, str]]:
        """``(holds, message)`` of every range and choice of this section."""
        return [
            (
                self.model in _noise_types(),
                f"noise.model must be {' or '.join(_noise_types())}, got {self.model!r}",
            ),
            (
                len(self.photons) == 2
                and 0 < self.photons[0] <= self.photons[1]
                and bool(self.val_photons)
                and min(self.val_photons) > 0,
                f"noise.photons must be two exposures 0 < lo <= hi (photo-electrons), got "
                f"{self.photons}; noise.val_photons positive",
            ),
        ]


@dataclass
class RunConfig:
    out: str = _opt("runs/default", "run folder")
    seed: int = _opt(0, "random seed")
    init_from: str | None = _opt(
        None,
        "start from the weights of a shipped model (name, e.g. D), a model file, a run folder or "
        "a checkpoint: the network's weights, and the learned kernels for --learn-pattern "
        "(optimiser state starts afresh; its provenance carries over); auto: try universal and "
        "every shipped network of the pattern's period, sharing 3/10 of the time "
        "limit, and continue from the best by validation (splitcam.training.auto_init)",
    )
    continue_schedule: bool = _opt(
        False,
        "with init_from: begin at the source's total steps on this run's schedule, optim.steps "
        "being the whole budget, so a run continued from a weights snapshot (a run folder that "
        "did not survive) ends on the same schedule and budget as one straight run; the Adam "
        "moments restart under a new warm-up, the divergence guard's scale carries over",
    )
    config_file: str | None = _opt(
        None,
        "the configuration file these settings came from (--config and each stage of --recipe "
        "set it); recorded in the provenance of the run and of the models exported from it",
    )
    device: str = _opt("auto", "auto, cpu, cuda, cuda:N or mps")
    log_every: int = _opt(10, "log every N steps")
    val_every: int = _opt(500, "validate every N steps")
    checkpoint_every: int = _opt(200, "checkpoint every N steps")
    checkpoint_minutes: float | None = _opt(
        None,
        "also checkpoint after every this many minutes of training (none: by steps only); "
        "bounds what a stop that saves nothing (a machine taken back) can lose",
    )
    time_limit: float | None = _opt(
        None,
        "stop (and save) after this many minutes of training in total (a resumed run "
        "continues the count; validation not counted); the cosine decays over it",
    )
    precision: str = _opt(
        "auto",
        "network precision: auto (bfloat16 + channels-last where a few timed training steps "
        "on this machine found it faster than float32, remembered per device model and torch "
        "version; float32 elsewhere), fp32 or bf16",
    )
    tensorboard: bool = _opt(False, "also log to TensorBoard (if installed)")
    threads: int | None = _opt(None, "torch CPU threads (default: torch's choice)")
    channels_last: bool = _opt(False, "channels-last memory format (on with fast precision)")
    bf16: bool = _opt(False, "bfloat16 autocast for the network (= --precision bf16)")
    compile: bool = _opt(False, "torch.compile the network (slow start, faster steps)")

    def checks(self) -> list[tuple[bool, str]]:
        """``(holds, message)`` of every range and choice of this section."""
        return [
            (
                self.precision in ("auto", "fp32", "bf16"),
                f"run.precision must be auto, fp32 or bf16, got {self.precision!r}",
            ),
            (
                self.checkpoint_minutes is None or self.checkpoint_minutes > 0,
                f"run.checkpoint_minutes must be > 0 or none, got {self.checkpoint_minutes}",
            ),
            (
                self.time_limit is None or self.time_limit > 0,
                f"run.time_limit must be > 0 minutes or none, got {self.time_limit}",
            ),
            (
                self.threads is None or self.threads >= 1,
                f"run.threads must be >= 1 or none (torch's choice), got {self.threads}",
            ),
            (
                min(self.log_every, self.val_every, self.checkpoint_every) >= 1,
                "run.log_every, run.val_every and run.checkpoint_every must be >= 1",
            ),
            (
                not self.continue_schedule or bool(self.init_from),
                "run.continue_schedule needs run.init_from (the snapshot to continue)",
            ),
        ]


@dataclass
class TrainConfig:
    pattern: PatternConfig = field(default_factory=PatternConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    data: DataConfig = field(default_factory=DataConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> TrainConfig:
        return _build(cls, data, source)

    @classmethod
    def from_file(cls, path: str | Path) -> TrainConfig:
        return cls.from_dict(read_config_file(path), source=str(path))

    @classmethod
    def from_saved(cls, data: dict[str, Any], source: str = "saved run") -> TrainConfig:
        """The settings a run saved (checkpoint or ``config.json``). A setting added after the
        run was saved takes the value that reproduces how the run trained
        (:data:`SAVED_BEFORE`), not today's default, so a resumed old run keeps its recipe."""
        data = {section: dict(values) for section, values in data.items()}
        for (section, name), value in SAVED_BEFORE.items():
            if isinstance(data.get(section), dict):
                data[section].setdefault(name, value)
        return cls.from_dict(data, source=source)

    def override(self, dotted: dict[str, Any]) -> TrainConfig:
        """A copy with ``{"section.key": value}`` overrides applied (validated like a file)."""
        data = self.to_dict()
        for key, value in dotted.items():
            section, _, name = key.partition(".")
            if section not in data or name not in data[section]:
                raise ConfigError(f"unknown setting {key!r}")
            data[section][name] = value
        return TrainConfig.from_dict(data, source="command line")

    def validate(self) -> None:
        """Checks that need more than types (ranges, choices): each section's own
        (``checks()``), then those that span sections, in that order; the first that fails is
        raised."""
        sections = (self.pattern, self.network, self.optim, self.data, self.run, self.noise)
        checks = [check for section in sections for check in section.checks()]
        checks += [
            (
                self.pattern.name.lower() != "random"
                or (self.network.arch == "universal" and not self.pattern.learn),
                "--pattern random (a new pattern every step) needs --arch universal and no "
                "--learn-pattern",
            ),
            (
                self.optim.teacher_weight >= 0
                and (self.optim.teacher_weight == 0 or not self.pattern.learn),
                "optim.teacher_weight must be >= 0, and 0 with --learn-pattern (a learned "
                f"pattern has no shipped network), got {self.optim.teacher_weight}",
            ),
            (
                self.data.colour_mined == 0 or self.pattern.name.lower() != "random",
                "data.colour_mined scores windows with one pattern's network; a run over many "
                "patterns (pattern random) has none",
            ),
        ]
        for ok, message in checks:
            if not ok:
                raise ConfigError(message)
        try:
            _noise_check(self)
        except ValueError as exc:
            raise ConfigError(f"noise: {exc}") from None

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        write_text(path, json.dumps(self.to_dict(), indent=2) + "\n")
        return path


#: The top-level key that makes a configuration file extend another (:func:`read_config_file`).
EXTENDS = "extends"


def dotted(sections: dict[str, Any]) -> dict[str, Any]:
    """Settings by section (a config file's tables, :meth:`TrainConfig.to_dict`) as dotted keys,
    the keys of :meth:`TrainConfig.override` and of the flags: ``{"optim": {"lr": 1e-3}}`` ->
    ``{"optim.lr": 1e-3}``. Entries that are not sections are left out.

    >>> dotted({"optim": {"lr": 1e-3, "steps": 10}, "run": {"seed": 1}})
    {'optim.lr': 0.001, 'optim.steps': 10, 'run.seed': 1}
    """
    return {
        f"{name}.{key}": value
        for name, section in sections.items()
        if isinstance(section, dict)
        for key, value in section.items()
    }


def read_config_file(path: str | Path) -> dict[str, Any]:
    """Parse a TOML, YAML or JSON configuration file into a dict.

    A file may start from another: a top-level ``extends = "recipe.toml"`` (a path relative to
    the file) reads that file first and lays this one's settings over it, table by table (a
    setting this file gives replaces the other's; a list is one setting). The other file may
    extend a third, and so on; a cycle or a missing file is an error naming the files.
    """
    return _read_extended(Path(path), ())


def _read_extended(path: Path, chain: tuple[Path, ...]) -> dict[str, Any]:
    data = _parse_config_file(path)
    base = data.pop(EXTENDS, None)
    if base is None:
        return data
    if not isinstance(base, str) or not base:
        raise ConfigError(
            f"config file {str(path)!r}: {EXTENDS} must name a config file (a string), got {base!r}"
        )
    chain = (*chain, path)
    parent = path.parent / base
    if parent.resolve() in {p.resolve() for p in chain}:
        cycle = " -> ".join(str(p) for p in (*chain, parent))
        raise ConfigError(f"config file {str(path)!r}: {EXTENDS} makes a cycle: {cycle}")
    if not parent.is_file():
        raise ConfigError(
            f"config file {str(path)!r} extends {base!r}, but {str(parent)!r} does not exist"
        )
    return _merge(_read_extended(parent, chain), data)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``over`` laid over it: tables merged key by key, any other value replaced."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def _parse_config_file(path: Path) -> dict[str, Any]:
    """One configuration file as written (``extends`` not followed)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read config file {str(path)!r}: {exc.strerror or exc}") from None
    suffix = path.suffix.lower()
    try:
        if suffix == ".toml":
            data = tomllib.loads(text)
        elif suffix in (".yaml", ".yml"):
            import yaml

            data = yaml.safe_load(text) or {}
        elif suffix == ".json":
            data = json.loads(text)
        else:
            raise ConfigError(
                f"config file {str(path)!r}: expected .toml, .yaml or .json, got {suffix!r}"
            )
    except ConfigError:
        raise
    except Exception as exc:  # the parsers' own error types differ; all mean "bad syntax"
        raise ConfigError(f"config file {str(path)!r} is not valid: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config file {str(path)!r} must hold a table of sections")
    return data


def _coerce(value: Any, hint: Any, key: str) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _coerce(value, inner[0], key)
    if origin is list:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected a list, got {value!r}")
        return [_coerce(v, args[0], f"{key}[{i}]") for i, v in enumerate(value)]
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    return value


def _build(cls: type, data: Any, source: str, prefix: str = "") -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: {prefix or 'config'} must be a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        where = f" in [{prefix}]" if prefix else ""
        raise ConfigError(
            f"{source}: unknown setting(s) {', '.join(map(repr, unknown))}{where}; "
            f"valid: {', '.join(sorted(names))}"
        )
    kwargs = {}
    for name, value in data.items():
        hint = hints[name]
        key = f"{prefix}.{name}" if prefix else name
        if dataclasses.is_dataclass(hint):
            kwargs[name] = _build(hint, value, source, key)
        else:
            try:
                kwargs[name] = _coerce(value, hint, key)
            except ConfigError as exc:
                raise ConfigError(f"{source}: {exc}") from None
    return cls(**kwargs)


@dataclass(frozen=True)
class Flag:
    """A command-line flag of ``splitcam train``, generated from a config field."""

    name: str
    """``--name`` (underscores become dashes)."""
    key: str
    """The dotted setting, e.g. ``optim.lr``."""
    kind: Any
    """The value type (``bool`` flags take no value and come with a ``--no-`` form; ``list``
    ones take several)."""
    many: bool
    help: str
    choices: tuple[str, ...] | None = None
    """The values a setting of a few names takes (e.g. ``data.domain``), else None."""


def train_flags() -> list[Flag]:
    """Every setting of :class:`TrainConfig` as a flag, help and default from its field."""
    out = []
    hints = typing.get_type_hints(TrainConfig)
    for section in dataclasses.fields(TrainConfig):
        cls = hints[section.name]
        sub = typing.get_type_hints(cls)
        defaults = cls()
        for f in dataclasses.fields(cls):
            hint = sub[f.name]
            args = [a for a in typing.get_args(hint) if a is not type(None)]
            many = typing.get_origin(hint) is list
            kind = args[0] if args else hint
            default = getattr(defaults, f.name)
            text = f.metadata.get("help", "")
            if kind is bool:
                text = f"{text} (default: {'on' if default else 'off'})"
            elif default is not None:
                shown = " ".join(map(str, default)) if many else default
                text = f"{text} (default: {shown})"
            out.append(
                Flag(
                    f.metadata.get("flag") or f.name,
                    f"{section.name}.{f.name}",
                    kind,
                    many,
                    text,
                    f.metadata.get("choices"),
                )
            )
    return out


def read_config_value(text: str) -> Any:
    """A value given on the command line (``--set optim.steps=2000``), parsed as in a TOML file:
    ``2000`` an integer, ``5e-4`` a number, ``true`` a boolean, ``[0, 15]`` a list; anything
    else is a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except Exception:  # not a TOML value: a bare string such as a path
        return text
