"""What a run changes and keeps (splitcam.training.state): a checkpoint written by
save_checkpoint and restored into a freshly prepared run gives back the weights, the optimiser's
moments, the step, the time spent and the generators (the next patches and noise are the ones
the first run would have drawn), while the peak rate is the new configuration's; save_best keeps
the weights it scored beside the checkpoint."""

from __future__ import annotations

import pytest
import torch
from conftest import tiny_config

from splitcam.io import checkpoints as ckpt_io
from splitcam.training.setup import prepare
from splitcam.training.state import save_best, save_checkpoint


def _moved(state) -> None:
    """One made-up optimiser step: weights, moments and step change, generators advance."""
    for p in state.system.parameters():
        if p.requires_grad:
            p.grad = torch.full_like(p, 1e-3)
    state.optimizer.step()
    state.sampler.sample(4)
    state.step = 7
    state.train_seconds = 12.5


@pytest.fixture
def moved(image_folder, tmp_path):
    """A prepared physics run after one made-up step: its config, folder, run and state."""
    config = tiny_config(image_folder, tmp_path / "r", **{"network.arch": "physics"})
    run_dir = tmp_path / "r"
    run_dir.mkdir()
    run, state = prepare(config, run_dir, None, False)
    _moved(state)
    return config, run_dir, run, state


def test_a_checkpoint_restores_what_the_run_changed(moved) -> None:
    config, run_dir, run, state = moved
    save_checkpoint(state, run)
    expected_weights = {k: v.clone() for k, v in state.system.state_dict().items()}
    expected_moments = [
        {k: v.clone() for k, v in s.items() if torch.is_tensor(v)}
        for s in state.optimizer.state.values()
    ]
    expected_batch = state.sampler.sample(4)

    changed = config.override({"optim.lr": 5e-4})
    again, restored = prepare(changed, run_dir, ckpt_io.load(run_dir), False)
    assert restored.step == 7 and restored.train_seconds == 12.5
    for key, value in restored.system.state_dict().items():
        assert torch.equal(value, expected_weights[key]), key
    moments = [
        {k: v for k, v in s.items() if torch.is_tensor(v)}
        for s in restored.optimizer.state.values()
    ]
    assert len(moments) == len(expected_moments) > 0
    for got, want in zip(moments, expected_moments, strict=True):
        assert all(torch.equal(got[k], want[k]) for k in want)
    assert torch.equal(restored.sampler.sample(4), expected_batch)
    assert [g["peak_lr"] for g in restored.optimizer.param_groups][0] == 5e-4


def test_save_best_keeps_the_scored_weights(moved) -> None:
    _, run_dir, run, state = moved
    save_best(state, run, 31.5)
    assert state.best_val == 31.5
    best = ckpt_io.load(run_dir / ckpt_io.BEST_NAME)
    weights = state.system.state_dict()
    saved = {k: v for k, v in best.section("model").items() if k.startswith("network.")}
    network = {k: v for k, v in weights.items() if k.startswith("network.")}
    assert saved.keys() == network.keys() and len(saved) > 0
    assert all(torch.equal(v, network[k]) for k, v in saved.items())
    assert not (run_dir / ckpt_io.CHECKPOINT_NAME).exists()
