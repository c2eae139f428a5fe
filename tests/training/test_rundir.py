"""The run folder (splitcam.training.rundir): its lock, resuming after a kill or Ctrl-C, settings
changed on resume, old runs."""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import subprocess
import sys
import time

import pytest
from conftest import tiny_config

from splitcam.cli import main
from splitcam.io import checkpoints as ckpt_io
from splitcam.training import CheckpointError, ConfigError, TrainConfig, train


def _spawn(image_folder, out, steps, every):
    argv = [
        sys.executable,
        "-m",
        "splitcam",
        "train",
        "--data",
        str(image_folder),
        "--val-split",
        "2",
        "--patch-size",
        "16",
        "--batch-size",
        "4",
        "--features",
        "8",
        "--blocks",
        "1",
        "--steps",
        str(steps),
        "--checkpoint-every",
        str(every),
        "--log-every",
        "1",
        "--val-every",
        "1000",
        "--threads",
        "1",
        "--out",
        str(out),
        "--quiet",
    ]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)


def _wait_for_step(out, step, proc, timeout=120.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read().decode()
        path = out / ckpt_io.CHECKPOINT_NAME
        if path.exists():
            try:
                if ckpt_io.load(path).meta["step"] >= step:
                    return
            except CheckpointError:
                pass
        time.sleep(0.05)
    raise AssertionError("training subprocess made no progress")


@pytest.mark.slow
@pytest.mark.integration
def test_sigkill_loses_only_the_steps_since_the_last_checkpoint(image_folder, tmp_path):
    out = tmp_path / "killed"
    proc = _spawn(image_folder, out, steps=100000, every=2)
    _wait_for_step(out, 4, proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    ckpt = ckpt_io.load(out)  # never damaged
    saved = ckpt.meta["step"]
    assert saved >= 4 and saved % 2 == 0
    # The kill may land mid-save: a partial *.tmp may remain, the checkpoint itself is intact.
    train(tiny_config(image_folder, out, **{"optim.steps": saved + 2}), resume=True, progress=False)
    assert not list(out.glob("*.tmp")) and not list(out.glob(".*.tmp-*"))
    steps = [json.loads(x)["step"] for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert steps == sorted(set(steps)) and steps[-1] == saved + 2  # no duplicated steps


@pytest.mark.slow
@pytest.mark.integration
def test_ctrl_c_saves_and_exits_cleanly(image_folder, tmp_path):
    out = tmp_path / "interrupted"
    proc = _spawn(image_folder, out, steps=100000, every=1000)
    deadline = time.monotonic() + 120
    while not (out / "metrics.jsonl").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr.decode()
    assert b"Traceback" not in stderr
    assert b"--resume" in stdout
    step = ckpt_io.load(out).meta["step"]
    assert (
        step >= 1
        and step == json.loads((out / "metrics.jsonl").read_text().splitlines()[-1])["step"]
    )


@pytest.mark.slow
@pytest.mark.integration
def test_a_second_run_on_the_same_folder_is_refused_and_a_killed_one_leaves_no_lock(
    image_folder, tmp_path
):
    out = tmp_path / "busy"
    proc = _spawn(image_folder, out, steps=100000, every=2)
    _wait_for_step(out, 2, proc)
    with pytest.raises(ConfigError, match="another training run is using"):
        train(tiny_config(image_folder, out), resume=True, progress=False)
    code = main(
        [
            "train",
            "--data",
            str(image_folder),
            "--out",
            str(out),
            "--resume",
            "--steps",
            "1",
            "--threads",
            "1",
            "--quiet",
        ]
    )
    assert code == 1  # a one-line error (checked by the message above), not a traceback
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    saved = ckpt_io.load(out).meta["step"]
    result = train(
        tiny_config(image_folder, out, **{"optim.steps": saved + 1}), resume=True, progress=False
    )
    assert result.step == saved + 1


def test_the_run_lock_is_an_os_lock_and_a_refusal_is_one_line(image_folder, tmp_path, capsys):
    fcntl = pytest.importorskip("fcntl")
    out = tmp_path / "held"
    out.mkdir()
    with open(out / ".lock", "a+") as holder:  # another holder of the folder's lock
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(
            ConfigError, match=f"another training run is using {re.escape(repr(str(out)))}"
        ):
            train(tiny_config(image_folder, out, **{"optim.steps": 1}), progress=False)
        capsys.readouterr()
        argv = ["train", "--data", str(image_folder), "--out", str(out), "--steps", "1"]
        tiny_flags = ["--features", "4", "--blocks", "1", "--patch-size", "16", "--batch-size", "2"]
        assert main([*argv, *tiny_flags, "--threads", "1", "--quiet"]) == 1
        err = capsys.readouterr().err
        assert err.startswith("splitcam train: error: another training run is using")
        assert err.count("\n") == 1 and "Traceback" not in err
        assert not (out / "config.json").exists()  # the refused run wrote nothing
    # Released (as the OS does when its holder dies, however it dies): the folder is free.
    assert train(tiny_config(image_folder, out, **{"optim.steps": 1}), progress=False).step == 1


def test_a_resume_that_changes_the_validation_starts_the_best_again(image_folder, tmp_path, caplog):
    """A best scored at another validation is not comparable: the first validation after a
    resume that changed it becomes the best, even when it scores less (here: noise added)."""
    caplog.set_level(logging.INFO, logger="splitcam")
    out = tmp_path / "revalidated"
    fixed = {"optim.schedule": "constant", "optim.warmup_steps": 0, "data.val_sigmas": [0.0]}
    train(tiny_config(image_folder, out, **{**fixed, "optim.steps": 3}), progress=False)
    before = json.loads((out / "best.json").read_text())
    assert before["step"] == 3
    noisy = {**fixed, "data.val_sigmas": [50.0], "optim.steps": 6}
    train(tiny_config(image_folder, out, **noisy), resume=True, progress=False)
    rows = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    val = {r["step"]: r["val_psnr"] for r in rows if "val_psnr" in r}
    assert val[6] < val[3] - 1  # sigma 50 scores below sigma 0
    after = json.loads((out / "best.json").read_text())
    assert after["step"] == 6 and after["best_val"] == pytest.approx(val[6])
    said = [r.getMessage() for r in caplog.records if r.name.startswith("splitcam.training")]
    assert any("resume changed data.val_sigmas: the best so far" in m for m in said)
    # A resume that leaves the validation as it was keeps comparing with the best.
    train(
        tiny_config(image_folder, out, **{**noisy, "optim.steps": 9}), resume=True, progress=False
    )
    assert json.loads((out / "best.json").read_text())["best_val"] >= after["best_val"]


def test_settings_changed_on_resume_apply_and_are_recorded(image_folder, tmp_path, capsys, caplog):
    caplog.set_level(logging.INFO, logger="splitcam")
    out = tmp_path / "changed"
    constant = {"optim.schedule": "constant", "optim.warmup_steps": 0}
    train(tiny_config(image_folder, out, **{**constant, "optim.steps": 2}), progress=False)
    train(
        tiny_config(image_folder, out, **{**constant, "optim.steps": 4, "optim.lr": 3e-4}),
        resume=True,
        progress=False,
    )
    said = [r.getMessage() for r in caplog.records if r.name.startswith("splitcam.training")]
    assert "resume at step 2: optim.lr 0.001 -> 0.0003" in said
    assert json.loads((out / "config.json").read_text())["optim"]["lr"] == 3e-4
    rows = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    lr = {r["step"]: r["lr"] for r in rows if "lr" in r}
    assert lr[2] == pytest.approx(1e-3) and lr[3] == pytest.approx(3e-4)
    assert lr[4] == pytest.approx(3e-4)
    ckpt = ckpt_io.load(out)
    assert ckpt.meta["optimizer"]["param_groups"][0]["lr"] == pytest.approx(3e-4)
    record = [json.loads(x) for x in (out / "changes.jsonl").read_text().splitlines()]
    assert record[-1]["step"] == 2
    assert record[-1]["changes"]["optim.lr"] == [1e-3, 3e-4]
    assert record[-1]["changes"]["optim.steps"] == [2, 4]
    with pytest.raises(CheckpointError, match="run.seed=0, got 5; this setting defines"):
        train(
            tiny_config(image_folder, out, **{**constant, "run.seed": 5}),
            resume=True,
            progress=False,
        )
    model_defining = {
        "pattern.name": "A",
        "pattern.learn": True,
        "pattern.init": "exact",
        "network.arch": "packed",
        "network.blocks": 2,
    }
    for key, value in model_defining.items():
        with pytest.raises(CheckpointError, match=f"{key}=.*this setting defines the model"):
            train(tiny_config(image_folder, out, **{key: value}), resume=True, progress=False)
    assert ckpt_io.load(out).meta["step"] == 4  # the refusals changed nothing


def test_resume_of_a_run_killed_before_its_first_checkpoint(image_folder, tmp_path, capsys, caplog):
    caplog.set_level(logging.INFO, logger="splitcam")
    out = tmp_path / "early"
    out.mkdir()
    tiny_config(image_folder, out).write(out / "config.json")
    (out / "metrics.jsonl").write_text('{"step": 0, "val_psnr": 10.0}\n')
    assert main(["train", "--out", str(out), "--resume", "--quiet"]) == 0
    assert "no checkpoint yet: starting it again from step 0" in caplog.text
    steps = [json.loads(x)["step"] for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert steps.count(0) == 1 and steps[-1] == 6
    with pytest.raises(ConfigError, match="no run to resume in .*drop --resume"):
        train(tiny_config(image_folder, tmp_path / "empty"), resume=True, progress=False)
    assert main(["train", "--out", str(tmp_path / "nothing"), "--resume", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("splitcam train: error: no run to resume in ")
    assert "drop --resume to start one there" in err
    assert not (tmp_path / "empty").exists() and not (tmp_path / "nothing").exists()
    # Started anew without --resume: no second step 0 from the earlier attempt either.
    again = tmp_path / "again"
    again.mkdir()
    (again / "metrics.jsonl").write_text('{"step": 0, "val_psnr": 10.0}\n')
    train(tiny_config(image_folder, again, **{"optim.steps": 2}), progress=False)
    steps = [json.loads(x)["step"] for x in (again / "metrics.jsonl").read_text().splitlines()]
    assert steps == [0, 1, 2]


def test_a_run_saved_before_partial_periods_existed_resumes_without_them(image_folder, tmp_path):
    from splitcam.training.rundir import resume_config

    run = tmp_path / "old"
    train(
        tiny_config(image_folder, run, **{"optim.steps": 2, "data.partial_periods": 0.0}),
        progress=False,
    )
    assert TrainConfig().data.partial_periods == 0.5  # today's default
    # Take the setting out of the checkpoint and config.json, as a run saved before it had it.
    path = run / ckpt_io.CHECKPOINT_NAME
    loaded = ckpt_io.load(path)
    del loaded.meta["config"]["data"]["partial_periods"]
    ckpt_io.save(path, loaded.meta, loaded.tensors)
    assert resume_config(run).data.partial_periods == 0.0
    (path).unlink()
    saved = json.loads((run / "config.json").read_text())
    del saved["data"]["partial_periods"]
    (run / "config.json").write_text(json.dumps(saved))
    assert resume_config(run).data.partial_periods == 0.0
