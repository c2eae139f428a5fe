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

A model whose weights are a blend of two others (``splitcam models blend``), or that trained on
from one, records the blend whole: its weight and each end's provenance, each end a chain of
stages or a blend again. Its recipe is a tree (:class:`Blend`): each end is replayed, the two are
blended with the recorded weight, and the model's own stages, if any, train on from the blend.
The runs of a tree's chains are named by what they are (``OUT/<i>-<stage>-<digest>``, the digest
of the stages up to it and what the first started from), so two ends that share their first
stages train them once.

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

import hashlib
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
    "Blend",
    "Recipe",
    "Stage",
    "blend_of",
    "read_recipe",
    "recipe_model",
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
    """A model's stages, in order; with ``blend``, the stages train on from that blend (none:
    the model is the blend)."""

    model: str
    stages: tuple[Stage, ...]
    blend: Blend | None = None

    def count(self) -> tuple[int, int]:
        """The runs and the blends that make the model, each once: two ends of a blend that
        share their first stages train them once (:func:`run_recipe`)."""
        runs: set[Path] = set()
        blends: set[Path] = set()
        _gather(self, self.blend is not None, runs, blends)
        return len(runs), len(blends)


@dataclass(frozen=True)
class Blend:
    """Weights on the line between two recipes' models
    (:func:`~splitcam.training.models.blend_models`): ``1 - weight`` of ``start``'s and
    ``weight`` of ``end``'s, stored as ``storage``."""

    weight: float
    start: Recipe
    end: Recipe
    storage: str = "float32"


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
    per run of its provenance, consecutive segments of one file and settings merged; where its
    weights are a blend (or it trained on from one), the blend's two ends' recipes, each read
    the same way from the blend's record, and its own stages after the blend.

    Raises:
        ConfigError: A segment that records no settings (a model exported before segments
            recorded them, and not filled in by ``scripts/name_stage_files.py``), or no
            segments and no blend.
    """
    provenance = meta.get("provenance") or {}
    segments = list(provenance.get("segments") or [])
    blend = None
    if record := blend_of(meta):
        own = bool(provenance.get("blend"))
        # a blend recorded before blends kept their storage: the model's own is its header's;
        # one it trained on from was a file between runs, replayed in float32
        storage = record.get("storage") or (meta.get("storage") if own else None) or "float32"
        blend = Blend(
            float(record["weight"]),
            shipped_recipe(record["start"], f"{name}, its blend's start"),
            shipped_recipe(record["end"], f"{name}, its blend's end"),
            storage,
        )
        # the blend's own segments are its ends'; what trained after it is the model's
        inside = _blended_segments(record)
        segments = [] if own else [s for s in segments if s not in inside]
    stages = _stages(segments, name)
    if not stages and blend is None:
        raise ConfigError(f"{name}: its provenance has no segments")
    return Recipe(str(meta.get("name", name)), stages, blend)


def _blended_segments(record: dict[str, Any]) -> list[dict[str, Any]]:
    """Every segment a blend's record holds: its ends', and their blends' ends' in turn."""
    segments = []
    for end in (record["start"], record["end"]):
        segments += (end.get("provenance") or {}).get("segments") or []
        if inner := blend_of(end):
            segments += _blended_segments(inner)
    return segments


def _stages(segments: list[dict[str, Any]], name: str) -> tuple[Stage, ...]:
    """One stage per run of ``segments`` (consecutive segments of one file and settings are a
    run continued), each to train the steps its segments trained."""
    stages: list[tuple[str, dict[str, Any], int]] = []
    for index, segment in enumerate(segments):
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
    return tuple(
        Stage(
            file,
            TrainConfig.from_saved(settings, source=f"{name}: {file}").override(
                {"optim.steps": steps, "run.time_limit": None}
            ),
        )
        for file, settings, steps in stages
    )


def read_recipe(spec: str | Path) -> Recipe:
    """A shipped model's recipe by name or a model file's (:func:`shipped_recipe`), or a
    recipe file.

    Raises:
        ConfigError: No such model or file (the message lists the shipped models), a damaged
            model or malformed recipe file, or a stage file that does not exist.
    """
    if isinstance(spec, str) and spec in recipe_names():
        header = MODELS_DIR / f"{spec}.json"
        return shipped_recipe(json.loads(header.read_text(encoding="utf-8")), spec)
    path = Path(spec)
    if path.suffix not in (".toml", ".json") or not path.is_file():
        known = ", ".join(recipe_names()) or "none"
        raise ConfigError(
            f"--recipe {spec}: no such model or file (shipped: {known}; or a model's .json, "
            "or a recipe .toml)"
        )
    if path.suffix == ".json":  # a model file of one's own: its header is its recipe
        from ..recon.loading import ModelError, load_model

        try:
            return shipped_recipe(load_model(path).meta, path.stem)
        except ModelError as exc:
            raise ConfigError(f"--recipe {spec}: {exc}") from None
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


def stage_folder(out: Path, index: int, stage: Stage, key: str | None = None) -> Path:
    """Where stage ``index`` (from 0) of a recipe trains: ``OUT/<index + 1>-<parent>-<stem>``
    (``2-edges-A``), so stages of one name in different folders stay apart; in a tree of
    blends, ``-<key>`` after it (:func:`recipe_model`)."""
    file = Path(stage.file)
    parent = file.parent.name
    label = file.stem if parent in ("experiments", "") else f"{parent}-{file.stem}"
    return out / (f"{index + 1}-{label}" + (f"-{key}" if key else ""))


def _digest(*parts: Any) -> str:
    """Eight hex digits that name what ``parts`` describe."""
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:8]


def _changed(config: TrainConfig) -> dict[str, Any]:
    """The settings of ``config`` that differ from the defaults: what names a stage in a tree,
    so a setting added to the package later (at a default that keeps the old behaviour) leaves
    the names of runs already trained as they were."""
    default = TrainConfig().to_dict()
    return {
        f"{section}.{key}": value
        for section, values in config.to_dict().items()
        for key, value in values.items()
        if default.get(section, {}).get(key) != value
    }


def _places(recipe: Recipe, out: Path, tree: bool) -> tuple[Path | None, list[Path], str | None]:
    """Where a recipe's blend (None without one) and each of its stages land under ``out``,
    and the key of what it makes: in a tree (``tree``), each run folder and blend file is
    named by the digest of the stages up to it and what the first started from, so the same
    stages from the same start share a folder; a plain chain keeps its stage names alone."""
    blend_file, key = None, None
    if recipe.blend is not None:
        b = recipe.blend
        ends = (_places(r, out, True)[2] for r in (b.start, b.end))
        key = _digest("blend", b.weight, b.storage, *ends)
        blend_file = out / f"blend-{key}.json"
    folders = []
    for index, stage in enumerate(recipe.stages):
        key = _digest(key, stage.file, _changed(stage.config)) if tree else None
        folders.append(stage_folder(out, index, stage, key))
    return blend_file, folders, key


def _gather(recipe: Recipe, tree: bool, runs: set[Path], blends: set[Path]) -> None:
    """Add where each run and blend of ``recipe`` lands (:func:`_places`) to the two sets."""
    blend_file, folders, _ = _places(recipe, Path(), tree)
    runs.update(folders)
    if recipe.blend is not None:
        blends.add(blend_file)  # type: ignore[arg-type]
        for end in (recipe.blend.start, recipe.blend.end):
            _gather(end, True, runs, blends)


def recipe_model(recipe: Recipe, out: str | Path) -> Path:
    """Where :func:`run_recipe` leaves the model of ``recipe`` under ``out``: its last stage's
    run folder, or the blend's model file where it has no stages after a blend."""
    blend_file, folders, _ = _places(recipe, Path(out), recipe.blend is not None)
    return folders[-1] if folders else blend_file  # type: ignore[return-value]


def run_recipe(
    recipe: Recipe, out: str | Path, overrides: dict[str, Any], *, progress: bool = True
) -> list[Any]:
    """Train every stage of ``recipe`` under ``out`` (see the module), skipping finished ones
    and resuming an interrupted one; a blend's two ends first, then the blend. Returns each
    trained stage's :class:`~splitcam.training.trainer.TrainResult`; stops at the first that
    did not finish. :func:`recipe_model` says where the model lands."""
    results: list[Any] = []
    _replay(recipe, Path(out), overrides, progress, results, recipe.blend is not None)
    return results


def _replay(
    recipe: Recipe, out: Path, overrides: dict[str, Any], progress: bool, results: list, tree: bool
) -> Path | None:
    """:func:`run_recipe` on one node of a tree: its model, or None when a stage stopped."""
    from .sweep import Experiment, status
    from .trainer import train

    blend_file, folders, _ = _places(recipe, out, tree)
    previous = blend_file
    if recipe.blend is not None and not _blend(
        recipe, blend_file, out, overrides, progress, results
    ):
        return None
    for index, (stage, folder) in enumerate(zip(recipe.stages, folders, strict=True)):
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
            return None
    return previous


def _blend(recipe: Recipe, target: Path, out: Path, overrides, progress, results) -> bool:
    """Make ``recipe``'s blend as ``target`` (once): replay both ends, export each end that is
    a run folder as a model file (``OUT/ends/``, float16 as ``splitcam models export``
    writes), blend. False when an end stopped."""
    from .models import blend_models, export_model

    assert recipe.blend is not None
    ends = []
    for end in (recipe.blend.start, recipe.blend.end):
        made = _replay(end, out, overrides, progress, results, True)
        if made is None:
            return False
        if made.suffix != ".json":  # a run folder
            exported = out / "ends" / f"{made.name}.json"
            if not exported.exists():
                export_model(made, exported, name=end.model)
            made = exported
        ends.append(made)
    if not target.exists():
        logger.info(f"recipe {recipe.model}: blending {ends[0].name} and {ends[1].name}")
        blend_models(
            *ends, recipe.blend.weight, target, name=recipe.model, storage=recipe.blend.storage
        )
    return True


def _shown(path: Path) -> Path:
    """``path`` relative to the working folder where it lies below it."""
    try:
        return path.relative_to(Path.cwd())
    except ValueError:
        return path
