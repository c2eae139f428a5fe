"""Design search: Optuna over the hyperparameters of pattern and metasurface design.

Both designers take settings that decide what they find: the learning rate, the number of steps,
the initialisation and its seed, the objective, and for a metasurface the geometry (maximum
height, distance to the photodiodes, pillar index). A search draws these settings for one trial
after another (Optuna's TPE sampler), designs with them and keeps the score of every trial in a
*study*:

- :func:`search_patterns` drives :func:`~splitcam.design.kernels.design_pattern` and maximises
  one score, the closed-form LMMSE PSNR of the designed pattern (``-10 log10`` of its MSE
  averaged over the sigmas, or the mean PSNR). A trial designs in stages of ``report_every``
  steps, each stage continuing from the last one's pattern (``init="exact"``, Adam starting
  afresh), and reports the score after every stage: the curve the median rule prunes on (after
  a warm-up, a trial below the median of the finished trials at the same step stops there; one
  that has run all its steps is kept).
- :func:`search_metasurfaces` drives :func:`~splitcam.design.metasurface.design_metasurface`
  and maximises two scores at once: the image quality (the closed-form LMMSE PSNR, as above) and
  the light collected (the mean RGGB collection efficiency of a 2x2 router,
  :func:`~splitcam.physics.optics.rggb_collection`; for other periods the mean share of light
  that reaches the photodiodes of the kernel window). The result is a Pareto front.

The study lives in one file, ``<folder>/journal.log`` (Optuna's journal storage, no database
server), so several processes or cluster jobs pointed at the same folder share one study, and a
search started again on the folder adds trials to it. The first call writes the fixed settings
(start pattern, sigmas, optics, ...) into the study; a later call with other settings is refused.
Every finished trial's pattern is written to ``<folder>/<mode>/<trial>.toml`` (and its height map
to ``.npy`` for a metasurface). A design is deterministic given its settings, so
:meth:`Search.reproduce` designs a trial again and finds its scores.

Optuna is an optional dependency (``pip install 'splitcam[search]'``); this module imports it,
and torch, only when a search runs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..checks import check_count
from .defaults import DEFAULT_LR, DEFAULT_STEPS

if TYPE_CHECKING:
    from ..patterns import Pattern

logger = logging.getLogger(__name__)

__all__ = [
    "INSTALL",
    "METASURFACE_SPACE",
    "PATTERN_SPACE",
    "Search",
    "open_search",
    "search_metasurfaces",
    "search_patterns",
]

#: How to install what a search needs.
INSTALL = "pip install 'splitcam[search]'"
#: The journal file of a study, in the study's folder.
JOURNAL = "journal.log"
MODES = ("patterns", "metasurfaces")

#: What :func:`search_patterns` searches by default. Each entry is ``("log", low, high)`` (a
#: float drawn on a log scale), ``("float", low, high)``, ``("int", low, high[, step])`` or
#: ``("choice", a, b, ...)``; a plain value holds the setting fixed. ``seed`` is drawn only for
#: the ``random`` initialisation (the others do not use it).
PATTERN_SPACE: dict[str, Any] = {
    "lr": ("log", 0.01, 0.5),
    "steps": ("int", 100, 600, 50),
    "init": ("choice", "support", "exact", "random"),
    "objective": ("choice", "mse", "psnr"),
    "seed": ("int", 0, 99),
}
#: What :func:`search_metasurfaces` searches by default (as :data:`PATTERN_SPACE`; lengths in µm).
#: The ``routing`` objective needs a 2x2 period: other periods design for ``lmmse`` only.
METASURFACE_SPACE: dict[str, Any] = {
    "max_height": ("float", 0.4, 2.0),
    "distance": ("float", 0.5, 4.0),
    "index": ("float", 1.5, 3.5),
    "lr": ("log", 0.01, 0.5),
    "init": ("choice", "random", "lens"),
    "objective": ("choice", "lmmse", "routing"),
    "seed": ("int", 0, 99),
}
#: The settings :func:`search_patterns` tries first in a new study (``baseline=True``): the
#: designer's defaults, so the table of a search shows what it gained over them.
PATTERN_BASELINES = (
    {"lr": DEFAULT_LR, "steps": DEFAULT_STEPS, "init": "support", "objective": "mse"},
)
_KINDS = ("log", "float", "int", "choice")


def _optuna() -> Any:
    """The ``optuna`` module, or a ModuleNotFoundError (``name="optuna"``) that says how to
    install it."""
    try:
        import optuna
    except ImportError:
        raise ModuleNotFoundError(f"design search needs optuna: {INSTALL}", name="optuna") from None
    return optuna


def _journal(path: Path) -> Any:
    """Optuna's journal storage on a file (``JournalFileBackend`` from optuna 4,
    ``JournalFileStorage`` before)."""
    optuna = _optuna()
    try:
        from optuna.storages.journal import JournalFileBackend as Backend
    except ImportError:  # optuna < 4
        from optuna.storages import JournalFileStorage as Backend
    return optuna.storages.JournalStorage(Backend(str(path)))


def _check_spec(name: str, spec: Any) -> None:
    """Refuse a search-space entry that is neither a plain value nor a valid range or choice."""
    if not isinstance(spec, tuple):
        if not isinstance(spec, (bool, int, float, str)):
            raise ValueError(f"search space {name}: expected a value or a tuple, got {spec!r}")
        return
    if not spec or spec[0] not in _KINDS:
        raise ValueError(f"search space {name}: expected a tuple starting with one of {_KINDS}")
    kind, *args = spec
    if kind == "choice":
        if not args:
            raise ValueError(f"search space {name}: no choices")
        return
    if len(args) not in ((2, 3) if kind == "int" else (2,)) or not args[0] < args[1]:
        raise ValueError(f"search space {name}: expected ({kind!r}, low, high), got {spec!r}")
    if kind == "log" and args[0] <= 0:
        raise ValueError(f"search space {name}: a log range needs low > 0, got {spec!r}")


def _space(defaults: Mapping[str, Any], given: Mapping[str, Any] | None) -> dict[str, Any]:
    """``defaults`` with the entries of ``given`` in their place, each checked."""
    unknown = sorted(set(given or {}) - set(defaults))
    if unknown:
        raise ValueError(
            f"search space: unknown setting(s) {', '.join(unknown)}; known: {', '.join(defaults)}"
        )
    space = {**defaults, **(given or {})}
    for name, spec in space.items():
        _check_spec(name, spec)
    return space


def _suggest(trial: Any, name: str, spec: Any) -> Any:
    """One setting of ``trial`` from its search-space entry (a plain value: a one-way choice,
    so the trial's parameters hold every setting)."""
    if not isinstance(spec, tuple):
        return trial.suggest_categorical(name, [spec])
    kind, *args = spec
    if kind == "choice":
        return trial.suggest_categorical(name, list(args))
    if kind == "int":
        step = int(args[2]) if len(args) > 2 else 1
        return trial.suggest_int(name, int(args[0]), int(args[1]), step=step)
    return trial.suggest_float(name, float(args[0]), float(args[1]), log=kind == "log")


def _draw(trial: Any, space: Mapping[str, Any]) -> dict[str, Any]:
    """The settings of a trial: every entry of ``space``, ``seed`` only for a random start."""
    params = {name: _suggest(trial, name, spec) for name, spec in space.items() if name != "seed"}
    params["seed"] = _suggest(trial, "seed", space["seed"]) if params["init"] == "random" else 0
    return params


def _admits(spec: Any, value: Any) -> bool:
    """Whether ``value`` lies in the search-space entry ``spec``."""
    if not isinstance(spec, tuple):
        return spec == value
    kind, *args = spec
    if kind == "choice":
        return value in args
    return args[0] <= value <= args[1]


def _mse_psnr(mse: Sequence[float], metric: str) -> float:
    """The score of MSEs per sigma: ``-10 log10`` of their mean (``mse``) or their mean PSNR."""
    if metric == "mse":
        return -10.0 * math.log10(sum(mse) / len(mse))
    return sum(-10.0 * math.log10(m) for m in mse) / len(mse)


# -- one trial of each kind ----------------------------------------------------------------------


def _pattern_trial(
    settings: Mapping[str, Any],
    params: Mapping[str, Any],
    report: Callable[[int, float], None] | None = None,
    name: str | None = None,
) -> tuple[Any, tuple[float]]:
    """Design a pattern with a trial's ``params`` in stages of ``settings["report_every"]``
    steps, calling ``report(steps done, score)`` after each; the joined
    :class:`~splitcam.design.kernels.DesignResult` and ``(score,)``."""
    from ..patterns import Pattern
    from .kernels import design_pattern

    start = Pattern.from_dict(settings["start"])
    steps = int(params["steps"])
    every = int(settings["report_every"]) or steps
    stages, pattern, init, done = [], start, str(params["init"]), 0
    while done < steps:
        stage = design_pattern(
            pattern,
            init=init,
            sigmas=settings["sigmas"],
            steps=min(every, steps - done),
            lr=float(params["lr"]),
            seed=int(params.get("seed", 0)),
            radius=int(settings["radius"]),
            objective=str(params["objective"]),
            name=name or f"{start.name}-designed",
        )
        stages.append(stage)
        done += len(stage.history)
        pattern, init = stage.pattern, "exact"
        if report is not None:
            report(done, _mse_psnr(list(stage.mse_after.values()), settings["metric"]))
    first, last = stages[0], stages[-1]
    metadata = {**first.pattern.metadata, "steps": steps, "stage_steps": every}
    designed = dataclasses.replace(
        last.pattern, description=first.pattern.description, metadata=metadata
    )
    result = dataclasses.replace(
        last,
        pattern=designed,
        start=start,
        init=first.init,
        mse_before=first.mse_before,
        history=[v for s in stages for v in s.history],
        seconds=sum(s.seconds for s in stages),
    )
    return result, (_mse_psnr(list(result.mse_after.values()), settings["metric"]),)


def _optics(settings: Mapping[str, Any], params: Mapping[str, Any]) -> Any:
    """The :class:`~splitcam.physics.optics.Optics` of a trial: the fixed ones of the study with
    the trial's height, distance and index."""
    from ..physics.optics import Optics

    fixed = dict(settings["optics"])
    fixed["kernel_size"] = tuple(fixed["kernel_size"])
    for key in ("max_height", "distance", "index"):
        fixed[key] = float(params[key])
    return Optics(**fixed)


def _metasurface_trial(
    settings: Mapping[str, Any],
    params: Mapping[str, Any],
    report: Callable[[int, float], None] | None = None,
    name: str = "metasurface",
) -> tuple[Any, tuple[float, float]]:
    """Design a metasurface with a trial's ``params``; the
    :class:`~splitcam.design.metasurface.MetasurfaceDesign` and ``(image quality, light)``."""
    del report  # a two-objective study is not pruned
    from .metasurface import design_metasurface

    period = tuple(settings["period"])
    result = design_metasurface(
        period,
        _optics(settings, params),
        init=str(params["init"]),
        sigmas=settings["sigmas"],
        steps=int(settings["steps"]),
        lr=float(params["lr"]),
        seed=int(params.get("seed", 0)),
        radius=int(settings["radius"]),
        name=name,
        objective=str(params["objective"]),
    )
    mse = [10.0 ** (-p / 10.0) for p in result.psnr_after.values()]
    if result.collection_after is not None:
        light = sum(result.collection_after) / len(result.collection_after)
    else:
        light = float(result.pattern.kernels.sum(axis=(2, 3)).mean())
    return result, (_mse_psnr(mse, settings["metric"]), light)


_TRIALS = {"patterns": _pattern_trial, "metasurfaces": _metasurface_trial}


# -- the study -----------------------------------------------------------------------------------


@dataclass
class Search:
    """A design search: its Optuna study (on ``folder/journal.log``) and fixed settings.

    Attributes:
        study: The :class:`optuna.study.Study`.
        folder: The study's folder (journal, trial patterns).
        mode: ``patterns`` (one score, maximised) or ``metasurfaces`` (image quality and light
            collected, both maximised).
        settings: What every trial shares (start pattern or optics, sigmas, ...), as stored in
            the study.
    """

    study: Any
    folder: Path
    mode: str
    settings: dict[str, Any]

    @property
    def objectives(self) -> tuple[str, ...]:
        """The names of the scores, in the order of a trial's values."""
        if self.mode == "patterns":
            return ("closed-form LMMSE PSNR (dB)",)
        return ("closed-form LMMSE PSNR (dB)", "light collected")

    def finished(self) -> list[Any]:
        """The finished trials (:class:`optuna.trial.FrozenTrial`), in trial order."""
        optuna = _optuna()
        return self.study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))

    def best(self) -> list[Any]:
        """The best trials, best first: for one score every finished trial by its score; for two,
        the Pareto front by image quality."""
        if self.mode == "patterns":
            return sorted(self.finished(), key=lambda t: (-t.values[0], t.number))
        return sorted(self.study.best_trials, key=lambda t: (-t.values[0], t.number))

    def pattern_file(self, number: int) -> Path:
        """Where trial ``number``'s pattern is written (``.npy`` beside it: the height map)."""
        return self.folder / self.mode / f"{number:04d}.toml"

    def trial(self, number: int | None = None) -> Any:
        """Trial ``number`` (default: the first of :meth:`best`)."""
        if number is None:
            best = self.best()
            if not best:
                raise ValueError(f"the study in {self.folder} has no finished trial yet")
            return best[0]
        return self.study.trials[number]

    def reproduce(self, number: int | None = None) -> tuple[Any, tuple[float, ...]]:
        """Design trial ``number`` (default: the best) again from its parameters and the study's
        settings; the design result and its scores (equal to the trial's values: designs are
        deterministic on a given machine and library version)."""
        trial = self.trial(number)
        return _TRIALS[self.mode](self.settings, trial.params, None, self._name(trial.number))

    def _name(self, number: int) -> str:
        return f"{self.settings['name']}-trial{number}"


def _study(
    folder: Path, mode: str, settings: dict, *, seed: int | None, startup: int, warmup: int = 0
) -> Search:
    """Open (or create) the study ``mode`` in ``folder``'s journal with ``settings``.

    Raises:
        ValueError: The study exists with other settings.
    """
    optuna = _optuna()
    folder.mkdir(parents=True, exist_ok=True)
    storage = _journal(folder / JOURNAL)
    directions = ["maximize"] * (1 if mode == "patterns" else 2)
    with _quiet_optuna():
        study = optuna.create_study(
            storage=storage, study_name=mode, directions=directions, load_if_exists=True
        )
    settings = json.loads(json.dumps(settings))
    stored = study.user_attrs.get("settings")
    if stored is None:
        study.set_user_attr("settings", settings)
    elif stored != settings:
        changed = sorted(k for k in set(stored) | set(settings) if stored.get(k) != settings.get(k))
        raise ValueError(
            f"the {mode} study in {folder} was made with other settings ({', '.join(changed)}); "
            f"give another folder to search with these"
        )
    # A sampler seeded afresh draws the same first trials again: offset by the trials so far.
    sampler = optuna.samplers.TPESampler(
        seed=None if seed is None else seed + len(study.trials), n_startup_trials=startup
    )
    pruner = (
        optuna.pruners.MedianPruner(n_startup_trials=startup, n_warmup_steps=warmup)
        if mode == "patterns"
        else optuna.pruners.NopPruner()
    )
    study = optuna.load_study(study_name=mode, storage=storage, sampler=sampler, pruner=pruner)
    return Search(study=study, folder=folder, mode=mode, settings=settings)


def open_search(folder: str | Path, mode: str = "patterns") -> Search:
    """The search ``mode`` (``patterns`` or ``metasurfaces``) already in ``folder``.

    Raises:
        ValueError: No such study in ``folder``.
    """
    optuna = _optuna()
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    folder = Path(folder)
    if not (folder / JOURNAL).is_file():
        raise ValueError(f"no search in {folder} (no {JOURNAL})")
    storage = _journal(folder / JOURNAL)
    try:
        study = optuna.load_study(study_name=mode, storage=storage)
    except KeyError:
        raise ValueError(f"no {mode} search in {folder}") from None
    return Search(study, folder, mode, dict(study.user_attrs.get("settings", {})))


@contextlib.contextmanager
def _quiet_optuna() -> Iterator[None]:
    """Optuna's own per-trial messages off (the search reports progress itself)."""
    optuna = _optuna()
    before = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        yield
    finally:
        optuna.logging.set_verbosity(before)


def _save_trial(search: Search, number: int, result: Any) -> None:
    """Write a finished trial's pattern (and a metasurface's height map) into the folder."""
    from ..io import atomic_path
    from ..patterns import save

    path = search.pattern_file(number)
    path.parent.mkdir(parents=True, exist_ok=True)
    save(result.pattern, path)
    if search.mode == "metasurfaces":
        import numpy as np

        with atomic_path(path.with_suffix(".npy")) as tmp:
            np.save(tmp, result.height.cpu().numpy())


def _describe(params: Mapping[str, Any]) -> str:
    return ", ".join(
        f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in params.items()
    )


def _run(
    search: Search,
    trials: int,
    space: Mapping[str, Any],
    first: Sequence[tuple[Mapping[str, Any], bool]],
    progress: bool,
) -> Search:
    """Enqueue ``first`` (settings, whether a baseline) and run ``trials`` trials."""
    optuna = _optuna()
    for params, baseline in first:
        search.study.enqueue_trial(
            dict(params), user_attrs={"baseline": baseline}, skip_if_exists=baseline
        )
    design = _TRIALS[search.mode]

    def objective(trial: Any) -> tuple[float, ...] | float:
        params = _draw(trial, space)

        def report(step: int, value: float) -> None:
            trial.report(value, step)
            # a design that has run all its steps is kept whatever its score
            if step < params["steps"] and trial.should_prune():
                raise optuna.TrialPruned(f"{value:.3f} at step {step}: below the median")

        result, values = design(search.settings, params, report, search._name(trial.number))
        trial.set_user_attr("seconds", result.seconds)
        _save_trial(search, trial.number, result)
        return values[0] if len(values) == 1 else values

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=trials, desc=f"search {search.mode}", unit="trial")

    def done(study: Any, trial: Any) -> None:
        state = trial.state.name.lower()
        if state == "complete":
            scores = ", ".join(f"{v:.4g}" for v in trial.values)
        elif trial.last_step is not None:
            scores = f"at step {trial.last_step}"
        else:
            scores = ""
        if bar is None:
            logger.info("trial %d %s %s (%s)", trial.number, state, scores, _describe(trial.params))
        else:
            bar.set_postfix({"trial": trial.number, state: scores}, refresh=False)
            bar.update(1)

    try:
        with _quiet_optuna():
            search.study.optimize(objective, n_trials=trials, callbacks=[done])
    finally:
        if bar is not None:
            bar.close()
    return search


def _first_trials(
    space: Mapping[str, Any],
    baselines: Sequence[Mapping[str, Any]],
    enqueue: Sequence[Mapping[str, Any]],
    baseline: bool,
    new: bool,
) -> list[tuple[dict[str, Any], bool]]:
    """The trials to run first: the baselines that the search space admits (new studies only,
    with ``baseline``), then ``enqueue``."""
    first = []
    if baseline and new:
        for params in baselines:
            # a fixed setting takes its fixed value; seed only matters for a random start
            keep = {k: v for k, v in params.items() if isinstance(space[k], tuple)}
            if (keep["init"] if "init" in keep else space["init"]) != "random":
                keep.pop("seed", None)
            if all(_admits(space[k], v) for k, v in keep.items()) and (keep, True) not in first:
                first.append((keep, True))
    return first + [(dict(p), False) for p in enqueue]


def _check_trials(trials: int, report_every: int, metric: str) -> None:
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 0:
        raise ValueError(f"expected trials as an integer >= 0, got {trials!r}")
    if isinstance(report_every, bool) or not isinstance(report_every, int) or report_every < 0:
        raise ValueError(f"expected report_every as an integer >= 0, got {report_every!r}")
    if metric not in ("mse", "psnr"):
        raise ValueError(f"metric must be mse or psnr, got {metric!r}")


def search_patterns(
    start: Pattern,
    *,
    trials: int,
    folder: str | Path = "search",
    sigmas: Sequence[float] | None = None,
    radius: int | None = None,
    space: Mapping[str, Any] | None = None,
    report_every: int = 50,
    metric: str = "mse",
    startup: int = 5,
    warmup: int = 100,
    seed: int | None = 0,
    baseline: bool = True,
    enqueue: Sequence[Mapping[str, Any]] = (),
    progress: bool = False,
) -> Search:
    """Search the settings of :func:`~splitcam.design.kernels.design_pattern` for the highest
    closed-form LMMSE PSNR of the designed pattern, with pruning.

    Args:
        start: Start pattern, fixed.
        trials: Trials to run in this call (added to those in the study).
        folder: The study's folder (journal and trial patterns); created if missing.
        sigmas: Noise levels (8-bit units) of the objective and the score (default: the
            designer's).
        radius: LMMSE filter radius (default: the designer's).
        space: Entries replacing those of :data:`PATTERN_SPACE` (a plain value fixes one).
        report_every: Steps per stage: the score is reported (and the trial may be pruned)
            after each; 0 designs in one stage (exactly ``design_pattern`` with the trial's
            settings, never pruned).
        metric: The score: ``mse`` (``-10 log10`` of the MSE averaged over the sigmas) or
            ``psnr`` (the mean PSNR over the sigmas), whatever objective a trial designs for.
        startup: Trials that finish before pruning starts, and random trials before the
            sampler models the scores.
        warmup: Steps before a trial may be pruned. The median rule compares trials at the same
            step, so a setting that climbs slowly at first (a small learning rate, the
            ``exact`` start) is pruned at an early report even where it would have ended
            higher; the warm-up spares the first reports.
        seed: Seed of the sampler (offset by the trials already in the study); ``None``: random.
        baseline: In a new study, first design with the designer's defaults
            (:data:`PATTERN_BASELINES`), where the space admits them.
        enqueue: Settings to try first (each a dict of the space's names).
        progress: Show a progress bar over the trials.

    Returns:
        The :class:`Search`.

    Raises:
        ImportError: Optuna is not installed.
        ValueError: Bad settings, or a study in ``folder`` made with other settings.
    """
    from ..patterns import check_pattern
    from ..recon.lmmse import DEFAULT_RADIUS
    from .ascent import check_sigmas
    from .defaults import DEFAULT_SIGMAS

    _check_trials(trials, report_every, metric)
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise ValueError(f"expected warmup as an integer >= 0, got {warmup!r}")
    pattern = check_pattern(start, "start")
    settings = {
        "start": pattern.to_dict(),
        "name": pattern.name,
        "sigmas": check_sigmas(DEFAULT_SIGMAS if sigmas is None else sigmas),
        "radius": DEFAULT_RADIUS if radius is None else int(radius),
        "report_every": report_every,
        "metric": metric,
    }
    full = _space(PATTERN_SPACE, space)
    if any(objective == "network" for objective in _choices(full["objective"])):
        raise ValueError("a search designs for the closed-form objectives (mse, psnr) only")
    search = _study(Path(folder), "patterns", settings, seed=seed, startup=startup, warmup=warmup)
    first = _first_trials(full, PATTERN_BASELINES, enqueue, baseline, not search.study.trials)
    return _run(search, trials, full, first, progress)


def _lowest(spec: Any) -> float:
    """The lowest value a numeric search-space entry admits."""
    if not isinstance(spec, tuple):
        return float(spec)
    return float(min(spec[1:]) if spec[0] == "choice" else spec[1])


def _choices(spec: Any) -> list[Any]:
    """The values a choice entry offers (a plain value: itself; a range: none)."""
    if not isinstance(spec, tuple):
        return [spec]
    return list(spec[1:]) if spec[0] == "choice" else []


def search_metasurfaces(
    period: tuple[int, int] = (2, 2),
    optics: Any = None,
    *,
    trials: int,
    folder: str | Path = "search",
    steps: int = 200,
    sigmas: Sequence[float] | None = None,
    radius: int | None = None,
    space: Mapping[str, Any] | None = None,
    metric: str = "mse",
    startup: int = 10,
    seed: int | None = 0,
    baseline: bool = True,
    enqueue: Sequence[Mapping[str, Any]] = (),
    progress: bool = False,
) -> Search:
    """Search the settings of :func:`~splitcam.design.metasurface.design_metasurface` for two
    scores at once, image quality (closed-form LMMSE PSNR) and light collected; the Pareto
    front is :meth:`Search.best`.

    Args:
        period: ``(Ph, Pw)`` of the router.
        optics: The fixed geometry and materials (an :class:`~splitcam.physics.optics.Optics`;
            default ``Optics()``); each trial replaces its ``max_height``, ``distance`` and
            ``index``.
        trials: As :func:`search_patterns`.
        folder: As :func:`search_patterns`.
        steps: Adam steps of every design.
        sigmas: As :func:`search_patterns`.
        radius: As :func:`search_patterns`.
        space: Entries replacing those of :data:`METASURFACE_SPACE`.
        metric: As :func:`search_patterns`.
        startup: Random trials before the sampler models the scores.
        seed: As :func:`search_patterns`.
        baseline: As :func:`search_patterns` (baselines: the geometry of ``optics`` designed
            with the designer's defaults, ``lmmse`` and ``routing``).
        enqueue: As :func:`search_patterns`.
        progress: As :func:`search_patterns`.

    Raises:
        ImportError: Optuna is not installed.
        ValueError: Bad settings, an index range not above the spacer's index, or a study in
            ``folder`` made with other settings.
    """
    from ..physics.optics import Optics
    from ..recon.lmmse import DEFAULT_RADIUS
    from .ascent import check_sigmas
    from .defaults import DEFAULT_SIGMAS

    _check_trials(trials, 0, metric)
    check_count(steps, "steps", 1)
    period = (int(period[0]), int(period[1]))
    optics = Optics() if optics is None else optics
    full = _space(METASURFACE_SPACE, space)
    if period != (2, 2) and "objective" not in (space or {}):
        full["objective"] = "lmmse"  # routing needs a 2x2 period
    if period != (2, 2) and "routing" in _choices(full["objective"]):
        raise ValueError(f"the routing objective needs a 2x2 period, got {period}")
    if _lowest(full["index"]) <= optics.spacer_index:
        raise ValueError(
            f"the pillar index must stay above the spacer's ({optics.spacer_index:g}), "
            f"got {full['index']!r}"
        )
    settings = {
        "period": list(period),
        "optics": _optics_settings(optics),
        "name": "metasurface",
        "steps": steps,
        "sigmas": check_sigmas(DEFAULT_SIGMAS if sigmas is None else sigmas),
        "radius": DEFAULT_RADIUS if radius is None else int(radius),
        "metric": metric,
    }
    search = _study(Path(folder), "metasurfaces", settings, seed=seed, startup=startup)
    baselines = _metasurface_baselines(optics)
    first = _first_trials(full, baselines, enqueue, baseline, not search.study.trials)
    return _run(search, trials, full, first, progress)


def _metasurface_baselines(optics: Any) -> list[dict[str, Any]]:
    """What :func:`search_metasurfaces` tries first in a new study (``baseline=True``): the
    geometry of ``optics`` designed with the designer's defaults, for each objective."""
    geometry = {"max_height": optics.max_height, "distance": optics.distance}
    common = {**geometry, "index": optics.index, "lr": 0.1, "init": "random", "seed": 0}
    return [{**common, "objective": objective} for objective in ("lmmse", "routing")]


def _optics_settings(optics: Any) -> dict[str, Any]:
    """The fixed fields of an :class:`~splitcam.physics.optics.Optics`, as plain data."""
    import numpy as np

    fixed = {}
    for f in dataclasses.fields(optics):
        if f.name in ("max_height", "distance", "index"):
            continue
        value = getattr(optics, f.name)
        fixed[f.name] = np.asarray(value).tolist() if isinstance(value, np.ndarray) else value
    fixed["kernel_size"] = list(fixed["kernel_size"])
    return fixed
