"""Typed training configuration: dataclasses that load from TOML/YAML/JSON, take command-line
overrides, and are written resolved into every run folder.

Defaults follow the paper's recipe (SPEC section 6: batch 80 of 64x64 patches, Adam, MSE,
``sigma ~ U[0, 30]``, 10^6 steps, 10 blocks of 64 features) except where measurement chose
better per CPU-hour (docs/results/convergence.md): the physics-informed network and Adam peaking
at 5e-4 after 100 warm-up steps with cosine decay. ``--arch paper --schedule constant --lr 1e-4``
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


class ConfigError(ValueError):
    """A configuration file or override is invalid; the message names the key."""


@dataclass
class PatternConfig:
    name: str = "D"
    """Pattern name (A-E, bayer) or a pattern file."""
    learn: bool = False
    """Optimise the splitter kernels jointly with the network (paper Eq. 5-6)."""
    init: str = "support"
    """Initialisation of learned kernels: support, exact or random."""
    lr: float | None = None
    """Learning rate of the pattern logits (default: the network's)."""


@dataclass
class NetworkConfig:
    arch: str = "physics"
    """physics (corrects the closed-form LMMSE estimate for the sensor's kernels and noise
    level; the default because it wins at equal CPU time, see docs/results/convergence.md),
    packed (blind, runs at 1/(Ph*Pw) of the positions) or paper (full resolution, SPEC
    section 5)."""
    features: int = 64
    blocks: int = 10


@dataclass
class DataConfig:
    train: str | None = None
    """Folder of training images."""
    val: str | None = None
    """Folder of validation images (default: the held-out split of the training folder)."""
    val_split: int = 0
    """Hold out the last N images (sorted by name) of the training folder for validation."""
    val_max_images: int | None = 8
    val_crop: int | None = 256
    """Centre-crop validation images to this size (bounds validation time on a CPU)."""
    val_sigmas: list[float] = field(default_factory=lambda: [0.0, 15.0])
    patch_size: int = 64
    batch_size: int = 80
    max_images: int | None = None


@dataclass
class OptimConfig:
    steps: int = 1_000_000
    lr: float = 5e-4
    """Peak learning rate (the paper: 1e-4, constant)."""
    schedule: str = "cosine"
    """constant (the paper's) or cosine: decay to 0 over the run's steps or time limit."""
    warmup_steps: int = 100
    """Linear warm-up from lr/warmup_steps to lr over the first steps (0: none)."""
    betas: list[float] = field(default_factory=lambda: [0.9, 0.999])
    sigma_min: float = 0.0
    sigma_max: float = 30.0
    per_sample_sigma: bool = False
    """Draw one sigma per patch instead of one per batch (the paper: per batch)."""


@dataclass
class RunConfig:
    out: str = "runs/default"
    seed: int = 0
    device: str = "auto"
    """auto, cpu, cuda, cuda:N or mps."""
    log_every: int = 10
    val_every: int = 500
    checkpoint_every: int = 200
    time_limit: float | None = None
    """Stop (and save) after this many minutes of training in total (a resumed run continues
    the count; validation and checkpoints not counted). The cosine schedule decays over it."""
    precision: str = "auto"
    """Network precision: auto (bfloat16 + channels-last where the hardware has native
    bfloat16: AVX512-BF16/AMX CPUs, CUDA GPUs; float32 elsewhere), fp32 (bit-exact) or bf16."""
    tensorboard: bool = False
    threads: int | None = None
    """torch intra-op threads (default: torch's choice)."""
    channels_last: bool = False
    """Run the network in channels-last memory format (also on with fast precision)."""
    bf16: bool = False
    """bfloat16 autocast for the network (the same as precision bf16)."""
    compile: bool = False
    """torch.compile the network (a one-off warm-up of about a minute; then faster steps)."""


@dataclass
class TrainConfig:
    pattern: PatternConfig = field(default_factory=PatternConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    data: DataConfig = field(default_factory=DataConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> TrainConfig:
        return _build(cls, data, source)

    @classmethod
    def from_file(cls, path: str | Path) -> TrainConfig:
        return cls.from_dict(read_config_file(path), source=str(path))

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
        """Checks that need more than types (ranges, choices)."""
        checks = [
            (
                self.pattern.init in ("support", "exact", "random"),
                f"pattern.init must be support, exact or random, got {self.pattern.init!r}",
            ),
            (
                self.network.arch in ("paper", "packed", "physics"),
                f"network.arch must be physics, packed or paper, got {self.network.arch!r}",
            ),
            (
                self.optim.schedule in ("constant", "cosine"),
                f"optim.schedule must be constant or cosine, got {self.optim.schedule!r}",
            ),
            (self.optim.warmup_steps >= 0, "optim.warmup_steps must be >= 0"),
            (
                self.run.precision in ("auto", "fp32", "bf16"),
                f"run.precision must be auto, fp32 or bf16, got {self.run.precision!r}",
            ),
            (
                self.network.features >= 1 and self.network.blocks >= 0,
                "network.features must be >= 1 and network.blocks >= 0",
            ),
            (self.data.patch_size >= 1, "data.patch_size must be >= 1"),
            (self.data.batch_size >= 1, "data.batch_size must be >= 1"),
            (self.optim.steps >= 0, f"optim.steps must be >= 0, got {self.optim.steps}"),
            (self.optim.lr > 0, f"optim.lr must be > 0, got {self.optim.lr}"),
            (self.pattern.lr is None or self.pattern.lr > 0, "pattern.lr must be > 0"),
            (
                0 <= self.optim.sigma_min <= self.optim.sigma_max,
                "expected 0 <= optim.sigma_min <= optim.sigma_max",
            ),
            (
                len(self.optim.betas) == 2 and all(0 <= b < 1 for b in self.optim.betas),
                f"optim.betas must be two numbers in [0, 1), got {self.optim.betas}",
            ),
            (
                min(self.run.log_every, self.run.val_every, self.run.checkpoint_every) >= 1,
                "run.log_every, run.val_every and run.checkpoint_every must be >= 1",
            ),
            (self.data.val_split >= 0, "data.val_split must be >= 0"),
        ]
        for ok, message in checks:
            if not ok:
                raise ConfigError(message)

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")
        return path


def read_config_file(path: str | Path) -> dict[str, Any]:
    """Parse a TOML, YAML or JSON configuration file into a dict."""
    path = Path(path)
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
