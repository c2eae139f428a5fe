"""The sweep runner (splitcam.training.sweep): skip finished experiments, resume interrupted
ones, snapshots, signals, the SLURM path."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
from conftest import (
    SWEEP_SMALL,
    experiment_file,
    small_config,
)

from splitcam.io import checkpoints as ckpt_io
from splitcam.training import ConfigError, train
from splitcam.training.config import TrainConfig
from splitcam.training.models import export_model
from splitcam.training.sweep import load_experiments, run_sweep, status, train_command


def _logged_lr(run_dir):
    rows = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return {r["step"]: r["lr"] for r in rows if "lr" in r}


@pytest.mark.slow
@pytest.mark.integration
def test_sweep_runs_skips_finished_and_resumes_interrupted(run_images, tmp_path):
    exps = tmp_path / "experiments"
    exps.mkdir()
    files = [
        experiment_file(exps, "a", **SWEEP_SMALL),
        experiment_file(
            exps,
            "b",
            **{**SWEEP_SMALL, "pattern.name": "A"},
        ),
    ]
    runs = tmp_path / "runs"
    # b was interrupted at step 2 of 4 (its own checkpoint, as a killed sweep leaves it).
    train(
        small_config(
            run_images, runs / "b", **{"pattern.name": "A", "optim.steps": 2, "run.threads": None}
        ),
        progress=False,
    )
    experiments = load_experiments(files, runs, data=str(run_images))
    assert [status(e) for e in experiments] == ["new", "partial"]
    said: list[str] = []
    result = run_sweep(experiments, jobs=2, threads=2, say=said.append)
    assert result == {"a": "done", "b": "done"}, (said, (runs / "b" / "sweep.log").read_text())
    assert any("[b] resumed" in s for s in said) and any("[a] started" in s for s in said)
    steps = [json.loads(x)["step"] for x in (runs / "b" / "metrics.jsonl").read_text().splitlines()]
    assert steps == sorted(steps) and steps[-1] == 4 and steps.count(2) <= 2  # log + val rows
    assert ckpt_io.load(runs / "b").meta["step"] == 4
    # Each run records its experiment file, as `train --config FILE` does (a recipe needs it).
    for name, file in zip("ab", files, strict=True):
        assert ckpt_io.read_meta(runs / name / "checkpoint.safetensors")["config"]["run"][
            "config_file"
        ] == str(file)
    said.clear()
    assert run_sweep(experiments, jobs=2, threads=2, say=said.append) == result
    assert all("done already" in s for s in said) and len(said) == 2


@pytest.mark.slow
@pytest.mark.integration
def test_sweep_snapshots_carry_an_unfinished_run_to_a_machine_without_its_folder(
    run_images, tmp_path, monkeypatch
):
    """--snapshots: an interrupted sweep exports its unfinished runs; with the run folder gone,
    the same sweep continues from the snapshot on the schedule of one straight run and ends at
    the whole budget, its provenance joining both segments."""
    from splitcam.training import sweep as sweep_module

    exps = tmp_path / "experiments"
    exps.mkdir()
    f = experiment_file(exps, "c", **SWEEP_SMALL)
    runs, snaps = tmp_path / "runs", tmp_path / "snapshots"
    experiments = load_experiments([f], runs, data=str(run_images))

    def interrupted(todo, jobs, threads, say):  # the sweep is stopped at step 2 of 4
        cfg = todo[0].config.override({"optim.steps": 2, "run.threads": None})
        train(cfg, progress=False)
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "_run_local", interrupted)
    said: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        run_sweep(experiments, jobs=1, threads=1, say=said.append, snapshots=snaps)
    assert any("[c] snapshot at step 2" in s for s in said), said
    snap = json.loads((snaps / "c.json").read_text())
    assert snap["provenance"]["total_steps"] == 2 and (snaps / "c.safetensors").is_file()
    monkeypatch.undo()

    # A new machine: no run folder, only the snapshot (as committed to git).
    shutil.rmtree(runs)
    experiments = load_experiments([f], runs, data=str(run_images))
    said.clear()
    result = run_sweep(experiments, jobs=1, threads=1, say=said.append, snapshots=snaps)
    assert result == {"c": "done"}, (said, (runs / "c" / "sweep.log").read_text())
    assert any("continues from the snapshot" in s for s in said)
    assert any("can go once the model ships" in s for s in said)
    assert sorted(_logged_lr(runs / "c")) == [3, 4]  # only the missing steps ran
    prov = json.loads(export_model(runs / "c", tmp_path / "whole").read_text())["provenance"]
    assert prov["total_steps"] == 4 and [s["steps"] for s in prov["segments"]] == [2, 2]
    # The run's own folder wins over the snapshot once it exists: nothing more to do.
    said.clear()
    assert run_sweep(experiments, jobs=1, threads=1, say=said.append, snapshots=snaps) == result
    assert any("done already" in s for s in said)


@pytest.mark.slow
@pytest.mark.integration
def test_a_background_sweep_ended_by_sigterm_stops_its_jobs_and_writes_snapshots(
    run_images, tmp_path
):
    """A sweep started as `nohup splitcam sweep ... &` (SIGINT ignored) and ended by SIGTERM (a
    scheduler, a session's end) stops its job, which saves a checkpoint, and exports it as a
    snapshot, instead of dying at once with its job still training."""
    exps = tmp_path / "experiments"
    exps.mkdir()
    f = experiment_file(
        exps, "long", **{**SWEEP_SMALL, "optim.steps": 100000, "run.val_every": 1000}
    )
    runs, snaps = tmp_path / "runs", tmp_path / "snapshots"
    cmd = [sys.executable, "-m", "splitcam", "sweep", str(f), "--out", str(runs), "--data"]
    cmd += [str(run_images), "--threads", "1", "--snapshots", str(snaps)]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),  # as `cmd &` does
        start_new_session=True,  # its own process group: nothing outlives the test
    )
    try:
        checkpoint = runs / "long" / "checkpoint.json"
        deadline = time.monotonic() + 120
        while not checkpoint.is_file() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        assert checkpoint.is_file(), proc.communicate()[0] if proc.poll() is not None else "slow"
        os.kill(proc.pid, signal.SIGTERM)
        out, _ = proc.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, out
    assert "[long] snapshot at step" in out, out
    step = json.loads((snaps / "long.json").read_text())["provenance"]["total_steps"]
    assert 0 < step < 100000
    assert ckpt_io.load(runs / "long").meta["step"] == step  # the job saved where it stopped
    lines = (runs / "long" / "metrics.jsonl").read_text().splitlines()
    time.sleep(1.0)  # no job is left training
    assert (runs / "long" / "metrics.jsonl").read_text().splitlines() == lines


@pytest.mark.integration
def test_a_job_stopped_by_a_signal_reads_as_partial_not_failed(run_images, tmp_path, monkeypatch):
    """A job that exits 130 (train's status when a signal stopped it after its checkpoint) is
    reported as stopped and its run as partial; any other non-zero status is a failure."""
    from splitcam.training import sweep as sweep_module

    exps = tmp_path / "experiments"
    exps.mkdir()
    f = experiment_file(exps, "s", **SWEEP_SMALL)
    runs = tmp_path / "runs"
    train(
        small_config(run_images, runs / "s", **{"optim.steps": 2, "run.threads": None}),
        progress=False,
    )
    experiments = load_experiments([f], runs, data=str(run_images))
    for code, state, said_word in ((130, "partial", "stopped"), (3, "failed", "failed (3)")):
        exits = [sys.executable, "-c", f"raise SystemExit({code})"]
        monkeypatch.setattr(sweep_module, "train_command", lambda *_, cmd=exits: cmd)
        said: list[str] = []
        assert run_sweep(experiments, jobs=1, threads=1, say=said.append) == {"s": state}
        assert any(said_word in line for line in said), said


def test_sweep_refuses_bad_input(run_images, tmp_path):
    exps = tmp_path / "e"
    exps.mkdir()
    f = experiment_file(exps, "a", **{"optim.steps": 2})
    with pytest.raises(ConfigError, match="no training images"):
        load_experiments([f], tmp_path / "runs")
    with pytest.raises(ConfigError, match="does not exist"):
        load_experiments([tmp_path / "missing.toml"], tmp_path / "runs")
    (exps / "sub").mkdir()
    g = experiment_file(exps / "sub", "a", **{"optim.steps": 2})
    with pytest.raises(ConfigError, match="two experiments named 'a'"):
        load_experiments([f, g], tmp_path / "runs", data=str(run_images))
    experiments = load_experiments([f], tmp_path / "runs", data=str(run_images))
    with pytest.raises(ConfigError, match="unknown executor"):
        run_sweep(experiments, executor="pbs")
    with pytest.raises(ConfigError, match="jobs"):
        run_sweep(experiments, jobs=0)


def test_a_sweep_job_records_its_experiment_file_not_the_resolved_copy(run_images, tmp_path):
    """The job trains from RUN/sweep_config.json; the provenance must name the experiment file
    (a run whose segment names no file cannot be trained again by `train --recipe`)."""
    own = experiment_file(tmp_path, "own", **{"optim.steps": 2, "run.config_file": "x.toml"})
    plain = experiment_file(tmp_path, "plain", **{"optim.steps": 2})
    experiments = load_experiments([plain, own], tmp_path / "runs", data=str(run_images))
    recorded = []
    for exp in experiments:
        cmd = train_command(exp, threads=1, resume=False)
        resolved = cmd[cmd.index("--config") + 1]
        assert resolved.endswith("sweep_config.json")
        recorded.append(TrainConfig.from_file(resolved).run.config_file)
    assert recorded == [str(plain), "x.toml"]  # a file naming its own keeps it, as in `train`


def test_sweep_slurm_path_through_submitit(run_images, tmp_path):
    """The cluster path, with submitit's in-process 'debug' cluster standing in for SLURM."""
    pytest.importorskip("submitit")
    exps = tmp_path / "e"
    exps.mkdir()
    f = experiment_file(exps, "s", **SWEEP_SMALL)
    experiments = load_experiments([f], tmp_path / "runs", data=str(run_images))
    said: list[str] = []
    result = run_sweep(
        experiments,
        executor="slurm",
        slurm={"time": 5, "partition": "cpu"},
        say=said.append,
        cluster="debug",
    )
    assert result == {"s": "done"}
    assert any("submitted" in s for s in said)
