"""The training loop: fixed or joint (pattern + network) optimisation, checkpoints, resume,
validation, logs, and DistributedDataParallel when started by ``torchrun``.

:func:`train` reads as the recipe it follows: open the run folder (:mod:`.rundir`), set the run
up (:mod:`.setup`), then step until the budget, the time limit or a stop request, each step
scheduling the learning rate, drawing a batch, taking a guarded optimiser step, logging and
validating, and now and then saving the checkpoint (:mod:`.state`).

Messages for the user (settings changed on resume, a divergence rolled back, where an
interrupted run was saved) go to the ``splitcam.training`` loggers: INFO for what happened,
WARNING for divergences; a program shows them by configuring those loggers.
"""

from __future__ import annotations

import contextlib
import logging
import math
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F

from ..io.locks import LOCK_NAME
from ..physics.light import decode_scene
from .config import TrainConfig
from .distributed import (
    agree,
    distributed_initialized,
    end_distributed,
    is_main_process,
    max_over_ranks,
    wrap_model,
)
from .rundir import (
    GUARD_GIVES_UP,
    METRICS_NAME,
    VALIDATION_SETTINGS,
    RunLog,
    RunStart,
    failure_of,
    last_metrics,
    lock_run,
    logged_losses,
    open_run,
    resumable,
)
from .schedule import learning_rate
from .schedule import progress as progress_of
from .setup import prepare
from .state import Run, TrainState, save_best, save_checkpoint
from .validation import validate

__all__ = ["TrainResult", "train", "training_loss"]

#: Logged losses a resumed run's divergence guard starts its window with.
GUARD_WINDOW_SEED = 20

logger = logging.getLogger(__name__)


@dataclass
class TrainResult:
    run_dir: Path
    step: int
    interrupted: bool
    last_metrics: dict[str, float]
    #: Why the run failed (diverged past the guard, or ended far below where it started), or None.
    failure: str | None = None


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
    if resume:
        resumable(run_dir)  # before the lock, so that a refused resume creates no folder
    # Under torchrun only rank 0 locks; the others wait for it in init_process_group.
    started_group = not distributed_initialized()
    created = not run_dir.exists()
    lock = lock_run(run_dir) if is_main_process() else None
    try:
        result = _train(config, run_dir, resume, progress)
        end_distributed(destroy=started_group)
        return result
    except BaseException:
        if lock is not None and created:
            _remove_if_empty(run_dir)
        raise
    finally:
        if lock is not None:
            lock.close()


def _remove_if_empty(run_dir: Path) -> None:
    """Remove a run folder that this run created and that holds nothing but its lock: a run
    that failed before it wrote anything (bad data, a refused setting) leaves nothing behind."""
    entries = [p for p in run_dir.iterdir() if p.name != LOCK_NAME]
    if not entries:
        (run_dir / LOCK_NAME).unlink(missing_ok=True)
        with contextlib.suppress(OSError):
            run_dir.rmdir()


def _train(config: TrainConfig, run_dir: Path, resume: bool, progress: bool) -> TrainResult:
    """Open the run folder, set the run up, train, save; what it came to."""
    start = open_run(config, run_dir, resume)
    run, state = prepare(config, run_dir, start.loaded, progress)
    if start.loaded is not None and _nothing_to_train(state, run):
        # The run's record (config, changes, checkpoint) stays as it is, so a changed setting
        # is never recorded for steps that did not run under it.
        return TrainResult(run_dir, state.step, False, last_metrics(run_dir / METRICS_NAME))
    _restart_best(state, run, start.changes)
    model = wrap_model(state.system, run.device, run.dist)
    log = _open_log(run, state, start)
    bar = _progress_bar(run, state) if progress and run.dist.is_main else None
    try:
        with _StopFlag() as stop:
            interrupted = _steps(state, run, model, log, bar, stop)
            failure = _failure(state, run, interrupted)
            # A failed run's state (diverged, or far below where it began) never replaces the
            # last resumable one saved while it was healthy.
            if not agree(failure is not None, run.dist):
                save_checkpoint(state, run)
    finally:
        if bar is not None:
            bar.close()
        if log is not None:
            log.close()
    return _result(state, run, interrupted, failure)


def _nothing_to_train(state: TrainState, run: Run) -> bool:
    """Whether a resumed run has already done its steps or spent its time limit (said)."""
    limit = run.config.run.time_limit
    spent = limit is not None and state.train_seconds >= 60 * limit
    if state.step < run.config.optim.steps and not spent:
        return False
    if run.dist.is_main:
        if spent:
            logger.info(
                f"{run.run_dir} has trained its time limit ({limit:g} min) and is at step "
                f"{state.step}: nothing to train; resume with a larger --time-limit (it counts "
                f"the run's whole training time) to continue"
            )
        else:
            logger.info(
                f"{run.run_dir} is already at step {state.step} ({run.config.optim.steps} "
                f"steps): nothing to train; resume with more --steps to continue"
            )
    return True


def _restart_best(state: TrainState, run: Run, changes: dict[str, list[Any]]) -> None:
    """A resume that changed what validation scores (``VALIDATION_SETTINGS``) drops the best
    score so far, measured on something else: the next validation's weights become the best."""
    changed = [key for key in VALIDATION_SETTINGS if key in changes]
    if not changed or state.best_val == float("-inf"):
        return
    state.best_val = float("-inf")
    if run.dist.is_main:
        logger.info(
            f"resume changed {', '.join(changed)}: the best so far was scored on another "
            f"validation, so best.safetensors is replaced at the next validation"
        )


def _open_log(run: Run, state: TrainState, start: RunStart) -> RunLog | None:
    """The run's logs (on the main process), with the settings a resume changed recorded."""
    if not run.dist.is_main:
        return None
    resumed_at = state.step if start.loaded is not None else None
    log = RunLog.open(run.config, run.run_dir, resumed_at=resumed_at, restarted=start.restarted)
    if start.changes:
        log.record_changes(state.step, start.changes)
    return log


def _progress_bar(run: Run, state: TrainState) -> Any:
    from tqdm import tqdm

    return tqdm(
        total=run.config.optim.steps,
        initial=state.step,
        unit="step",
        dynamic_ncols=True,
        desc=f"train {run.run_dir.name}",
    )


@dataclass
class _Window:
    """What the steps since the last logged one add up to."""

    loss: float = 0.0
    steps: int = 0
    data_time: float = 0.0
    #: The largest gradient norm.
    grad_max: float = 0.0
    #: Divergences rolled back.
    rollbacks: int = 0
    started: float = field(default_factory=time.perf_counter)

    def add(self, loss: float, grad_norm: float) -> None:
        self.loss += loss if math.isfinite(loss) else 0.0
        self.steps += 1
        self.grad_max = max(self.grad_max, grad_norm)

    def reset(self) -> None:
        self.loss, self.steps, self.data_time, self.grad_max, self.rollbacks = 0.0, 0, 0.0, 0.0, 0
        self.started = time.perf_counter()

    def row(self, state: TrainState, run: Run) -> dict[str, float]:
        """The logged values of the window ending at this step."""
        elapsed = time.perf_counter() - self.started
        mean = self.loss / self.steps
        patches = self.steps * run.config.data.batch_size * run.dist.world_size
        return {
            "step": state.step,
            "loss": mean,
            "train_psnr": 10 * math.log10(1 / max(mean, 1e-12)),
            "steps_per_s": self.steps / elapsed,
            "patches_per_s": patches / elapsed,
            "data_frac": self.data_time / elapsed,
            "lr": state.optimizer.param_groups[0]["lr"],
            "grad_norm_max": self.grad_max,
            "rollbacks": self.rollbacks,
            "lr_scale": state.guard.lr_scale,
        }


def _steps(
    state: TrainState,
    run: Run,
    model: torch.nn.Module,
    log: RunLog | None,
    bar: Any,
    stop: _StopFlag,
) -> bool:
    """Train until the budget, the time limit, a stop request or the divergence guard gives up;
    whether a request stopped it."""
    window = _Window()
    state.guard.start(state.system, state.optimizer)
    if run.checkpoint_path.is_file():  # resumed: the state on disk is the one loaded
        state.saved_step = state.step
    # A resumed run's guard compares with the losses it logged before (none for a new run).
    state.guard.seed(logged_losses(run.run_dir / METRICS_NAME, GUARD_WINDOW_SEED))
    # A resumed run whose time limit is already spent does no more steps.
    limit = run.time_limit_s
    state.timed_out = limit is not None and state.train_seconds >= limit
    if state.step == 0 and run.val_images and log is not None:
        scores = _validate(state, run)
        log.write({"step": 0, **scores, "time": time.time()}, scalars=False)
        _keep_best(state, run, scores)
    saved_at = state.train_seconds
    while state.step < run.config.optim.steps and not state.timed_out:
        if _step(state, run, model, window):
            state.gave_up = True
            return False
        if bar is not None:
            bar.update(1)
        _log(state, run, window, log, bar)
        if agree(stop.requested or state.timed_out, run.dist):
            return not state.timed_out
        if _checkpoint_due(state, run, saved_at):
            save_checkpoint(state, run)
            saved_at = state.train_seconds
    return False


def _checkpoint_due(state: TrainState, run: Run, saved_at: float) -> bool:
    """Whether to save now: every ``run.checkpoint_every`` steps, and every
    ``run.checkpoint_minutes`` of training time (the same on every rank: the time is the
    maximum over ranks). The last step saves anyway."""
    settings = run.config.run
    if state.step >= run.config.optim.steps or not state.guard.settled:
        return False
    minutes = settings.checkpoint_minutes
    due_by_time = minutes is not None and state.train_seconds - saved_at >= 60 * minutes
    return state.step % settings.checkpoint_every == 0 or due_by_time


def _step(state: TrainState, run: Run, model: torch.nn.Module, window: _Window) -> bool:
    """One training step: schedule, batch, forward and backward, the guarded update; whether
    the divergence guard gave up."""
    t0 = time.perf_counter()
    _schedule(state, run)
    batch = _next_batch(state, run)
    window.data_time += time.perf_counter() - t0
    loss, grad_norm = _forward_backward(state, run, model, batch)
    if agree(state.guard.diverged(loss), run.dist):
        _roll_back(state, run, loss, window)
        if state.guard.lr_scale <= 0.5**GUARD_GIVES_UP:
            state.step += 1
            return True
    else:
        state.optimizer.step()
        state.guard.applied(loss, state.system, state.optimizer)
        if state.ema is not None:
            state.ema.update()
    state.step += 1
    _count_time(state, run, t0)
    window.add(loss, grad_norm)
    return False


def _schedule(state: TrainState, run: Run) -> None:
    """Set each parameter group's learning rate for this step (its peak scaled by the guard)."""
    optim = run.config.optim
    progress = progress_of(state.step, optim.steps, state.train_seconds, run.time_limit_s)
    for group in state.optimizer.param_groups:
        group["lr"] = learning_rate(
            optim.schedule,
            group["peak_lr"] * state.guard.lr_scale,
            state.step - state.start_step,  # fresh Adam moments warm up again
            optim.warmup_steps,
            progress,
        )


def _next_batch(state: TrainState, run: Run) -> torch.Tensor:
    """This rank's next batch of patches as the light the sensor sees (and, in a run over many
    patterns, this step's pattern): the patches' sRGB values, or in the linear domain their
    radiance (model.md §13), which is then also the target of the loss."""
    batch = state.sampler.sample(run.config.data.batch_size).to(run.device, non_blocking=True)
    batch = decode_scene(batch, run.config.data.domain)
    state.last_batch = batch
    if run.mix is not None:
        state.system.sensor.set_pattern(run.mix.pattern(state.step))
    return batch


def _forward_backward(
    state: TrainState, run: Run, model: torch.nn.Module, batch: torch.Tensor
) -> tuple[float, float]:
    """``(loss, gradient norm)`` of a batch, its gradients computed (and clipped).

    The loss compares the estimate with the batch in the run's domain: in the linear domain,
    radiance with radiance (docs/results/exposure/linear-training.md compares this with a loss
    on both encoded to sRGB)."""
    autocast: Any = (
        torch.autocast(run.device.type, dtype=torch.bfloat16)
        if run.fast
        else contextlib.nullcontext()
    )
    with autocast:
        pred = model(batch, state.noise)
    pred = pred.float()
    loss = F.mse_loss(pred, batch)
    objective = training_loss(run.config.optim.loss, pred, batch, mse=loss)
    if state.teachers is not None:
        teacher = state.teachers.estimate(run.mix.pattern(state.step) if run.mix else None)
        if teacher is not None:
            weight = run.config.optim.teacher_weight
            objective = objective + weight * training_loss(run.config.optim.loss, pred, teacher)
    state.optimizer.zero_grad(set_to_none=True)
    objective.backward()
    trainable = [p for group in state.optimizer.param_groups for p in group["params"]]
    clip = run.config.optim.clip_grad or math.inf
    value = loss.item()
    return value, float(torch.nn.utils.clip_grad_norm_(trainable, clip, foreach=True))


#: Charbonnier's epsilon: below an error of 1e-3 (a quarter of an 8-bit level) it is quadratic.
CHARBONNIER_EPS = 1e-3


def training_loss(
    name: str, pred: torch.Tensor, target: torch.Tensor, *, mse: torch.Tensor | None = None
) -> torch.Tensor:
    """The objective ``optim.loss`` names (:data:`~splitcam.training.config.LOSSES`).

    Whatever the objective, the logged loss, the training PSNR and the divergence guard use
    the batch's MSE, so runs with different objectives read on one scale.

    >>> import torch
    >>> p, t = torch.zeros(1, 3, 2, 2), torch.full((1, 3, 2, 2), 0.5)
    >>> tuple(round(training_loss(n, p, t).item(), 4) for n in ("mse", "l1", "charbonnier"))
    (0.25, 0.5, 0.5)
    """
    if name in ("mse", "log_mse"):
        mse = F.mse_loss(pred, target) if mse is None else mse
        return mse.clamp_min(1e-12).log() if name == "log_mse" else mse
    if name == "l1":
        return F.l1_loss(pred, target)
    if name == "charbonnier":
        return ((pred - target).square() + CHARBONNIER_EPS**2).sqrt().mean()
    raise ValueError(f"unknown training loss {name!r}")


def _roll_back(state: TrainState, run: Run, loss: float, window: _Window) -> None:
    """A diverged step is not applied: back to weights from before the instability, at a lower
    learning rate."""
    state.guard.roll_back(state.system, state.optimizer)
    if state.ema is not None:
        state.ema.reset()
    window.rollbacks += 1
    if run.dist.is_main:
        logger.warning(
            f"step {state.step + 1}: loss {loss:.3g} diverged; rolled back and scaled the "
            f"learning rate by {state.guard.lr_scale:g}"
        )


def _count_time(state: TrainState, run: Run, t0: float) -> None:
    """Add the step's time to the run's, and note when the time limit is reached."""
    state.train_seconds += time.perf_counter() - t0
    # Every rank must use the same learning rate, which depends on the time.
    state.train_seconds = max_over_ranks(state.train_seconds, run.dist)
    limit = run.time_limit_s
    if limit is not None and state.train_seconds >= limit:
        state.timed_out = True


def _log(state: TrainState, run: Run, window: _Window, log: RunLog | None, bar: Any) -> None:
    """Log the window every ``run.log_every`` steps and validate every ``run.val_every`` (both
    at the last step); the row goes to the logs and the progress bar."""
    config = run.config
    final = state.step == config.optim.steps or state.timed_out
    log_now = state.step % config.run.log_every == 0 or final
    val_now = bool(run.val_images) and (state.step % config.run.val_every == 0 or final)
    if log is not None:
        if log_now:
            state.last_metrics = window.row(state, run)
        if val_now:
            t_val = time.perf_counter()
            scores = _validate(state, run)
            state.last_metrics.update(scores)
            _keep_best(state, run, scores)
            state.last_metrics["step"] = state.step
            window.started += time.perf_counter() - t_val  # keep steps/s about training only
        if log_now or val_now:
            state.last_metrics["time"] = time.time()
            log.write(state.last_metrics)
            _show(bar, state.last_metrics)
    if log_now:
        window.reset()


def _validate(state: TrainState, run: Run) -> dict[str, float]:
    """The validation scores, of the averaged weights when the run keeps an average."""
    averaged = state.ema.applied() if state.ema is not None else contextlib.nullcontext()
    with averaged:
        return validate(
            state.system,
            run.val_images,
            run.val_levels,
            run.val_patterns,
            domain=run.config.data.domain,
            precision="bf16" if run.fast else "fp32",
        )


def _keep_best(state: TrainState, run: Run, scores: dict[str, float]) -> None:
    """Save the weights as the run's best when this validation beats every earlier one."""
    val = scores.get("val_psnr")
    if val is not None and math.isfinite(val) and val > state.best_val:
        save_best(state, run, val)


def _show(bar: Any, row: dict[str, float]) -> None:
    """The latest values beside the progress bar."""
    if bar is None:
        return
    shown = {"loss": ("loss", ".2e"), "psnr": ("train_psnr", ".2f"), "val": ("val_psnr", ".2f")}
    post = {name: format(row[key], spec) for name, (key, spec) in shown.items() if key in row}
    bar.set_postfix(post, refresh=False)


def _failure(state: TrainState, run: Run, interrupted: bool) -> str | None:
    """Why a run that ran to its end failed (:func:`~splitcam.training.rundir.failure_of`, or
    the guard gave up), and which resumable state is kept; None for a run that did not fail or
    was interrupted (and on ranks other than the main one)."""
    if interrupted or not run.dist.is_main:
        return None
    if state.gave_up:
        failure = (
            f"the loss diverged at step {state.step} and kept diverging after the guard halved "
            f"the learning rate {GUARD_GIVES_UP} times"
        )
    else:
        failure = failure_of(run.run_dir / METRICS_NAME, state.last_metrics, state.guard.lr_scale)
    if failure is None:
        return None
    kept = (
        f"the resumable checkpoint of step {state.saved_step} is kept (nothing of the failed "
        "steps after it was saved): --resume with a lower --lr continues from it"
        if state.saved_step is not None
        else "no checkpoint had been saved: start again with a lower --lr"
    )
    return f"{failure}; {kept}"


def _result(state: TrainState, run: Run, interrupted: bool, failure: str | None) -> TrainResult:
    """What the run came to: where it stopped, and why it failed (:func:`_failure`)."""
    if run.dist.is_main:
        if state.timed_out and failure is None:
            logger.info(
                f"time limit reached ({run.config.run.time_limit:g} min of training): saved step "
                f"{state.step} to {run.checkpoint_path}; to train further, --resume with a "
                f"larger --time-limit (it counts the run's whole training time)"
            )
        elif interrupted:
            logger.info(
                f"interrupted: saved step {state.step} to {run.checkpoint_path}; continue with "
                f"--resume"
            )
    return TrainResult(run.run_dir, state.step, interrupted, state.last_metrics, failure)


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
