"""``splitcam train --recipe``: a shipped model trained again end to end, stage by stage.

Most shipped models are several runs, each continuing the last from its weights with settings of
its own: the paper's recipe, then a border fine-tuning, then the noise range of the paper's
tables, then photos at half size, then a GPU segment (``experiments/README.md``). The chain is
written once, by the training itself: every run records its configuration file
(``run.config_file``) and its settings, and the model exported from the last run carries one
segment per run in its provenance (:func:`~splitcam.training.models.provenance_of`). A shipped
model is therefore its own recipe, inside the installed package: :func:`read_recipe` reads its
segments (consecutive segments of one file, a run continued, are one stage) and replays each with
the settings it recorded and the steps it trained. A time limit is a machine's, not the recipe's:
a stage that stopped on one replays its recorded steps, over which its schedule then runs (the
schedule of a time-limited run follows elapsed time, so the decay is the same over the steps).

For a chain that is not shipped yet, a recipe file lists configuration files in order::

    model = "mine"
    stages = ["one.toml", "two.toml"]   # relative to the recipe

:func:`run_recipe` trains stage ``i`` into ``OUT/<i>-<stage>`` starting from stage ``i - 1``'s
run folder (the first stage from what its settings say: a shipped model's from scratch), with
the settings given on the command line (``--data``, ``--threads``, ``--device``...) applied to
every stage. A stage that finished is
skipped and one that was interrupted is resumed, so the same command continues a recipe.
"""

from __future__ import annotations

import json
import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..io.weights import MODELS_DIR
from .config import ConfigError, TrainConfig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = [
    "MACHINE_KEYS",
    "Recipe",
    "Stage",
    "blend_of",
    "read_recipe",
    "recipe_names",
    "replayable",
    "run_recipe",
    "shipped_recipe",
]

logger = logging.getLogger(__name__)

#: Settings that say where and on what a run trained, not what it learned: left out of the
#: settings a segment records (:func:`replayable`) and given again by whoever replays it.
MACHINE_KEYS = (
    "data.train",
    "data.val",
    "run.out",
    "run.init_from",
    "run.config_file",
    "run.device",
    "run.threads",
)


def replayable(config: dict[str, Any]) -> dict[str, Any]:
    """A run's settings by section (:meth:`TrainConfig.to_dict`) without :data:`MACHINE_KEYS`:
    what a provenance segment records so that the stage can be trained again anywhere."""
    return {
        section: {k: v for k, v in values.items() if f"{section}.{k}" not in MACHINE_KEYS}
        for section, values in config.items()
    }


@dataclass(frozen=True)
class Stage:
    """One stage of a recipe: the configuration file it was written in (a name: it need not
    exist here) and the settings it trains with."""

    file: str
    config: TrainConfig


@dataclass(frozen=True)
class Recipe:
    """A model's stages, in order."""

    model: str
    stages: tuple[Stage, ...]


def recipe_names() -> list[str]:
    """The shipped models, each its own recipe."""
    return sorted(p.stem for p in MODELS_DIR.glob("*.json")) if MODELS_DIR.is_dir() else []


def blend_of(meta: dict[str, Any]) -> dict[str, Any] | None:
    """The blend a model header records (:func:`~splitcam.training.models.blend_models`):
    of its own weights, or of the weights it was trained on from; None for a chain of stages,
    which a recipe replays."""
    provenance = meta.get("provenance") or {}
    return provenance.get("blend") or provenance.get("from_blend")


def shipped_recipe(meta: dict[str, Any], name: str = "model") -> Recipe:
    """The recipe a model's header records (:func:`read_recipe` on a shipped model): one stage
    per run of its provenance, consecutive segments of one file and settings merged.

    Raises:
        ConfigError: A segment that records no settings (a model exported before segments
            recorded them, and not filled in by ``scripts/name_stage_files.py``), or a model
            whose weights are (or were trained on from) a blend of two
            (:func:`~splitcam.training.models.blend_models`).
    """
    if blend := blend_of(meta):
        ends = " and ".join(str(blend[end].get("name")) for end in ("start", "end"))
        how = "are" if (meta.get("provenance") or {}).get("blend") else "were trained on from"
        raise ConfigError(
            f"{name}: its weights {how} a blend of two models ({ends}, weight "
            f"{blend.get('weight')}; splitcam models blend), not a chain of stages, so it "
            "cannot be trained again with --recipe; its provenance records how each end was "
            "trained (its blend's start and end): train each, then blend them"
        )
    stages: list[tuple[str, dict[str, Any], int]] = []
    for index, segment in enumerate((meta.get("provenance") or {}).get("segments") or []):
        settings, file = segment.get("settings"), segment.get("config_file")
        if not settings or not file:
            raise ConfigError(
                f"{name}: segment {index + 1} of its provenance records no configuration file "
                "or settings, so it cannot be trained again"
            )
        if stages and stages[-1][0] == file and stages[-1][1] == settings:
            stages[-1] = (file, settings, stages[-1][2] + int(segment["steps"]))
        else:
            stages.append((file, settings, int(segment["steps"])))
    if not stages:
        raise ConfigError(f"{name}: its provenance has no segments")
    return Recipe(
        str(meta.get("name", name)),
        tuple(
            Stage(
                file,
                TrainConfig.from_saved(settings, source=f"{name}: {file}").override(
                    {"optim.steps": steps, "run.time_limit": None}
                ),
            )
            for file, settings, steps in stages
        ),
    )


def read_recipe(spec: str | Path) -> Recipe:
    """A shipped model's recipe by name (:func:`shipped_recipe`), or a recipe file.

    Raises:
        ConfigError: No such model or file (the message lists the shipped models), a malformed
            file, or a stage file that does not exist.
    """
    if isinstance(spec, str) and spec in recipe_names():
        header = MODELS_DIR / f"{spec}.json"
        return shipped_recipe(json.loads(header.read_text(encoding="utf-8")), spec)
    path = Path(spec)
    if path.suffix != ".toml" or not path.is_file():
        known = ", ".join(recipe_names()) or "none"
        raise ConfigError(f"--recipe {spec}: no such model or file (shipped: {known}; or a .toml)")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"recipe {path}: {exc}") from None
    stages = data.get("stages")
    if not isinstance(stages, list) or not stages or not all(isinstance(s, str) for s in stages):
        raise ConfigError(f'recipe {path}: expected stages = ["FILE.toml", ...]')
    files = [(path.parent / s).resolve() for s in stages]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise ConfigError(f"recipe {path}: stage file {missing[0]} not found")
    return Recipe(
        str(data.get("model", path.stem)),
        tuple(Stage(str(_shown(f)), TrainConfig.from_file(f)) for f in files),
    )


def stage_folder(out: Path, index: int, stage: Stage) -> Path:
    """Where stage ``index`` (from 0) of a recipe trains: ``OUT/<index + 1>-<parent>-<stem>``
    (``2-edges-A``), so stages of one name in different folders stay apart."""
    file = Path(stage.file)
    parent = file.parent.name
    label = file.stem if parent in ("experiments", "") else f"{parent}-{file.stem}"
    return out / f"{index + 1}-{label}"


def run_recipe(
    recipe: Recipe, out: str | Path, overrides: dict[str, Any], *, progress: bool = True
) -> list[Any]:
    """Train every stage of ``recipe`` under ``out`` (see the module), skipping finished ones
    and resuming an interrupted one. Returns each trained stage's
    :class:`~splitcam.training.trainer.TrainResult`; stops at the first that did not finish."""
    from .sweep import Experiment, status
    from .trainer import train

    out = Path(out)
    results = []
    previous: Path | None = None
    for index, stage in enumerate(recipe.stages):
        folder = stage_folder(out, index, stage)
        config = stage.config.override(
            {
                **overrides,
                "run.out": str(folder),
                "run.config_file": stage.file,
                **({"run.init_from": str(previous)} if previous is not None else {}),
            }
        )
        previous = folder
        state = status(Experiment(folder.name, Path(stage.file), config, folder))
        if state == "done":
            logger.info(f"recipe {recipe.model}: stage {index + 1} ({folder.name}) done, skipped")
            continue
        resume = state == "partial"
        logger.info(
            f"recipe {recipe.model}: stage {index + 1} of {len(recipe.stages)}, {stage.file}"
            + (" (resumed)" if resume else "")
        )
        result = train(config, resume=resume, progress=progress)
        results.append(result)
        if result.interrupted or result.failure:
            break
    return results


def _shown(path: Path) -> Path:
    """``path`` relative to the working folder where it lies below it."""
    try:
        return path.relative_to(Path.cwd())
    except ValueError:
        return path
