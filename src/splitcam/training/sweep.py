"""Sweeps: run a list of experiments (training configuration files), here or on a cluster.

An *experiment* is a ``splitcam train`` configuration file (TOML, YAML or JSON); its run folder is
``OUT/<file stem>``. :func:`run_sweep` trains every experiment that is not finished, and resumes
those that were interrupted (their folder holds a checkpoint), so the same command can be run
again after any interruption and only the missing work is done.

Executors:

- ``local``: ``jobs`` trainings at a time on this machine, each in its own process
  (``python -m splitcam train``) with ``threads // jobs`` intra-op threads, its output in
  ``OUT/<name>/sweep.log``. Ctrl-C stops every job the way Ctrl-C stops ``train`` (a checkpoint
  is saved), so the next sweep resumes them.
- ``slurm``: one array of jobs through ``submitit`` (``pip install submitit``), with partition,
  time, GPUs and CPUs per job; a job that hits its time limit has saved a checkpoint, and the
  next sweep resumes it. One training over several GPUs stays ``torchrun``.

Weights snapshots (``snapshots=DIR``, ``splitcam sweep --snapshots DIR``) carry an unfinished run
across machines whose run folders do not survive (a checkpoint with its optimiser state is too big
for a repository; a 16-bit snapshot is a sixth of it): when the sweep stops, finished or
interrupted, every unfinished run is exported to ``DIR/<name>.json`` + ``.safetensors``; an
experiment with no run folder but a snapshot starts from it with ``run.continue_schedule`` (the
schedule and budget of one straight run; only the Adam moments restart). So the same command
continues a sweep whether or not ``OUT`` is still there.

The sweep itself decides nothing about the recipe: each file is the whole configuration of its
run, so a table that compares runs compares exactly what the files say.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from ..checks import check_count
from ..io import checkpoints as ckpt_io
from .config import ConfigError, TrainConfig

__all__ = [
    "Experiment",
    "continue_from_snapshots",
    "load_experiments",
    "run_sweep",
    "save_snapshots",
    "status",
]

EXECUTORS = ("local", "slurm")


@dataclasses.dataclass
class Experiment:
    """One training of a sweep: its name (the file stem), file, resolved config and run folder."""

    name: str
    path: Path
    config: TrainConfig
    run_dir: Path


def load_experiments(
    files: Sequence[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    *,
    data: str | None = None,
    overrides: dict[str, Any] | None = None,
) -> list[Experiment]:
    """Read and validate every experiment file before anything runs.

    Args:
        files: Configuration files (duplicates by name are refused).
        out: Folder of the run folders (``out/<stem>``; the file's ``run.out`` is replaced).
        data: Training folder for every experiment (replaces ``data.train``).
        overrides: Further ``{"section.key": value}`` settings for every experiment.

    Raises:
        ConfigError: A missing or invalid file, or two files of the same name.
    """
    if not files:
        raise ConfigError("no experiment files given")
    seen: dict[str, Path] = {}
    experiments = []
    for f in files:
        path = Path(f)
        if not path.is_file():
            raise ConfigError(f"experiment file {str(path)!r} does not exist")
        if path.stem in seen:
            raise ConfigError(f"two experiments named {path.stem!r}: {seen[path.stem]} and {path}")
        seen[path.stem] = path
        run_dir = Path(out) / path.stem
        settings = {**(overrides or {}), "run.out": str(run_dir)}
        if data is not None:
            settings["data.train"] = str(data)
        config = TrainConfig.from_file(path)
        # Recorded in the run's provenance as `train --config FILE` records it, so a model
        # exported from the run can be trained again from its recipe (the job itself reads the
        # resolved copy, RUN/sweep_config.json).
        settings.setdefault("run.config_file", config.run.config_file or str(path))
        config = config.override(settings)
        if not config.data.train:
            raise ConfigError(f"{path}: no training images (data.train); give --data DIR")
        experiments.append(Experiment(path.stem, path, config, run_dir))
    return experiments


def snapshot_path(exp: Experiment, snapshots: str | os.PathLike[str]) -> Path:
    """Where the weights snapshot of ``exp`` lives in ``snapshots`` (its JSON file)."""
    return Path(snapshots) / f"{exp.name}.json"


def continue_from_snapshots(
    experiments: Sequence[Experiment],
    snapshots: str | os.PathLike[str],
    say: Callable[[str], None] = print,
) -> list[Experiment]:
    """The experiments, those with no run folder but a snapshot set to continue from it.

    An experiment that names its own ``run.init_from`` keeps it: a snapshot never replaces a
    start the experiment file chose.
    """
    out = []
    for exp in experiments:
        snap = snapshot_path(exp, snapshots)
        if status(exp) == "new" and snap.is_file() and not exp.config.run.init_from:
            settings = {"run.init_from": str(snap), "run.continue_schedule": True}
            exp = dataclasses.replace(exp, config=exp.config.override(settings))
            say(f"[{exp.name}] no run folder: continues from the snapshot {snap}")
        out.append(exp)
    return out


def save_snapshots(
    experiments: Sequence[Experiment],
    snapshots: str | os.PathLike[str],
    say: Callable[[str], None] = print,
) -> dict[str, Path]:
    """Export every unfinished run (a checkpoint short of its budget) as a float16 snapshot in
    ``snapshots``; returns ``{name: JSON path}``. A finished run's old snapshot is left where it
    is, with a line saying it can go once the model ships."""
    from .models import export_model

    written = {}
    for exp in experiments:
        state = status(exp)
        snap = snapshot_path(exp, snapshots)
        if state == "partial":
            step = int(ckpt_io.read_meta(exp.run_dir / ckpt_io.CHECKPOINT_NAME).get("step", 0))
            written[exp.name] = export_model(
                exp.run_dir,
                snap,
                name=exp.name,
                description=f"snapshot of the unfinished run {exp.name} "
                f"(step {step} of {exp.config.optim.steps})",
            )
            say(f"[{exp.name}] snapshot at step {step}: {snap}")
        elif state == "done" and snap.is_file():
            say(f"[{exp.name}] done: its snapshot {snap} can go once the model ships")
    return written


def shipped_already(
    exp: Experiment, snapshots: str | os.PathLike[str] | None = None
) -> Path | None:
    """The JSON of the shipped model of ``exp``'s name when that model already has the
    experiment's whole budget and the experiment has nothing of its own to continue (no run
    folder, no snapshot, no ``run.init_from``); else None. A sweep skips such an experiment:
    without this, naming a shipped model's file on a machine without its run folder would
    train it again from scratch."""
    from ..io import weights
    from ..recon.loading import model_names

    if status(exp) != "new" or exp.config.run.init_from or exp.name not in model_names():
        return None
    if snapshots is not None and snapshot_path(exp, snapshots).is_file():
        return None
    path = weights.MODELS_DIR / f"{exp.name}.json"
    try:
        steps = int(json.loads(path.read_text())["provenance"]["total_steps"])
    except (OSError, ValueError, KeyError, TypeError):
        return None  # a model without readable provenance is not vouched for: train
    return path if steps >= exp.config.optim.steps else None


def without_shipped(
    experiments: Sequence[Experiment],
    snapshots: str | os.PathLike[str] | None = None,
    say: Callable[[str], None] = print,
) -> list[Experiment]:
    """The experiments less those :func:`shipped_already` vouches for, each skip said."""
    out = []
    for exp in experiments:
        model = shipped_already(exp, snapshots)
        if model is None:
            out.append(exp)
        else:
            say(
                f"{exp.name}: skipped, ships with its whole budget ({model}); "
                "--retrain-shipped trains it again from scratch"
            )
    return out


def status(exp: Experiment) -> str:
    """``new`` (no checkpoint), ``partial`` (a checkpoint short of the budget) or ``done``.

    The budget is the experiment's ``optim.steps`` and, when set, ``run.time_limit``: a run is
    done when it has reached either.
    """
    path = exp.run_dir / ckpt_io.CHECKPOINT_NAME
    if not path.is_file():
        return "new"
    try:
        meta = ckpt_io.read_meta(path)
    except ckpt_io.CheckpointError:
        return "partial"  # let `train --resume` say what is wrong with it
    steps_done = int(meta.get("step", 0)) >= exp.config.optim.steps
    limit = exp.config.run.time_limit
    time_done = limit is not None and float(meta.get("train_seconds", 0.0)) >= limit * 60 - 1e-6
    return "done" if steps_done or time_done else "partial"


SWEEP_CONFIG = "sweep_config.json"
#: Exit status of a `train` stopped by SIGINT/SIGTERM after saving its checkpoint (`splitcam
#: train` returns it for an interrupted run): not a failure, the run resumes.
STOPPED = 130


def _ended(code: int) -> str:
    """How a job's exit status reads in the sweep's log."""
    if code == 0:
        return "finished"
    if code == STOPPED:
        return "stopped (checkpoint saved)"
    return f"failed ({code})"


def train_command(exp: Experiment, threads: int | None, resume: bool) -> list[str]:
    """The ``splitcam train`` command line of one experiment: its resolved configuration is
    written to ``RUN/sweep_config.json`` (the file plus the sweep's own settings)."""
    exp.run_dir.mkdir(parents=True, exist_ok=True)
    config = exp.config.write(exp.run_dir / SWEEP_CONFIG)
    cmd = [sys.executable, "-m", "splitcam", "train", "--config", str(config), "--quiet"]
    if threads:
        cmd += ["--threads", str(threads)]
    if resume:
        cmd.append("--resume")
    return cmd


def _run_local(
    todo: list[Experiment], jobs: int, threads: int | None, say: Callable[[str], None]
) -> dict[str, int]:
    """Run the experiments ``jobs`` at a time; returns ``{name: exit status}``."""
    per_job = max(1, threads // jobs) if threads else None
    pending = list(todo)
    running: dict[str, tuple[subprocess.Popen, Any, float]] = {}
    codes: dict[str, int] = {}
    try:
        while pending or running:
            while pending and len(running) < jobs:
                exp = pending.pop(0)
                resume = status(exp) == "partial"
                cmd = train_command(exp, per_job, resume)
                env = dict(os.environ)
                if per_job:
                    env["OMP_NUM_THREADS"] = str(per_job)
                log = open(exp.run_dir / "sweep.log", "a", encoding="utf-8")  # noqa: SIM115
                log.write(f"$ {' '.join(cmd)}\n")
                log.flush()
                proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
                running[exp.name] = (proc, log, time.monotonic())
                say(
                    f"[{exp.name}] {'resumed' if resume else 'started'} "
                    f"({per_job or 'default'} threads; log {exp.run_dir / 'sweep.log'})"
                )
            time.sleep(0.2)
            for name, (proc, log, began) in list(running.items()):
                if proc.poll() is None:
                    continue
                log.close()
                del running[name]
                codes[name] = proc.returncode
                minutes = (time.monotonic() - began) / 60
                say(f"[{name}] {_ended(proc.returncode)} after {minutes:.1f} min")
    except KeyboardInterrupt:
        say(
            "interrupted: stopping the jobs (each saves a checkpoint; run the sweep again to "
            "resume)"
        )
        for proc, _, _ in running.values():
            proc.send_signal(signal.SIGINT)
        for name, (proc, log, _) in running.items():
            try:
                codes[name] = proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                proc.kill()
                codes[name] = proc.wait()
            log.close()
        raise
    return codes


@contextlib.contextmanager
def _stopped_by_signals() -> Iterator[None]:
    """SIGINT and SIGTERM stop a local sweep the way Ctrl-C does (its jobs save their
    checkpoints, snapshots are written). Without this, a sweep started in the background
    (``nohup ... &``: SIGINT ignored) or ended by a scheduler or a session's end (SIGTERM)
    died at once, leaving its jobs running and no snapshots."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _train_job(config_dict: dict[str, Any], resume: bool) -> int:
    """What one cluster job runs (in-process ``train``); module level so submitit can pickle
    a reference to it."""
    from .trainer import train

    result = train(TrainConfig.from_dict(config_dict), resume=resume, progress=False)
    return result.step


def _run_slurm(
    todo: list[Experiment],
    folder: Path,
    options: dict[str, Any],
    say: Callable[[str], None],
    cluster: str | None = None,
) -> dict[str, int]:
    try:
        import submitit
    except ImportError:
        raise ConfigError(
            "--executor slurm needs submitit: pip install 'splitcam[cluster]' (or submitit)"
        ) from None
    executor = submitit.AutoExecutor(folder=str(folder), cluster=cluster)
    params = {
        "timeout_min": int(options.get("time") or 60),
        "slurm_partition": options.get("partition"),
        "gpus_per_node": options.get("gpus"),
        "cpus_per_task": options.get("cpus"),
        "slurm_array_parallelism": options.get("jobs"),
        "name": "splitcam-sweep",
    }
    executor.update_parameters(**{k: v for k, v in params.items() if v is not None})
    args = [(e.config.to_dict(), status(e) == "partial") for e in todo]
    jobs = executor.map_array(_train_job, *zip(*args, strict=True))
    for exp, job in zip(todo, jobs, strict=True):
        say(f"[{exp.name}] submitted as job {job.job_id}")
    if options.get("wait", True):
        codes = {}
        for exp, job in zip(todo, jobs, strict=True):
            try:
                job.result()
                codes[exp.name] = 0
                say(f"[{exp.name}] finished")
            except Exception as exc:  # a failed job: report it, the sweep goes on
                codes[exp.name] = 1
                say(f"[{exp.name}] failed: {str(exc).strip().splitlines()[-1]}")
        return codes
    return {}


def run_sweep(
    experiments: Sequence[Experiment],
    *,
    executor: str = "local",
    jobs: int = 1,
    threads: int | None = None,
    slurm: dict[str, Any] | None = None,
    say: Callable[[str], None] = print,
    cluster: str | None = None,
    snapshots: str | os.PathLike[str] | None = None,
) -> dict[str, str]:
    """Train every experiment that is not done; resume the interrupted ones.

    Args:
        experiments: From :func:`load_experiments`.
        executor: ``local`` or ``slurm``.
        jobs: Trainings at a time (local), or the array's parallelism (slurm).
        threads: Intra-op threads shared by the local jobs (default: all cores).
        slurm: ``partition``, ``time`` (minutes), ``gpus``, ``cpus``, ``wait`` for ``slurm``.
        say: Where progress lines go.
        cluster: submitit's cluster override (``debug`` runs the jobs in this process: tests).
        snapshots: Folder of weights snapshots: a run with no folder continues from its
            snapshot; when the sweep stops (finished, failed or interrupted), every unfinished
            run is exported there (not for a slurm sweep that does not wait).

    Returns:
        ``{name: status}`` after the sweep (``done``, ``partial``, ``new``, or ``failed``).
    """
    if executor not in EXECUTORS:
        raise ConfigError(f"unknown executor {executor!r}; use {' or '.join(EXECUTORS)}")
    try:
        check_count(jobs, "jobs", 1)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    if threads is None and executor == "local":
        threads = os.cpu_count() or 1
    if snapshots is not None:
        experiments = continue_from_snapshots(experiments, snapshots, say)
    before = {e.name: status(e) for e in experiments}
    todo = [e for e in experiments if before[e.name] != "done"]
    for e in experiments:
        if before[e.name] == "done":
            say(f"[{e.name}] done already: skipped ({e.run_dir})")
    waits = executor == "local" or (slurm or {}).get("wait", True)
    try:
        if todo and executor == "local":
            with _stopped_by_signals():
                codes = _run_local(todo, min(jobs, len(todo)), threads, say)
        elif todo:
            root = Path(todo[0].run_dir).parent / ".submitit"
            codes = _run_slurm(todo, root, {**(slurm or {}), "jobs": jobs}, say, cluster)
        else:
            codes = {}
    finally:  # interrupted too: the checkpoints the jobs saved become snapshots
        if snapshots is not None and waits:
            save_snapshots(experiments, snapshots, say)
    result = {}
    for e in experiments:
        result[e.name] = "failed" if codes.get(e.name, 0) not in (0, STOPPED) else status(e)
    return result
