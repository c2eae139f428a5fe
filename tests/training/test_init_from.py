"""Starting a run from a model (splitcam.training.init_from): weights, provenance, schedule, learned
patterns, ambiguous names."""

from __future__ import annotations

import json
import math

import pytest
import torch
from conftest import blocky_images, small_config, tiny_config

from splitcam.io import checkpoints as ckpt_io
from splitcam.recon.loading import load_model
from splitcam.training import ConfigError, load_system, train
from splitcam.training.models import export_model


def test_training_from_a_model_continues_its_weights_and_provenance(
    run_images, trained_run, tmp_path
):
    model = export_model(trained_run, tmp_path / "m", storage="float32")
    system = load_model(model)
    out = tmp_path / "more"
    config = small_config(
        run_images,
        out,
        **{
            "run.init_from": str(model),
            "optim.steps": 2,
            "optim.lr": 1e-12,
            "optim.warmup_steps": 0,
        },
    )
    train(config, progress=False)
    continued = load_system(out)
    for key, value in system.network.state_dict().items():  # a tiny lr: the weights stay
        torch.testing.assert_close(continued.network.state_dict()[key], value, rtol=0, atol=1e-8)
    meta = json.loads(export_model(out, tmp_path / "m2").read_text())
    prov = meta["provenance"]
    assert prov["total_steps"] == 6
    assert [s["steps"] for s in prov["segments"]] == [4, 2]
    assert prov["segments"][1]["init_from"] == "m"
    assert [r["step"] for r in prov["validation"]] == [0, 2, 4, 4, 6]
    # Another fixed pattern of the same period starts from these weights, and says so; another
    # architecture (or period) is refused.
    other = small_config(
        run_images,
        tmp_path / "x",
        **{"run.init_from": str(model), "pattern.name": "A", "optim.steps": 1},
    )
    train(other, progress=False)
    assert (
        ckpt_io.read_meta(tmp_path / "x" / "checkpoint.safetensors")["init_from"]["pattern"] == "D"
    )
    with pytest.raises(ConfigError, match="differs"):
        train(
            small_config(
                run_images, tmp_path / "z", **{"run.init_from": str(model), "pattern.name": "E"}
            ),
            progress=False,
        )
    with pytest.raises(ConfigError, match="differs"):
        train(
            small_config(
                run_images, tmp_path / "y", **{"run.init_from": str(model), "network.features": 4}
            ),
            progress=False,
        )


def _logged_lr(run_dir):
    rows = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return {r["step"]: r["lr"] for r in rows if "lr" in r}


def test_continue_schedule_ends_a_snapshot_on_the_schedule_and_budget_of_one_run(
    run_images, tmp_path
):
    """A run whose folder was lost goes on from its exported weights: steps, schedule and
    budget are those of one straight run; only the Adam moments restart, under a new warm-up.
    Resuming the continued run keeps its starting step."""
    whole = {"optim.steps": 8, "optim.warmup_steps": 2, "run.val_every": 2}
    straight = tmp_path / "straight"
    train(small_config(run_images, straight, **whole), progress=False)
    first = tmp_path / "first"
    train(small_config(run_images, first, **{**whole, "optim.steps": 4}), progress=False)
    snapshot = export_model(first, tmp_path / "snap", storage="float32")
    cont = tmp_path / "cont"
    settings = {**whole, "run.init_from": str(snapshot), "run.continue_schedule": True}
    train(small_config(run_images, cont, **{**settings, "optim.steps": 6}), progress=False)
    train(small_config(run_images, cont, **settings), resume=True, progress=False)

    def cosine(step, steps, warm=1.0):  # logged after step s: the rate of step s - 1
        return 1e-3 * warm * 0.5 * (1 + math.cos(math.pi * (step - 1) / steps))

    want, got = _logged_lr(straight), _logged_lr(cont)
    assert sorted(got) == [5, 6, 7, 8]  # steps of the whole, from the snapshot's on
    # Steps 5 and 6 ran on a 6-step budget, the first of them warming up the fresh moments.
    assert got[5] == pytest.approx(cosine(5, 6, warm=0.5), rel=1e-12)
    assert got[6] == pytest.approx(cosine(6, 6), rel=1e-12)
    for step in (7, 8):  # resumed: the straight run's cosine at the same step
        assert got[step] == pytest.approx(want[step], rel=1e-12)
        assert got[step] == pytest.approx(cosine(step, 8), rel=1e-12)
    prov = json.loads(export_model(cont, tmp_path / "whole").read_text())["provenance"]
    assert prov["total_steps"] == 8
    assert [s["steps"] for s in prov["segments"]] == [4, 4]
    assert [r["step"] for r in prov["validation"]] == [0, 2, 4, 6, 8]

    with pytest.raises(ConfigError, match="needs run.init_from"):
        small_config(run_images, tmp_path / "x", **{"run.continue_schedule": True}).validate()
    with pytest.raises(ConfigError, match="between 0 and optim.steps"):
        train(
            small_config(run_images, tmp_path / "y", **{**settings, "optim.steps": 4}),
            progress=False,
        )


def test_learned_pattern_starts_from_the_model_kernels(run_images, tmp_path):
    out = tmp_path / "joint"
    train(
        small_config(run_images, out, **{"pattern.learn": True, "optim.lr": 0.05}), progress=False
    )
    learned = load_system(out).sensor.pixel_kernels()
    # The high rate moves the kernels far (and the loss up: the run counts as failed, so its
    # export needs force); what matters here is that the kernels carry over.
    model = export_model(out, tmp_path / "jm", force=True)
    out2 = tmp_path / "joint2"
    train(
        small_config(
            run_images,
            out2,
            **{
                "pattern.learn": True,
                "run.init_from": str(model),
                "optim.steps": 1,
                "optim.lr": 1e-12,
                "optim.warmup_steps": 0,
            },
        ),
        progress=False,
    )
    torch.testing.assert_close(load_system(out2).sensor.pixel_kernels(), learned, rtol=0, atol=1e-5)


def test_init_from_an_ambiguous_name_is_refused(tmp_path, monkeypatch):
    from splitcam.training import ConfigError, train

    data = blocky_images(tmp_path / "img", 4)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "D").mkdir()
    config = tiny_config(data, tmp_path / "run", **{"run.init_from": "D", "network.features": 64})
    with pytest.raises(ConfigError, match="ambiguous"):
        train(config, progress=False)
