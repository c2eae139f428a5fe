"""``splitcam train --recipe``: a shipped model trained again end to end, stage by stage.

Most shipped models are several runs, each continuing the last from its weights with settings of
its own: the paper's recipe, then a border fine-tuning, then the noise range of the paper's
tables, then photos at half size, then a GPU segment (``experiments/README.md``). A **recipe**
(``experiments/recipes/<model>.toml``) lists those configuration files in order::

    model = "A"
    stages = ["../A.toml", "../edges/A.toml", "../sigma20/A.toml"]   # relative to the recipe

:func:`run_recipe` trains stage ``i`` into ``OUT/<i>-<stage>`` starting from stage ``i - 1``'s
run folder (the first stage from what its file says), with the settings given on the command
line (``--data``, ``--threads``, ``--device``...) applied to every stage. A stage that finished is
skipped and one that was interrupted is resumed, so the same command continues a recipe. Each
stage records its configuration file (``run.config_file``), so the provenance of the model
exported from the last stage names every file of the chain.
"""

from __future__ import annotations

import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .config import ConfigError, TrainConfig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["RECIPES_DIR", "Recipe", "read_recipe", "recipe_names", "run_recipe"]

logger = logging.getLogger(__name__)

#: Where the shipped models' recipes are (a recipe by name is looked up here).
RECIPES_DIR = Path(__file__).resolve().parents[3] / "experiments" / "recipes"


@dataclass(frozen=True)
class Recipe:
    """A model's stages: its name and the configuration files, in order."""

    model: str
    stages: tuple[Path, ...]


def recipe_names(folder: Path = RECIPES_DIR) -> list[str]:
    """The recipes in ``folder`` (the shipped models' by default), by name."""
    return sorted(p.stem for p in folder.glob("*.toml")) if folder.is_dir() else []


def read_recipe(spec: str | Path, folder: Path = RECIPES_DIR) -> Recipe:
    """A recipe file, or a recipe by model name in ``folder``.

    Raises:
        ConfigError: No such recipe (the message lists the known ones), a malformed file, or a
            stage file that does not exist.
    """
    path = Path(spec)
    if not path.suffix:
        path = folder / f"{spec}.toml"
    if not path.is_file():
        known = ", ".join(recipe_names(folder)) or "none"
        raise ConfigError(f"--recipe {spec}: no such recipe (known: {known}; or a .toml file)")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"recipe {path}: {exc}") from None
    stages = data.get("stages")
    if not isinstance(stages, list) or not stages or not all(isinstance(s, str) for s in stages):
        raise ConfigError(f'recipe {path}: expected stages = ["FILE.toml", ...]')
    files = tuple((path.parent / s).resolve() for s in stages)
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise ConfigError(f"recipe {path}: stage file {missing[0]} not found")
    return Recipe(str(data.get("model", path.stem)), files)


def stage_folder(out: Path, index: int, stage: Path) -> Path:
    """Where stage ``index`` (from 0) of a recipe trains: ``OUT/<index + 1>-<parent>-<stem>``
    (``2-edges-A``), so stages of one name in different folders stay apart."""
    parent = stage.parent.name
    label = stage.stem if parent in ("experiments", "") else f"{parent}-{stage.stem}"
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
        config = TrainConfig.from_file(stage).override(
            {
                **overrides,
                "run.out": str(folder),
                "run.config_file": str(_shown(stage)),
                **({"run.init_from": str(previous)} if previous is not None else {}),
            }
        )
        previous = folder
        state = status(Experiment(folder.name, stage, config, folder))  # as a sweep decides
        if state == "done":
            logger.info(f"recipe {recipe.model}: stage {index + 1} ({folder.name}) done, skipped")
            continue
        resume = state == "partial"
        logger.info(
            f"recipe {recipe.model}: stage {index + 1} of {len(recipe.stages)}, {_shown(stage)}"
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
