"""A training run's folder: its lock, what a resume may continue, and its logs.

This module is the one writer and reader of ``metrics.jsonl`` (one JSON object per logged step)
and ``changes.jsonl`` (the settings a resume changed, and from which step), and it judges from
them whether a finished run failed (:func:`failure_of`).
"""

from __future__ import annotations

import json
import logging
import math
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..io import appending, read_json_lines, stale_temporaries, write_text
from ..io import checkpoints as ckpt_io
from ..io.locks import FolderBusy, lock_folder
from .config import ConfigError, TrainConfig, dotted, read_config_file

logger = logging.getLogger(__name__)

METRICS_NAME = "metrics.jsonl"
CHANGES_NAME = "changes.jsonl"
CONFIG_NAME = "config.json"

#: The divergence guard gives up once it has halved the learning rate this many times.
GUARD_GIVES_UP = 10
#: A run that ends this many dB below its start in validation PSNR has failed.
FAILED_DROP_DB = 3.0

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

#: Settings that choose what validation scores. Changed on resume, the best score so far was
#: measured on something else, so the run's best starts again at its next validation.
VALIDATION_SETTINGS = (
    "data.val",
    "data.val_split",
    "data.val_max_images",
    "data.val_crop",
    "data.val_scale",
    "data.val_sigmas",
    "noise.val_photons",
    "pattern.val_patterns",
)


def lock_run(run_dir: Path) -> Any:
    """Hold the run folder's lock (:func:`splitcam.io.locks.lock_folder`) for the whole run: a
    second run on the same folder is refused at once (:class:`ConfigError`).

    Returns:
        The open lock file (close it to release the lock), or None.
    """
    try:
        return lock_folder(run_dir, "training run")
    except FolderBusy as exc:
        raise ConfigError(str(exc)) from None


def resumable(run_dir: Path) -> None:
    """Refuse ``--resume`` of a folder with neither a checkpoint nor a ``config.json``."""
    if not (run_dir / ckpt_io.CHECKPOINT_NAME).exists() and not (run_dir / CONFIG_NAME).is_file():
        raise ConfigError(f"no run to resume in {str(run_dir)!r}; drop --resume to start one there")


def resume_config(run_dir: str | Path) -> TrainConfig:
    """The settings of the run in ``run_dir`` (what ``--resume`` continues with): its
    checkpoint's, or, for a run that ended before its first checkpoint, its ``config.json``.

    Raises:
        ConfigError: Nothing to resume there.
        CheckpointError: The checkpoint is damaged or records no configuration.
    """
    run_dir = Path(run_dir)
    resumable(run_dir)
    ckpt_path = run_dir / ckpt_io.CHECKPOINT_NAME
    if ckpt_path.exists():
        loaded = ckpt_io.load(ckpt_path)
        ckpt_io.require(loaded, "config", purpose="its run cannot be resumed")
        return TrainConfig.from_saved(loaded.meta["config"], source=str(ckpt_path))
    path = run_dir / CONFIG_NAME
    return TrainConfig.from_saved(read_config_file(path), source=str(path))


@dataclass
class RunStart:
    """What a run starts from: the checkpoint it resumes (None for a new run), the settings the
    resume changes (``{key: [old, new]}``), and whether it restarts a run that was killed
    before its first checkpoint."""

    loaded: ckpt_io.Checkpoint | None = None
    changes: dict[str, list[Any]] = field(default_factory=dict)
    restarted: bool = False


def open_run(config: TrainConfig, run_dir: Path, resume: bool) -> RunStart:
    """Check that ``run_dir`` can take this run, and load the checkpoint a resume continues.

    Raises:
        ConfigError: Nothing to resume, or a new run in a folder that holds a checkpoint.
        CheckpointError: The checkpoint is damaged, or of a model these settings do not define.
    """
    ckpt_path = run_dir / ckpt_io.CHECKPOINT_NAME
    if resume and not ckpt_path.exists():
        resumable(run_dir)
        # Killed before its first checkpoint: nothing to continue but its settings.
        return RunStart(restarted=True)
    if not resume:
        if ckpt_path.exists():
            raise ConfigError(
                f"{str(run_dir)!r} already holds a checkpoint; use --resume to continue it or "
                f"choose another --out"
            )
        return RunStart()
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
    return RunStart(loaded, _changed_settings(saved, config))


def _flat(config: TrainConfig) -> dict[str, Any]:
    return dotted(config.to_dict())


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


class RunLog:
    """The logs a run writes into its folder: ``metrics.jsonl``, ``changes.jsonl``, and with
    ``run.tensorboard`` a TensorBoard event file. Only the main process keeps one."""

    def __init__(self, run_dir: Path, tensorboard: Any = None) -> None:
        self.run_dir = run_dir
        self.metrics_path = run_dir / METRICS_NAME
        self._tensorboard = tensorboard

    @classmethod
    def open(
        cls, config: TrainConfig, run_dir: Path, *, resumed_at: int | None, restarted: bool
    ) -> RunLog:
        """Prepare the folder for the steps to come and write its ``config.json``.

        A resumed run (``resumed_at``: the checkpoint's step) drops the log lines of steps done
        after that checkpoint; a new run clears the logs of an earlier one in this folder that
        ended before its first checkpoint (they describe nothing that survives).
        """
        run_dir.mkdir(parents=True, exist_ok=True)
        log = cls(run_dir)
        if resumed_at is not None:
            truncate_metrics(log.metrics_path, resumed_at)
        else:
            names = (METRICS_NAME, CHANGES_NAME, ckpt_io.BEST_NAME)
            stale = [n for n in names if (run_dir / n).exists()]
            for name in stale:
                (run_dir / name).unlink()
            if restarted:
                logger.info(f"{run_dir} has no checkpoint yet: starting it again from step 0")
            elif stale:
                logger.info(f"{run_dir}: cleared {' and '.join(stale)} of a run with no checkpoint")
        config.write(run_dir / CONFIG_NAME)
        if config.run.tensorboard:
            log._tensorboard = _tensorboard(run_dir)
        return log

    def record_changes(self, step: int, changes: dict[str, list[Any]]) -> None:
        """Settings changed on resume apply from ``step`` on; the record says when and what."""
        for key, (old, new) in changes.items():
            logger.info(f"resume at step {step}: {key} {old!r} -> {new!r}")
        with appending(self.run_dir / CHANGES_NAME) as fh:
            fh.write(json.dumps({"step": step, "time": time.time(), "changes": changes}) + "\n")

    def write(self, row: dict[str, Any], *, scalars: bool = True) -> None:
        """Append one row to ``metrics.jsonl``; with ``scalars`` its values (but its step and
        time) to TensorBoard too."""
        with appending(self.metrics_path) as fh:
            fh.write(json.dumps(row) + "\n")
        if scalars and self._tensorboard is not None:
            for key, value in row.items():
                if key not in ("step", "time"):
                    self._tensorboard.add_scalar(key, value, row["step"])

    def close(self) -> None:
        if self._tensorboard is not None:
            self._tensorboard.close()


def _tensorboard(run_dir: Path) -> Any:
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        warnings.warn("TensorBoard is not installed; logging to metrics.jsonl only", stacklevel=2)
        return None
    return SummaryWriter(str(run_dir / "tensorboard"))


def _lines(path: Path) -> Iterator[tuple[str, dict[str, Any]]]:
    """``(line, row)`` of every readable row of a JSON-lines log (a line cut by a kill, or
    otherwise damaged, is skipped): :func:`splitcam.io.read_json_lines`."""
    for _, line, row in read_json_lines(path)[0]:
        yield line, row


def metrics_rows(run_dir: Path) -> list[dict[str, Any]]:
    """The logged rows of a run's ``metrics.jsonl``, in order."""
    return [row for _, row in _lines(Path(run_dir) / METRICS_NAME)]


def changes_rows(run_dir: Path) -> list[dict[str, Any]]:
    """The entries of a run's ``changes.jsonl`` (``step``, ``time``, ``changes``), in order."""
    return [row for _, row in _lines(Path(run_dir) / CHANGES_NAME)]


def last_metrics(path: Path) -> dict[str, float]:
    """The last logged values of a run's ``metrics.jsonl`` at ``path`` (each key's latest, so
    validation included where it was logged)."""
    last: dict[str, float] = {}
    for _, row in _lines(path):
        last.update(row)
    return last


def logged_losses(path: Path, n: int) -> list[float]:
    """The last ``n`` training losses logged in a run's ``metrics.jsonl`` at ``path``."""
    losses = [float(row["loss"]) for _, row in _lines(path) if "loss" in row]
    return losses[-n:]


def truncate_metrics(path: Path, step: int) -> None:
    """Drop log lines after ``step`` (steps a killed run did after its last checkpoint)."""
    if not path.is_file():
        return
    kept = [line for line, row in _lines(path) if row.get("step", 0) <= step]
    write_text(path, "".join(k + "\n" for k in kept))


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
    for _, row in _lines(metrics_path):
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
