"""The average of the network's weights (splitcam.training.ema, ``optim.ema``): it is the
naive exponential average of the weights the run went through, survives a resume exactly, is
what validation and the run's readers use, and restarts when the guard rolls back."""

from __future__ import annotations

import json
import shutil

import pytest
import torch
from conftest import initial_state, tiny_config
from torch import nn

from splitcam.io import checkpoints as ckpt_io
from splitcam.recon.loading import load_network
from splitcam.training import train
from splitcam.training.ema import WeightAverage

BASE = {
    "optim.schedule": "constant",
    "optim.warmup_steps": 0,
    "run.val_every": 1000,
    "run.checkpoint_every": 1000,
}


def _section(run, prefix: str) -> dict[str, torch.Tensor]:
    return ckpt_io.load(run).section(prefix)


def test_the_average_follows_the_naive_recurrence():
    net = nn.Sequential(nn.Linear(3, 2), nn.BatchNorm1d(2))
    avg = WeightAverage(net, decay=0.9)
    seen = [{k: v.clone() for k, v in net.state_dict().items()}]
    for _ in range(30):
        with torch.no_grad():
            for p in net.parameters():
                p.add_(torch.randn_like(p))
            net[1].running_mean.add_(1.0)
        avg.update()
        seen.append({k: v.clone() for k, v in net.state_dict().items()})
    expect = dict(seen[0])
    for n, weights in enumerate(seen[1:]):
        d = min(0.9, (1 + n) / (10 + n))
        expect = {k: d * expect[k] + (1 - d) * weights[k] for k in ("0.weight", "0.bias")}
    for k in ("0.weight", "0.bias"):
        torch.testing.assert_close(avg.shadow[k], expect[k])
    # Buffers are the module's, not averaged.
    assert torch.equal(avg.shadow["1.running_mean"], net[1].running_mean)
    own = {k: v.clone() for k, v in net.state_dict().items()}
    with avg.applied():
        torch.testing.assert_close(net[0].weight, expect["0.weight"])
    for k, v in net.state_dict().items():
        assert torch.equal(v, own[k]), k
    avg.reset()
    assert avg.updates == 0 and torch.equal(avg.shadow["0.weight"], net[0].weight)
    with pytest.raises(ValueError, match="decay"):
        WeightAverage(net, decay=1.0)


def test_a_run_keeps_the_average_of_the_weights_it_went_through(image_folder, tmp_path):
    """Trained one step at a time (resumes are exact), the run's weights after each step are
    known; the checkpoint's average is their naive exponential average, and a straight run of
    the same steps saves the same average."""
    decay, steps = 0.5, 4
    config = {**BASE, "optim.ema": decay}
    start = initial_state(tiny_config(image_folder, tmp_path / "zero", **config))
    seen = [{k[len("model/") :]: v for k, v in start.items()}]
    run = tmp_path / "stepwise"
    for k in range(1, steps + 1):
        train(
            tiny_config(image_folder, run, **config, **{"optim.steps": k}),
            resume=k > 1,
            progress=False,
        )
        seen.append(_section(run, "model"))
    net_keys = [k for k in seen[0] if k.startswith("network.") and seen[0][k].is_floating_point()]
    expect = {k: seen[0][k].float() for k in net_keys}
    for n, weights in enumerate(seen[1:]):
        d = min(decay, (1 + n) / (10 + n))
        expect = {k: d * expect[k] + (1 - d) * weights[k].float() for k in net_keys}
    saved = _section(run, "ema")
    moved = max(float((saved[k] - seen[-1][k]).abs().max()) for k in net_keys)
    assert moved > 0  # the average is not the last weights
    for k in net_keys:
        torch.testing.assert_close(saved[k], expect[k], rtol=1e-5, atol=1e-7)
    assert ckpt_io.load(run).meta["ema_updates"] == steps

    straight = tmp_path / "straight"
    train(tiny_config(image_folder, straight, **config, **{"optim.steps": steps}), progress=False)
    for k, v in _section(straight, "ema").items():
        torch.testing.assert_close(v, saved[k], rtol=1e-5, atol=1e-7)

    # The run's network, as evaluate --checkpoint and models export read it, is the average.
    network = load_network(run).network
    for k, v in network.state_dict().items():
        torch.testing.assert_close(v.float(), saved[f"network.{k}"].float())


def test_validation_scores_the_average(image_folder, tmp_path):
    """The last validation of a run with an average is the score of the averaged weights: a
    copy of the checkpoint without them (the trained weights) scores differently, and one whose
    trained weights are replaced by the average scores the same."""
    from splitcam.training import load_system
    from splitcam.training.validation import val_images, validate

    config = tiny_config(
        image_folder,
        tmp_path / "r",
        # float32: a CPU with native bfloat16 would validate the run in it (precision auto)
        # and the copies below in float32
        **{**BASE, "optim.ema": 0.5, "optim.steps": 6, "run.val_every": 6, "run.precision": "fp32"},
    )
    train(config, progress=False)
    rows = [json.loads(x) for x in (tmp_path / "r/metrics.jsonl").read_text().splitlines()]
    logged = [r for r in rows if "val_psnr" in r][-1]
    assert logged["step"] == 6
    system = load_system(tmp_path / "r")
    images, sigmas = val_images(config), config.data.val_sigmas
    scored = validate(system, images, sigmas)
    assert scored["val_psnr"] == pytest.approx(logged["val_psnr"], abs=1e-6)
    loaded = ckpt_io.load(tmp_path / "r")
    trained = {k: v for k, v in loaded.tensors.items() if not k.startswith("ema/")}
    shutil.copytree(tmp_path / "r", tmp_path / "plain")
    ckpt_io.save(tmp_path / "plain" / ckpt_io.CHECKPOINT_NAME, loaded.meta, trained)
    plain = validate(load_system(tmp_path / "plain"), images, sigmas)
    assert plain["val_psnr"] != pytest.approx(logged["val_psnr"], abs=1e-6)


def test_a_roll_back_restarts_the_average(image_folder, tmp_path):
    """The guard's roll-back at step 21 (factor below 1, as in the guard's test) restarts the
    average from the restored weights: the run's updates count from there."""
    config = {
        **BASE,
        "optim.ema": 0.99,
        "optim.steps": 25,
        "optim.divergence_factor": 1e-6,
    }
    train(tiny_config(image_folder, tmp_path / "g", **config), progress=False)
    # Steps 1-20 applied, 21 rolled back (not applied, average restarted), 22-25 applied.
    assert ckpt_io.load(tmp_path / "g").meta["ema_updates"] == 4


def test_an_exported_model_is_the_average_and_says_so(image_folder, tmp_path):
    from splitcam.recon.loading import load_model
    from splitcam.training.models import export_model

    config = {**BASE, "optim.ema": 0.5, "optim.steps": 3, "optim.loss": "l1"}
    train(tiny_config(image_folder, tmp_path / "r", **config), progress=False)
    path = export_model(tmp_path / "r", tmp_path / "m", storage="float32")
    model = load_model(path)
    saved = _section(tmp_path / "r", "ema")
    for k, v in model.network.state_dict().items():
        torch.testing.assert_close(v.float(), saved[f"network.{k}"].float())
    recipe = json.loads(path.read_text())["provenance"]["segments"][-1]["recipe"]
    assert (recipe["ema"], recipe["loss"]) == (0.5, "l1")
