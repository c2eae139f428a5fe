"""Training: learning happens, checkpoints resume exactly, damage and kills are survived."""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
from conftest import blocky_images, tiny_config
from PIL import Image

from splitcam import patterns
from splitcam.cli import main
from splitcam.evaluation.protocol import mean_psnr
from splitcam.io import checkpoints as ckpt_io
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.training import CheckpointError, ConfigError, TrainConfig, load_system, train
from splitcam.training.trainer import _val_images


@pytest.fixture(scope="module")
def image_folder(tmp_path_factory):
    """Eight smooth random colour images (learnable in a few steps)."""
    return blocky_images(tmp_path_factory.mktemp("images"), 8)


def tiny(folder, out, **changes) -> TrainConfig:
    return tiny_config(folder, out, **changes)


def losses(run) -> list[float]:
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    return [r["loss"] for r in rows if "loss" in r]


@pytest.mark.parametrize("arch", ["packed", "physics"])
def test_a_few_steps_lower_the_loss(image_folder, tmp_path, arch):
    config = tiny(image_folder, tmp_path / "r", **{"optim.steps": 40, "network.arch": arch})
    result = train(config, progress=False)
    values = losses(tmp_path / "r")
    assert len(values) == 40 and result.step == 40
    if arch == "packed":  # from scratch, the blind network halves its loss
        assert np.mean(values[-5:]) < 0.5 * np.mean(values[:5])
    rows = [json.loads(line) for line in (tmp_path / "r/metrics.jsonl").read_text().splitlines()]
    val = [r for r in rows if "val_psnr" in r]
    assert val[0]["step"] == 0 and val[-1]["step"] == 40
    assert val[-1]["val_psnr"] > val[0]["val_psnr"] + 0.5
    if arch == "physics":  # it starts at the LMMSE estimate: its correction is zero
        lmmse = mean_psnr(closed_form_lmmse("D"), _val_images(config), config.data.val_sigmas)
        assert val[0]["val_psnr"] == pytest.approx(np.mean(list(lmmse.values())), abs=1e-3)
    assert json.loads((tmp_path / "r/config.json").read_text())["optim"]["steps"] == 40


def test_resume_equals_the_uninterrupted_run(image_folder, tmp_path):
    # A constant learning rate, so that stopping at 3 steps first changes nothing else.
    constant = {"optim.schedule": "constant"}
    train(tiny(image_folder, tmp_path / "full", **constant), progress=False)
    train(tiny(image_folder, tmp_path / "split", **{**constant, "optim.steps": 3}), progress=False)
    train(tiny(image_folder, tmp_path / "split", **constant), resume=True, progress=False)
    assert losses(tmp_path / "split") == losses(tmp_path / "full")
    a = ckpt_io.load(tmp_path / "full").tensors
    b = ckpt_io.load(tmp_path / "split").tensors
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


def test_partial_period_batches_train_and_resume_exactly(image_folder, tmp_path, monkeypatch):
    """Batches cut part-way through a period reach the loss at their cut size (a learned
    pattern and the physics network included), and the cuts come from the checkpointed
    generator: a resumed run repeats the uninterrupted one."""
    shapes = []
    original = torch.nn.functional.mse_loss

    def spy(pred, target, *args, **kwargs):
        shapes.append(tuple(target.shape[-2:]))
        return original(pred, target, *args, **kwargs)

    monkeypatch.setattr("splitcam.training.trainer.F.mse_loss", spy)
    changes = {
        "optim.schedule": "constant",
        "data.partial_periods": 0.5,
        "pattern.learn": True,
        "network.arch": "physics",
    }
    train(tiny(image_folder, tmp_path / "full", **changes), progress=False)
    size = tiny(image_folder, tmp_path / "x").data.patch_size
    assert set(shapes) <= {(size - a, size - b) for a in (0, 1) for b in (0, 1)}
    assert len(set(shapes)) >= 2
    train(tiny(image_folder, tmp_path / "split", **{**changes, "optim.steps": 3}), progress=False)
    train(tiny(image_folder, tmp_path / "split", **changes), resume=True, progress=False)
    assert losses(tmp_path / "split") == losses(tmp_path / "full")


def test_schedule_survives_a_resume(image_folder, tmp_path):
    """The learning rate is a function of the step and the run's length: a run stopped early
    and resumed uses, after the resume, the learning rates of the uninterrupted run."""

    def lrs(run):
        rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
        return {r["step"]: r["lr"] for r in rows if "lr" in r}

    cosine = {"optim.schedule": "cosine", "optim.warmup_steps": 2, "optim.steps": 8}
    train(tiny(image_folder, tmp_path / "full", **cosine), progress=False)
    train(tiny(image_folder, tmp_path / "split", **{**cosine, "optim.steps": 4}), progress=False)
    train(tiny(image_folder, tmp_path / "split", **cosine), resume=True, progress=False)
    full, split = lrs(tmp_path / "full"), lrs(tmp_path / "split")
    peak = 1e-3
    # Logged after step s: the rate used for step s (0-based s - 1).
    expected = {
        s: peak * min(1.0, s / 2) * 0.5 * (1 + np.cos(np.pi * (s - 1) / 8)) for s in range(1, 9)
    }
    assert full == pytest.approx(expected, rel=1e-9)
    assert {s: split[s] for s in range(5, 9)} == pytest.approx(
        {s: expected[s] for s in range(5, 9)}, rel=1e-9
    )


def test_joint_training_changes_the_pattern_and_keeps_it_valid(image_folder, tmp_path):
    cfg = tiny(image_folder, tmp_path / "joint", **{"pattern.learn": True, "pattern.lr": 0.05})
    train(cfg, progress=False)
    learned = patterns.load(tmp_path / "joint/pattern.toml")
    start = patterns.get("D")
    assert not learned.equals(start, atol=1e-3)
    assert np.all(learned.kernels >= 0)
    np.testing.assert_allclose(learned.kernels.sum(axis=(2, 3)), 1.0, atol=1e-6)
    ckpt = ckpt_io.load(tmp_path / "joint")
    assert patterns.Pattern.from_dict(ckpt.meta["pattern"]).equals(learned, atol=1e-9)
    # The learned pattern is what a loaded system senses with.
    system = load_system(tmp_path / "joint")
    np.testing.assert_allclose(system.sensor.kernels.numpy(), learned.kernels, atol=1e-9)

    train(tiny(image_folder, tmp_path / "fixed"), progress=False)
    fixed = patterns.Pattern.from_dict(ckpt_io.load(tmp_path / "fixed").meta["pattern"])
    assert fixed.equals(start)


def test_damaged_and_foreign_checkpoints_are_refused(image_folder, tmp_path):
    train(tiny(image_folder, tmp_path / "r", **{"optim.steps": 2}), progress=False)
    path = tmp_path / "r" / ckpt_io.CHECKPOINT_NAME
    data = path.read_bytes()
    # The header alone gives the same meta as the whole file (what sweep status reads).
    assert ckpt_io.read_meta(path) == ckpt_io.load(path).meta
    assert ckpt_io.read_meta(path)["step"] == 2
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="damaged"):
        ckpt_io.load(path)
    with pytest.raises(CheckpointError, match="damaged"):
        train(tiny(image_folder, tmp_path / "r"), resume=True, progress=False)
    path.write_bytes(b"\x00" * 64)
    with pytest.raises(CheckpointError, match="damaged"):
        ckpt_io.read_meta(path)
    with pytest.raises(CheckpointError, match="damaged"):
        load_system(tmp_path / "r")
    path.write_bytes(data)
    with pytest.raises(CheckpointError, match="network.features=8, got 16"):
        train(
            tiny(image_folder, tmp_path / "r", **{"network.features": 16}),
            resume=True,
            progress=False,
        )
    ckpt = ckpt_io.load(path)
    bigger = torch.nn.Conv2d(1, 1, 3)
    with pytest.raises(CheckpointError, match="another architecture"):
        ckpt_io.load_module(bigger, ckpt)
    with pytest.raises(CheckpointError, match="no checkpoint"):
        ckpt_io.load(tmp_path / "nothing")
    with pytest.raises(ConfigError, match="already holds a checkpoint"):
        train(tiny(image_folder, tmp_path / "r"), progress=False)


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
    train(tiny(image_folder, out, **{"optim.steps": saved + 2}), resume=True, progress=False)
    assert not list(out.glob("*.tmp")) and not list(out.glob(".*.tmp-*"))
    steps = [json.loads(x)["step"] for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert steps == sorted(set(steps)) and steps[-1] == saved + 2  # no duplicated steps


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


def test_config_files_and_overrides(tmp_path, image_folder):
    toml = tmp_path / "c.toml"
    toml.write_text('[pattern]\nname = "A"\nlearn = true\n[optim]\nlr = 2e-4\n')
    cfg = TrainConfig.from_file(toml)
    assert cfg.pattern.name == "A" and cfg.pattern.learn and cfg.optim.lr == 2e-4
    assert cfg.data.batch_size == 8 and cfg.optim.sigma_max == 30  # defaults kept
    yaml_file = tmp_path / "c.yaml"
    yaml_file.write_text("network:\n  features: 32\n")
    assert TrainConfig.from_file(yaml_file).network.features == 32
    bad = [
        ('[pattern]\nnmae = "A"\n', "unknown setting.*'nmae'.*valid: design_steps, init, learn"),
        ("[optim]\nsteps = 1.5\n", "optim.steps: expected an integer, got 1.5"),
        ('[pattern]\nlearn = "False"\n', "pattern.learn: expected true or false"),
        ("[nope]\nx = 1\n", "unknown setting"),
        ("[optim\n", "not valid"),
    ]
    for text, message in bad:
        toml.write_text(text)
        with pytest.raises(ConfigError, match=message):
            TrainConfig.from_file(toml)
    with pytest.raises(ConfigError, match="pattern.init must be support, exact or random"):
        TrainConfig().override({"pattern.init": "zeros"}).validate()
    with pytest.raises(ConfigError, match="no training data"):
        train(TrainConfig().override({"run.out": str(tmp_path / "x")}), progress=False)


def test_cli_train_plot_reconstruct(image_folder, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        f'[data]\ntrain = "{image_folder}"\nval_split = 2\npatch_size = 16\n'
        "batch_size = 4\nval_crop = 32\n[network]\nfeatures = 8\nblocks = 1\n"
        "[run]\nthreads = 1\nval_every = 2\n"
    )
    out = tmp_path / "run"
    assert (
        main(
            [
                "train",
                "--config",
                str(cfg),
                "--steps",
                "4",
                "--out",
                str(out),
                "--quiet",
                "--lr",
                "1e-3",
            ]
        )
        == 0
    )
    saved = json.loads((out / "config.json").read_text())
    assert saved["optim"]["lr"] == 1e-3 and saved["data"]["batch_size"] == 4
    assert main(["train", "--out", str(out), "--resume", "--steps", "6", "--quiet"]) == 0
    assert ckpt_io.load(out).meta["step"] == 6
    assert main(["plot", str(out)]) == 0
    assert (out / "curves.png").stat().st_size > 1000
    assert main(["plot", str(out), str(out), "--out", str(tmp_path / "both.png")]) == 0
    assert (tmp_path / "both.png").stat().st_size > 1000
    photo = image_folder / "im0.png"
    rec = tmp_path / "rec.png"
    assert (
        main(
            [
                "reconstruct",
                "--checkpoint",
                str(out),
                "--image",
                str(photo),
                "--sigma",
                "5",
                "--out",
                str(rec),
                "--quiet",
            ]
        )
        == 0
    )
    with Image.open(rec) as im:
        assert im.size == (48, 48) and im.mode == "RGB"
    raw = tmp_path / "raw.npy"
    assert main(["simulate", str(photo), "--pattern", "D", "--out", str(raw)]) == 0
    assert (
        main(
            [
                "reconstruct",
                "--checkpoint",
                str(out),
                "--raw",
                str(raw),
                "--out",
                str(tmp_path / "rec2.png"),
                "--quiet",
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert (
        main(
            [
                "reconstruct",
                "--checkpoint",
                str(tmp_path / "none"),
                "--raw",
                str(raw),
                "--out",
                str(rec),
            ]
        )
        == 1
    )
    assert "no checkpoint" in capsys.readouterr().err
    assert main(["train", "--out", str(tmp_path / "new"), "--quiet"]) == 1
    assert "no training data" in capsys.readouterr().err


@pytest.mark.slow
def test_compiled_training_keeps_the_checkpoint_format(image_folder, tmp_path):
    train(
        tiny(image_folder, tmp_path / "c", **{"run.compile": True, "optim.steps": 2}),
        progress=False,
    )
    train(tiny(image_folder, tmp_path / "e", **{"optim.steps": 2}), progress=False)
    compiled = ckpt_io.load(tmp_path / "c").section("model")
    eager = ckpt_io.load(tmp_path / "e").section("model")
    assert compiled.keys() == eager.keys()
    for key in eager:
        torch.testing.assert_close(compiled[key], eager[key], rtol=1e-4, atol=1e-5)


# --- defects found by trying it as a new user (issue 8) ------------------------------------------


def test_a_second_run_on_the_same_folder_is_refused_and_a_killed_one_leaves_no_lock(
    image_folder, tmp_path
):
    out = tmp_path / "busy"
    proc = _spawn(image_folder, out, steps=100000, every=2)
    _wait_for_step(out, 2, proc)
    with pytest.raises(ConfigError, match="another training run is using"):
        train(tiny(image_folder, out), resume=True, progress=False)
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
        tiny(image_folder, out, **{"optim.steps": saved + 1}), resume=True, progress=False
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
            train(tiny(image_folder, out, **{"optim.steps": 1}), progress=False)
        capsys.readouterr()
        argv = ["train", "--data", str(image_folder), "--out", str(out), "--steps", "1"]
        tiny_flags = ["--features", "4", "--blocks", "1", "--patch-size", "16", "--batch-size", "2"]
        assert main([*argv, *tiny_flags, "--threads", "1", "--quiet"]) == 1
        err = capsys.readouterr().err
        assert err.startswith("splitcam train: error: another training run is using")
        assert err.count("\n") == 1 and "Traceback" not in err
        assert not (out / "config.json").exists()  # the refused run wrote nothing
    # Released (as the OS does when its holder dies, however it dies): the folder is free.
    assert train(tiny(image_folder, out, **{"optim.steps": 1}), progress=False).step == 1


def test_settings_changed_on_resume_apply_and_are_recorded(image_folder, tmp_path, capsys, caplog):
    caplog.set_level(logging.INFO, logger="splitcam")
    out = tmp_path / "changed"
    constant = {"optim.schedule": "constant", "optim.warmup_steps": 0}
    train(tiny(image_folder, out, **{**constant, "optim.steps": 2}), progress=False)
    train(
        tiny(image_folder, out, **{**constant, "optim.steps": 4, "optim.lr": 3e-4}),
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
        train(tiny(image_folder, out, **{**constant, "run.seed": 5}), resume=True, progress=False)
    model_defining = {
        "pattern.name": "A",
        "pattern.learn": True,
        "pattern.init": "exact",
        "network.arch": "packed",
        "network.blocks": 2,
    }
    for key, value in model_defining.items():
        with pytest.raises(CheckpointError, match=f"{key}=.*this setting defines the model"):
            train(tiny(image_folder, out, **{key: value}), resume=True, progress=False)
    assert ckpt_io.load(out).meta["step"] == 4  # the refusals changed nothing


def test_resume_of_a_run_killed_before_its_first_checkpoint(image_folder, tmp_path, capsys, caplog):
    caplog.set_level(logging.INFO, logger="splitcam")
    out = tmp_path / "early"
    out.mkdir()
    tiny(image_folder, out).write(out / "config.json")
    (out / "metrics.jsonl").write_text('{"step": 0, "val_psnr": 10.0}\n')
    assert main(["train", "--out", str(out), "--resume", "--quiet"]) == 0
    assert "no checkpoint yet: starting it again from step 0" in caplog.text
    steps = [json.loads(x)["step"] for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert steps.count(0) == 1 and steps[-1] == 6
    with pytest.raises(ConfigError, match="no run to resume in .*drop --resume"):
        train(tiny(image_folder, tmp_path / "empty"), resume=True, progress=False)
    assert main(["train", "--out", str(tmp_path / "nothing"), "--resume", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("splitcam train: error: no run to resume in ")
    assert "drop --resume to start one there" in err
    assert not (tmp_path / "empty").exists() and not (tmp_path / "nothing").exists()
    # Started anew without --resume: no second step 0 from the earlier attempt either.
    again = tmp_path / "again"
    again.mkdir()
    (again / "metrics.jsonl").write_text('{"step": 0, "val_psnr": 10.0}\n')
    train(tiny(image_folder, again, **{"optim.steps": 2}), progress=False)
    steps = [json.loads(x)["step"] for x in (again / "metrics.jsonl").read_text().splitlines()]
    assert steps == [0, 1, 2]


def test_validation_is_on_by_default_on_a_held_out_split(image_folder, tmp_path):
    from splitcam.training.trainer import _train_source, val_split

    config = tiny(image_folder, tmp_path / "v", **{"data.val_split": None})
    assert val_split(config) == 1  # 8 images: max(1, 8 // 10)
    held_out = {p.name for p in _train_source(config)}
    assert "im7.png" not in held_out and len(held_out) == 7
    train(config, progress=False)
    rows = [json.loads(x) for x in (tmp_path / "v/metrics.jsonl").read_text().splitlines()]
    assert any("val_psnr" in r for r in rows)
    assert val_split(tiny(image_folder, tmp_path / "w", **{"data.val_split": 0})) == 0


def test_every_setting_has_a_flag_with_its_default_in_the_help():
    import argparse
    import dataclasses

    from splitcam.cli import build_parser
    from splitcam.training.config import TrainConfig as Config
    from splitcam.training.config import train_flags

    flags = {f.key: f for f in train_flags()}
    keys = {
        f"{s.name}.{f.name}"
        for s in dataclasses.fields(Config)
        for f in dataclasses.fields(getattr(Config(), s.name))
    }
    assert set(flags) == keys  # none left out
    # The flags `splitcam train` has, each showing the dataclass's default in its help.
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    options = {o: a for a in sub.choices["train"]._actions for o in a.option_strings}
    defaults = Config()
    for key, flag in flags.items():
        section, name = key.split(".")
        action = options["--" + flag.name.replace("_", "-")]
        assert action.dest == flag.name and action.help == flag.help
        default = getattr(getattr(defaults, section), name)
        if isinstance(default, bool):
            assert action.help.endswith(f"(default: {'on' if default else 'off'})"), key
        elif isinstance(default, list):
            assert action.help.endswith(f"(default: {' '.join(map(str, default))})"), key
        elif default is not None:
            assert action.help.endswith(f"(default: {default})"), key
        assert action.default is None  # "not given": the config file's value stays
    assert flags["optim.lr"].help.endswith("(default: 0.001)")
    # The flag names of the hand-written table this replaced keep their meaning.
    old = {
        "pattern": "pattern.name", "learn_pattern": "pattern.learn", "init": "pattern.init",
        "pattern_lr": "pattern.lr", "data": "data.train", "val": "data.val",
        "val_split": "data.val_split", "val_images": "data.val_max_images",
        "val_sigmas": "data.val_sigmas", "patch_size": "data.patch_size",
        "batch_size": "data.batch_size", "arch": "network.arch", "features": "network.features",
        "blocks": "network.blocks", "steps": "optim.steps", "lr": "optim.lr",
        "schedule": "optim.schedule", "warmup_steps": "optim.warmup_steps",
        "per_sample_sigma": "optim.per_sample_sigma", "out": "run.out", "device": "run.device",
        "seed": "run.seed", "log_every": "run.log_every", "val_every": "run.val_every",
        "checkpoint_every": "run.checkpoint_every", "threads": "run.threads",
        "time_limit": "run.time_limit", "precision": "run.precision",
        "tensorboard": "run.tensorboard", "channels_last": "run.channels_last",
        "bf16": "run.bf16", "compile": "run.compile",
    }  # fmt: skip
    assert {f.name: f.key for f in flags.values() if f.name in old} == old
    args = parser.parse_args(
        ["train", "--lr", "0.002", "--betas", "0.8", "0.9", "--learn-pattern", "--val-split", "3"]
    )
    assert args.lr == 0.002 and args.betas == [0.8, 0.9] and args.learn_pattern is True
    assert args.val_split == 3 and args.tensorboard is None
    assert parser.parse_args(["train", "--no-learn-pattern"]).learn_pattern is False


def test_checkpoint_headers_without_network_and_nan_weights_are_named(image_folder, tmp_path):
    from safetensors.torch import save_file

    train(tiny(image_folder, tmp_path / "r", **{"optim.steps": 1}), progress=False)
    ckpt = ckpt_io.load(tmp_path / "r")
    header = {k: v for k, v in ckpt.meta.items() if k != "network"}
    bad = tmp_path / "no_network.safetensors"
    save_file(ckpt.tensors, str(bad), metadata={"splitcam": json.dumps(header)})
    with pytest.raises(CheckpointError, match="no_network.safetensors.*no 'network'"):
        load_system(bad)
    header = {k: v for k, v in ckpt.meta.items() if k != "pattern"}
    save_file(ckpt.tensors, str(bad), metadata={"splitcam": json.dumps(header)})
    with pytest.raises(CheckpointError, match="no_network.safetensors.*no 'pattern'"):
        load_system(bad)
    # Resuming needs more of the header: each missing key is named, with the file.
    for missing in ("config", "step", "optimizer"):
        run = tmp_path / f"lacks_{missing}"
        run.mkdir()
        header = {k: v for k, v in ckpt.meta.items() if k != missing}
        save_file(
            ckpt.tensors,
            str(run / ckpt_io.CHECKPOINT_NAME),
            metadata={"splitcam": json.dumps(header)},
        )
        with pytest.raises(CheckpointError, match=f"lacks_{missing}.*no '{missing}' in its header"):
            train(tiny(image_folder, run, **{"optim.steps": 2}), resume=True, progress=False)
    assert main(["train", "--out", str(tmp_path / "lacks_config"), "--resume", "--quiet"]) == 1
    tensors = dict(ckpt.tensors)
    key = next(k for k in tensors if k.startswith("model/network") and k.endswith("weight"))
    tensors[key] = tensors[key].clone()
    tensors[key].view(-1)[0] = float("nan")
    nan = tmp_path / "nan.safetensors"
    save_file(tensors, str(nan), metadata={"splitcam": json.dumps(ckpt.meta)})
    with pytest.raises(CheckpointError, match=f"nan.safetensors.*NaN.*{key}"):
        load_system(nan)


def test_joint_run_with_design_steps_starts_from_the_designed_kernels(
    image_folder, tmp_path, monkeypatch
):
    """pattern.design_steps: the learned kernels start where `design` takes the initialisation
    (lower closed-form error than the support start), and a resume keeps the trained kernels
    instead of designing again."""
    from splitcam.design import design_pattern
    from splitcam.recon.closed_form import closed_form_mse
    from splitcam.training import setup
    from splitcam.training.trainer import build_system

    learn = {"pattern.learn": True, "pattern.design_steps": 30, "optim.steps": 3}
    config = tiny(image_folder, tmp_path / "j", **learn)
    expected = design_pattern("D", init="support", steps=30, seed=config.run.seed + 17)
    start = build_system(config).sensor.pixel_kernels().detach()
    support = (
        build_system(tiny(image_folder, tmp_path / "s", **{**learn, "pattern.design_steps": 0}))
        .sensor.pixel_kernels()
        .detach()
    )
    torch.testing.assert_close(
        start.double(), patterns_kernels(expected.pattern), atol=1e-6, rtol=0
    )
    assert float(closed_form_mse(start, 10.0)) < 0.95 * float(closed_form_mse(support, 10.0))
    train(config, progress=False)

    def no_design(*args, **kwargs):
        raise AssertionError("a resumed run must not design its kernels again")

    monkeypatch.setattr(setup, "design_pattern", no_design)
    train(
        tiny(image_folder, tmp_path / "j", **{**learn, "optim.steps": 4}),
        resume=True,
        progress=False,
    )
    assert ckpt_io.load(tmp_path / "j").meta["step"] == 4
    with pytest.raises(CheckpointError, match="design_steps"):
        train(
            tiny(
                image_folder,
                tmp_path / "j",
                **{**learn, "pattern.design_steps": 5, "optim.steps": 5},
            ),
            resume=True,
            progress=False,
        )


def patterns_kernels(pattern: patterns.Pattern) -> torch.Tensor:
    from splitcam.physics.sensor import pattern_pixel_kernels

    return pattern_pixel_kernels(pattern)


def test_a_run_past_its_time_limit_does_no_more_steps_on_resume(image_folder, tmp_path):
    config = tiny(image_folder, tmp_path / "t", **{"run.time_limit": 1e-5, "optim.steps": 50})
    first = train(config, progress=False)
    assert 1 <= first.step < 50
    again = train(config, resume=True, progress=False)
    assert again.step == first.step


def test_a_validation_before_the_first_logged_step_shows_in_the_progress_bar(
    image_folder, tmp_path
):
    """Validation every 3 steps, logging every 4: the row of step 3 holds validation only (the
    training window is logged at step 4), in the file and beside the progress bar."""
    changes = {"run.log_every": 4, "run.val_every": 3, "optim.steps": 5}
    result = train(tiny(image_folder, tmp_path / "b", **changes), progress=True)
    assert result.step == 5 and "loss" in result.last_metrics
    rows = [json.loads(x) for x in (tmp_path / "b/metrics.jsonl").read_text().splitlines()]
    assert [(r["step"], "loss" in r, "val_psnr" in r) for r in rows] == [
        (0, False, True),
        (3, False, True),
        (4, True, False),
        (5, True, True),
    ]


def _weights(run) -> dict:
    tensors = ckpt_io.load(run).tensors
    return {k: v for k, v in tensors.items() if k.startswith("model/network.")}


def test_divergence_rolls_back_and_halves_the_learning_rate(image_folder, tmp_path, caplog):
    """A divergence factor below 1 makes step 21 (the first with 20 losses of history) a
    divergence: its update is not applied, the weights go back to the step-0 snapshot, and the
    learning rate is halved from there on; the checkpoint records the scale and a resumed run
    keeps it. Without divergence the rate is the schedule's."""
    base = {
        "optim.steps": 25,
        "run.log_every": 1,
        "run.checkpoint_every": 100,
        "run.val_every": 1000,
        "optim.warmup_steps": 0,
        "optim.schedule": "constant",
    }
    train(
        tiny(image_folder, tmp_path / "g", **base, **{"optim.divergence_factor": 1e-6}),
        progress=False,
    )
    rows = [json.loads(x) for x in (tmp_path / "g/metrics.jsonl").read_text().splitlines()]
    by_step = {r["step"]: r for r in rows if "rollbacks" in r}
    assert [s for s, r in by_step.items() if r["rollbacks"]] == [21]
    assert by_step[20]["lr"] == pytest.approx(1e-3) and by_step[22]["lr"] == pytest.approx(5e-4)
    assert ckpt_io.load(tmp_path / "g").meta["lr_scale"] == 0.5
    said = [r for r in caplog.records if "diverged; rolled back" in r.getMessage()]
    assert [(r.levelno, r.name.split(".")[0]) for r in said] == [(logging.WARNING, "splitcam")]
    assert said[0].getMessage().startswith("step 21: loss ")
    train(
        tiny(
            image_folder,
            tmp_path / "g",
            **{**base, "optim.steps": 27},
            **{"optim.divergence_factor": None},
        ),
        resume=True,
        progress=False,
    )
    rows = [json.loads(x) for x in (tmp_path / "g/metrics.jsonl").read_text().splitlines()]
    assert [r["lr"] for r in rows if r.get("step") in (26, 27)] == pytest.approx([5e-4, 5e-4])
    train(tiny(image_folder, tmp_path / "free", **base), progress=False)
    rows = [json.loads(x) for x in (tmp_path / "free/metrics.jsonl").read_text().splitlines()]
    assert all(r["lr"] == pytest.approx(1e-3) and r["rollbacks"] == 0 for r in rows if "lr" in r)


def test_divergence_guard_restores_the_older_snapshot() -> None:
    from splitcam.training.guard import DivergenceGuard

    model = torch.nn.Linear(2, 1)
    optimizer = torch.optim.Adam(model.parameters(), lr=0.1)
    guard = DivergenceGuard(10.0, every=3, min_history=2)
    states = []
    for _ in range(7):  # snapshots after 0, 3 and 6 healthy steps: kept 3 and 6
        states.append(model.weight.detach().clone())
        guard.applied(1.0, model, optimizer)
        model.weight.data += 1.0
    assert not guard.diverged(5.0) and guard.diverged(11.0) and guard.diverged(float("nan"))
    guard.roll_back(model, optimizer)
    assert torch.equal(model.weight, states[3]) and guard.lr_scale == 0.5
    assert not guard.diverged(1e9)  # the window starts afresh
    with pytest.raises(ValueError, match="factor"):
        DivergenceGuard(-1.0)


def test_gradient_clipping_bounds_the_update(image_folder, tmp_path):
    """Clipping the gradient norm to 1e-12 leaves Adam's update at ~lr * 1e-12 / eps: the
    weights barely move, where an unclipped run moves them by about lr per step."""
    base = {"optim.steps": 5, "run.val_every": 1000, "optim.warmup_steps": 0}
    train(tiny(image_folder, tmp_path / "c", **base, **{"optim.clip_grad": 1e-12}), progress=False)
    train(tiny(image_folder, tmp_path / "f", **base), progress=False)
    train(tiny(image_folder, tmp_path / "z", **{**base, "optim.steps": 0}), progress=False)
    start, clipped, free = (_weights(tmp_path / n) for n in ("z", "c", "f"))
    moved = max(float((clipped[k] - start[k]).abs().max()) for k in start)
    moved_free = max(float((free[k] - start[k]).abs().max()) for k in start)
    assert moved < 1e-5 < 1e-3 < moved_free


def test_training_minutes_leave_out_the_pause_of_a_resumed_run():
    """A run logged every 10 s, stopped for 80 minutes and resumed: the curves' time axis counts
    the pause as one ordinary gap, and an uninterrupted run keeps its wall-clock minutes."""
    from splitcam.viz.curves import active_minutes

    times = [0, 10, 20, 30, 4830, 4840, 4850]
    minutes = active_minutes([{"step": 10 * i, "time": t} for i, t in enumerate(times)])
    assert minutes == pytest.approx([t / 60 for t in (0, 10, 20, 30, 40, 50, 60)])
    steady = [0, 9, 21, 30, 41]
    got = active_minutes([{"step": i, "time": t} for i, t in enumerate(steady)])
    assert got == pytest.approx([t / 60 for t in steady])


def test_a_run_saved_before_partial_periods_existed_resumes_without_them(image_folder, tmp_path):
    from splitcam.training.trainer import resume_config

    run = tmp_path / "old"
    train(
        tiny(image_folder, run, **{"optim.steps": 2, "data.partial_periods": 0.0}), progress=False
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
