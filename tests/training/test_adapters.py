"""Fine-tuning through an adapter (splitcam.training.adapters, ``optim.adapter``): the folded
network computes what the adapted one does, a frozen network stays frozen, readers of the run
get a plain network, and a resume is exact."""

from __future__ import annotations

import pytest
import torch
from conftest import tiny_config

from splitcam import patterns
from splitcam.io import checkpoints as ckpt_io
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.loading import load_model, load_network
from splitcam.recon.networks import UniversalReconNet
from splitcam.training import TrainConfig, train
from splitcam.training.adapters import BASE_PREFIX, ChannelAdapter
from splitcam.training.config import ConfigError


def _kernels(name: str) -> torch.Tensor:
    return SplitterSensor(patterns.get(name)).pixel_kernels().detach()


def test_the_folded_network_computes_what_the_adapted_one_does():
    torch.manual_seed(0)
    net = UniversalReconNet(features=8, blocks=2).eval()
    for p in net.parameters():  # the tail starts at zero: give every layer something to scale
        p.data.normal_(0, 0.1)
    adapter = ChannelAdapter(net)
    assert len(adapter.names) == 7  # head, 2 x 2 in the blocks, body_out, tail
    for p in adapter.parameters():
        p.data.add_(torch.randn_like(p) * 0.3)
    raw, kernels = torch.rand(2, 1, 13, 11), _kernels("rgbw")
    adapted = net(raw, 5.0, kernels)
    plain = UniversalReconNet(features=8, blocks=2).eval()
    plain.load_state_dict(adapter.folded(net.state_dict()))
    torch.testing.assert_close(plain(raw, 5.0, kernels), adapted, rtol=1e-5, atol=1e-5)
    # The adapter really changes the output, and removing it restores the network's own.
    adapter.remove()
    assert (net(raw, 5.0, kernels) - adapted).abs().max() > 1e-3


@pytest.fixture
def film_settings(tiny_universal):
    model, _ = tiny_universal
    return {
        "pattern.name": "rgbw",
        "network.arch": "universal",
        "run.init_from": str(model),
        "optim.adapter": "film",
        "optim.steps": 4,
        "run.val_every": 2,
        "run.checkpoint_every": 2,
    }


def test_a_frozen_network_only_moves_its_adapter_and_readers_get_it_folded(
    tiny_universal, film_settings, tmp_path
):
    model, data = tiny_universal
    run = tmp_path / "film"
    train(tiny_config(data, run, **film_settings), progress=False)
    start = load_model(str(model)).network.state_dict()
    loaded = ckpt_io.load(run)
    base = loaded.section(BASE_PREFIX)
    model_state = loaded.section("model")
    convs = [k for k in base if k.startswith("network.trunk.")]
    assert convs and all(torch.equal(base[k], start[k[len("network.") :]]) for k in base)
    # What readers load: the start's weights with the trained scales and shifts folded in.
    scale = model_state["adapter.scale.trunk-head"]
    shift = model_state["adapter.shift.trunk-head"]
    assert (scale - 1).abs().max() > 0
    torch.testing.assert_close(
        model_state["network.trunk.head.weight"],
        start["trunk.head.weight"] * scale.view(-1, 1, 1, 1),
    )
    torch.testing.assert_close(
        model_state["network.trunk.head.bias"], start["trunk.head.bias"] * scale + shift
    )
    # The encoder is not a convolution: frozen and saved as it was.
    assert torch.equal(model_state["network.encoder.0.weight"], start["encoder.0.weight"])
    network = load_network(run).network
    assert isinstance(network, UniversalReconNet)
    best = ckpt_io.load(run / ckpt_io.BEST_NAME)
    assert not best.section(BASE_PREFIX)


def test_an_adapted_run_resumes_exactly(tiny_universal, film_settings, tmp_path):
    _, data = tiny_universal
    # A constant rate: the first part's schedule is then that of the whole run.
    settings = {
        **film_settings,
        "optim.base_lr_scale": 0.1,
        "optim.schedule": "constant",
        "optim.warmup_steps": 0,
    }
    straight = tmp_path / "straight"
    train(tiny_config(data, straight, **settings), progress=False)
    split = tmp_path / "split"
    train(tiny_config(data, split, **{**settings, "optim.steps": 2}), progress=False)
    train(tiny_config(data, split, **settings), resume=True, progress=False)
    a, b = ckpt_io.load(straight), ckpt_io.load(split)
    for prefix in ("model", BASE_PREFIX):
        left, right = a.section(prefix), b.section(prefix)
        assert left.keys() == right.keys()
        for k in left:
            assert torch.equal(left[k], right[k]), (prefix, k)
    # At a tenth of the rate the network's own weights move too.
    start = load_model(film_settings["run.init_from"]).network.state_dict()
    moved = a.section(BASE_PREFIX)["network.trunk.head.weight"] - start["trunk.head.weight"]
    assert moved.abs().max() > 0


def test_adapter_settings_are_checked():
    with pytest.raises(ConfigError, match="adapter"):
        TrainConfig().override({"optim.adapter": "lora"}).validate()
    with pytest.raises(ConfigError, match="ema"):
        TrainConfig().override({"optim.adapter": "film", "optim.ema": 0.999}).validate()
    with pytest.raises(ConfigError, match="base_lr_scale"):
        TrainConfig().override({"optim.adapter": "film", "optim.base_lr_scale": -1}).validate()
    with pytest.raises(ConfigError, match="hard_patches"):
        TrainConfig().override({"data.hard_patches": 2}).validate()
