"""``splitcam train``: flags and their defaults, training, resuming, plotting and reconstructing
from the run, failed runs, fine-tuning a model for any pattern."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from conftest import blocky_images, tiny_config
from PIL import Image

from splitcam import patterns
from splitcam.cli import main
from splitcam.io import checkpoints as ckpt_io
from splitcam.patterns.random import random_pattern
from splitcam.training import train


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


def test_fine_tuning_from_a_universal_model(tiny_universal, tmp_path, capsys):
    """`train --pattern FILE --init-from MODEL`: the architecture follows the model, the weights
    start from it, and the run is a model like any other."""
    from splitcam.cli import main
    from splitcam.recon.loading import load_model
    from splitcam.recon.registry import build_method

    model, data = tiny_universal
    mine = tmp_path / "mine.toml"
    patterns.save(random_pattern(np.random.default_rng(6)), mine)
    run = tmp_path / "ft"
    args = ["train", "--pattern", str(mine), "--init-from", str(model), "--data", str(data)]
    tiny = ["--val-split", "2", "--val-images", "1", "--patch-size", "16", "--batch-size", "2"]
    assert main([*args, *tiny, "--steps", "2", "--out", str(run), "--quiet"]) == 0
    config = json.loads((run / "config.json").read_text())
    assert config["network"]["arch"] == "universal" and config["network"]["features"] == 8
    assert config["run"]["time_limit"] is None  # --steps given: no default budget
    assert config["optim"]["lr"] == 3e-4  # the fine-tuning rate
    method = build_method(str(run), precision="fp32")  # a run of one pattern: its own
    assert method.pattern.equals(patterns.load(mine))
    source = load_model(model)
    from splitcam.training.checkpoint import load_system

    tuned = load_system(run)
    changed = [
        k
        for k, v in tuned.network.state_dict().items()
        if not torch.equal(v, source.network.state_dict()[k])
    ]
    assert changed  # trained on from the model's weights


def test_a_config_file_keeps_its_budget_and_rate_when_it_starts_from_a_universal_model(
    tiny_universal, tmp_path
):
    """The settings implied by `--init-from universal` give way to the --config file, as the
    defaults do (experiments/gpu/universal.toml sets its own): they once overrode it with the
    10-minute budget and the fine-tuning rate (the file's 2 steps end the run either way)."""
    from splitcam.cli import main

    model, data = tiny_universal
    config = tmp_path / "mine.toml"
    config.write_text(
        f'[pattern]\nname = "D"\n[optim]\nlr = 1e-3\nsteps = 2\n'
        f"[run]\ntime_limit = 0.004\ninit_from = {json.dumps(str(model))}\n"
    )
    run = tmp_path / "ft"
    tiny = ["--val-split", "2", "--val-images", "1", "--patch-size", "16", "--batch-size", "2"]
    args = ["train", "--config", str(config), "--data", str(data), *tiny]
    assert main([*args, "--out", str(run), "--quiet"]) == 0
    saved = json.loads((run / "config.json").read_text())
    assert saved["network"]["arch"] == "universal"  # still implied by the model
    assert saved["run"]["time_limit"] == 0.004 and saved["optim"]["lr"] == 1e-3
    assert saved["run"]["config_file"] == str(config)  # what the provenance names


def test_a_run_that_diverges_says_so_and_fails(tmp_path, capsys):
    """`--lr 100` used to end at a loss of 1e19 and report "finished" with exit 0."""

    data = blocky_images(tmp_path / "img", 5)
    args = ["train", "--data", str(data), "--patch-size", "16", "--batch-size", "4"]
    args += ["--features", "8", "--blocks", "1", "--val-split", "2", "--val-crop", "32"]
    args += ["--val-every", "10", "--threads", "1", "--quiet"]
    assert main([*args, "--steps", "20", "--lr", "100", "--out", str(tmp_path / "bad")]) == 1
    assert "splitcam train: failed:" in capsys.readouterr().err
    good = train(tiny_config(data, tmp_path / "good", **{"optim.steps": 6}), progress=False)
    assert good.failure is None


def test_train_with_a_pattern_file_starts_from_universal(image_folder, tmp_path):
    from splitcam.cli import main

    mine = tmp_path / "mine.toml"
    patterns.save(random_pattern(np.random.default_rng(3)), mine)
    run = tmp_path / "run"
    args = ["train", "--pattern", str(mine), "--data", str(image_folder), "--steps", "1"]
    tiny = ["--val-split", "1", "--patch-size", "16", "--batch-size", "1", "--threads", "1"]
    assert main([*args, *tiny, "--out", str(run), "--quiet"]) == 0
    config = json.loads((run / "config.json").read_text())
    assert config["run"]["init_from"] == "universal"
    assert config["network"]["arch"] == "universal"
    assert config["data"]["hard_patches"] == 0.5 and config["optim"]["lr"] == 3e-4


@pytest.mark.parametrize("period", [(2, 2), (3, 3), (4, 4), (2, 4)])
def test_a_users_pattern_file_of_any_period_fine_tunes_and_reconstructs(
    tiny_universal, tmp_path, period
):
    """A pattern file of period 2x2 to 4x4 trains like any other (from the network for any
    pattern) and its run reconstructs a photo of odd size that ends part-way through a period."""
    from splitcam.physics.noise import add_evaluation_noise
    from splitcam.physics.sensor import SplitterSensor
    from splitcam.recon.registry import build_method

    model, data = tiny_universal
    rng = np.random.default_rng(sum(period))
    while True:  # a draw of exactly this period
        drawn = random_pattern(rng)
        if drawn.period == period:
            break
    mine = tmp_path / "mine.toml"
    patterns.save(drawn, mine)
    run = tmp_path / "run"
    args = ["train", "--pattern", str(mine), "--init-from", str(model), "--data", str(data)]
    tiny = ["--val-split", "2", "--val-images", "1", "--patch-size", "16", "--batch-size", "2"]
    assert main([*args, *tiny, "--steps", "2", "--out", str(run), "--quiet"]) == 0
    method = build_method(str(run), precision="fp32")
    scene = torch.rand(1, 3, 13, 11, generator=torch.Generator().manual_seed(0))
    raw = add_evaluation_noise(SplitterSensor(drawn)(scene), "x", 5.0)
    out = method.reconstruct(raw, 5.0)
    assert out.shape == (1, 3, 13, 11) and torch.isfinite(out).all()


def test_a_photon_fine_tune_keeps_the_exposures_its_network_was_trained_on(
    image_folder, tmp_path, capsys
):
    """`--init-from universal-photon --noise photon` without `--photons` trains on the range the
    shipped network was trained on (its header: 1 to 10^4), not the default 10 to 10^4, which
    forgot the exposures below 10 (docs/results/exposure/measured/fine-tuned/); `--photons`
    given, or a network trained on Gaussian noise, keep the run's own."""
    from splitcam.recon.loading import resolve_model

    header = json.loads(resolve_model("universal-photon").read_text())["config"]["noise"]
    run = tmp_path / "ft"
    args = ["train", "--pattern", "D", "--init-from", "universal-photon", "--noise", "photon"]
    tiny = ["--val-split", "2", "--val-images", "1", "--patch-size", "16", "--batch-size", "2"]
    more = ["--domain", "linear", "--data", str(image_folder), "--steps", "1", "--quiet"]
    assert main([*args, *tiny, *more, "--out", str(run)]) == 0
    assert "the range universal-photon was trained on" in capsys.readouterr().out
    saved = json.loads((run / "config.json").read_text())
    assert saved["noise"]["photons"] == header["photons"]
