"""The divergence guard (splitcam.training.guard): snapshots, roll-back, giving up."""

from __future__ import annotations

import pytest
import torch
from conftest import blocky_images, tiny_config

from splitcam.training import train


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


def test_the_guard_gives_up_after_halving_the_rate_ten_times(tmp_path):
    from splitcam.training.rundir import GUARD_GIVES_UP

    data = blocky_images(tmp_path / "img", 5)
    # A factor below 1 makes every step once the window is full a divergence.
    config = tiny_config(
        data,
        tmp_path / "r",
        **{"optim.steps": 400, "optim.divergence_factor": 1e-9, "run.val_every": 1000},
    )
    result = train(config, progress=False)
    assert result.step < 400
    assert result.failure and f"halved the learning rate {GUARD_GIVES_UP} times" in result.failure


def test_a_diverged_resume_keeps_the_last_good_resumable_state(tmp_path):
    """A resume at a learning rate far too high diverges and fails saying so; the checkpoint
    saved before it is left byte for byte (weights, optimiser state, step), and a resume at a
    sane rate continues from it."""
    data = blocky_images(tmp_path / "img", 5)
    settings = {"optim.steps": 40, "run.checkpoint_every": 20, "run.val_every": 1000}
    config = tiny_config(data, tmp_path / "r", **settings)
    assert train(config, progress=False).failure is None
    checkpoint = tmp_path / "r" / "checkpoint.safetensors"
    before = checkpoint.read_bytes()
    wild = config.override({"optim.steps": 400, "optim.lr": 1000.0, "optim.warmup_steps": 0})
    failed = train(wild, resume=True, progress=False)
    assert failed.failure and failed.step < 400
    assert "checkpoint of step 40" in failed.failure and "lower --lr" in failed.failure
    assert checkpoint.read_bytes() == before
    calm = config.override({"optim.steps": 50, "optim.lr": 1e-4})
    again = train(calm, resume=True, progress=False)
    assert again.failure is None and again.step == 50


def test_the_first_snapshot_predates_the_first_update() -> None:
    """An update that wrecks the network at once is undone: the guard's first snapshot is the
    state before any step (start), and a seeded window catches the next loss."""
    from splitcam.training.guard import DivergenceGuard

    model = torch.nn.Linear(2, 1)
    optimizer = torch.optim.Adam(model.parameters(), lr=0.1)
    guard = DivergenceGuard(10.0)
    start = model.weight.detach().clone()
    guard.start(model, optimizer)
    guard.seed([1.0, 1.1, 0.9])
    guard.applied(1.0, model, optimizer)
    model.weight.data += 100.0  # the wrecking update
    assert guard.diverged(1e4) and guard.settled
    guard.roll_back(model, optimizer)
    assert torch.equal(model.weight, start) and not guard.settled
    for _ in range(guard.every + 1):
        guard.applied(1.0, model, optimizer)
    assert guard.settled


def test_a_continued_schedule_that_diverges_says_no_checkpoint_was_kept(tmp_path):
    """A new run that continues another's schedule starts past step 0 with nothing on disk: its
    failure must not claim a kept checkpoint."""
    data = blocky_images(tmp_path / "img", 5)
    first = tiny_config(data, tmp_path / "a", **{"optim.steps": 10, "run.val_every": 1000})
    assert train(first, progress=False).failure is None
    wild = {
        "optim.steps": 400,
        # A factor below 1: every step once the window is full is a divergence, so the guard
        # gives up.
        "optim.divergence_factor": 1e-9,
        "run.init_from": str(tmp_path / "a"),
        "run.continue_schedule": True,
        "run.checkpoint_every": 1000,
        "run.val_every": 1000,
    }
    failed = train(tiny_config(data, tmp_path / "b", **wild), progress=False)
    assert failed.failure and "no checkpoint had been saved" in failed.failure
    assert not (tmp_path / "b" / "checkpoint.safetensors").exists()
