"""Training in the linear domain (model.md §13): ``data.domain``, patches decoded to radiance
before the sensor, the LMMSE inside the networks from the linear image statistics, validation
scored like ``evaluate --domain linear``, and models that reconstruct only their own domain."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
from conftest import blocky_images, tiny_config

from splitcam import patterns
from splitcam.cli import main
from splitcam.evaluation.protocol import mean_psnr
from splitcam.io import checkpoints as ckpt_io
from splitcam.io.domains import DOMAINS
from splitcam.physics.light import srgb_to_linear
from splitcam.physics.noise import Exposure
from splitcam.recon.closed_form import closed_form_lmmse, shipped_image_statistics
from splitcam.recon.networks import PhysicsReconNet, UniversalReconNet, build_network
from splitcam.recon.registry import build_method, build_model
from splitcam.training import ConfigError, TrainConfig, train
from splitcam.training.config import train_flags
from splitcam.training.models import export_model
from splitcam.training.trainer import _next_batch
from splitcam.training.validation import val_images

#: A linear run of four steps, validated at steps 0 and 4.
LINEAR = {
    "data.domain": "linear",
    "optim.steps": 4,
    "optim.warmup_steps": 2,
    "run.val_every": 4,
    "run.checkpoint_every": 4,
}


def _rows(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


def _holds(network: torch.nn.Module, domain: str) -> bool:
    stats = shipped_image_statistics(domain)
    return torch.equal(network.stat_mean.double(), stats.mean) and torch.equal(
        network.stat_second.double(), stats.second
    )


@pytest.fixture(scope="module")
def images(tmp_path_factory) -> Path:
    return blocky_images(tmp_path_factory.mktemp("images"), 5)


@pytest.fixture(scope="module")
def linear_run(images, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "linear"
    train(tiny_config(images, out, **LINEAR), progress=False)
    return out


def test_domain_setting_defaults_to_srgb_and_lists_its_choices():
    assert TrainConfig().data.domain == "srgb"
    flag = next(f for f in train_flags() if f.key == "data.domain")
    assert flag.name == "domain" and flag.choices == DOMAINS
    assert "(default: srgb)" in flag.help
    assert TrainConfig().override({"data.domain": "linear"}).data.domain == "linear"
    with pytest.raises(ConfigError, match="data.domain must be one of srgb, linear"):
        TrainConfig().override({"data.domain": "LINEAR"}).validate()


def test_a_run_saved_without_the_domain_reads_as_srgb():
    saved = TrainConfig().to_dict()
    del saved["data"]["domain"]
    assert TrainConfig.from_saved(saved).data.domain == "srgb"


def test_networks_hold_the_statistics_they_are_given():
    linear = shipped_image_statistics("linear")
    for config in ({"arch": "physics", "period": [2, 2]}, {"arch": "universal"}):
        small = {**config, "features": 4, "blocks": 0}
        assert _holds(build_network(small), "srgb")  # the default is unchanged
        assert _holds(build_network(small, statistics=linear), "linear")
    assert _holds(PhysicsReconNet((2, 2), features=4, blocks=0), "srgb")
    assert _holds(UniversalReconNet(features=4, blocks=0, statistics=linear), "linear")
    # The blind networks use no statistics.
    build_network({"arch": "packed", "period": [2, 2], "features": 4}, statistics=linear)
    net = PhysicsReconNet((2, 2), features=4, blocks=0)
    net.use_statistics(linear)
    assert _holds(net, "linear") and net.stat_mean.dtype == torch.float64


def test_use_statistics_refuses_another_window():
    stats = shipped_image_statistics("linear")
    smaller = type(stats)(stats.mean, stats.second[:, :, 1:-1, 1:-1], 0)
    with pytest.raises(ValueError, match="expected image statistics of shape"):
        PhysicsReconNet((2, 2), features=4, blocks=0).use_statistics(smaller)


@pytest.mark.parametrize("domain", DOMAINS)
def test_training_patches_are_the_light_of_the_domain(domain):
    """A batch is what the sampler cut, decoded to radiance in the linear domain; it is both
    the scene the sensor sees and the target of the loss."""
    patches = torch.rand(2, 3, 8, 8, generator=torch.Generator().manual_seed(0))
    state = SimpleNamespace(sampler=SimpleNamespace(sample=lambda n: patches[:n]))
    config = TrainConfig().override({"data.domain": domain, "data.batch_size": 2})
    run = SimpleNamespace(config=config, device=torch.device("cpu"), mix=None)
    batch = _next_batch(state, run)
    expected = srgb_to_linear(patches) if domain == "linear" else patches
    torch.testing.assert_close(batch, expected, rtol=0, atol=0)
    assert state.last_batch is batch


def test_a_linear_run_trains_validates_and_exports_in_linear(linear_run, images, tmp_path):
    config = TrainConfig.from_file(linear_run / "config.json")
    assert config.data.domain == "linear"
    loaded = ckpt_io.load(linear_run)
    assert loaded.meta["config"]["data"]["domain"] == "linear"
    for key in ("stat_mean", "stat_second"):
        torch.testing.assert_close(
            loaded.tensors[f"model/network.{key}"],
            getattr(shipped_image_statistics("linear"), key.removeprefix("stat_")),
            rtol=0,
            atol=0,
        )

    rows = [r for r in _rows(linear_run) if "val_psnr_0" in r]
    assert [r["step"] for r in rows] == [0, 4]
    held_out = val_images(config)
    # At step 0 the physics network is the closed-form LMMSE of the linear statistics, scored
    # in the linear domain.
    lmmse = mean_psnr(
        closed_form_lmmse(patterns.get("D"), domain="linear"), held_out, [0.0], domain="linear"
    )
    assert rows[0]["val_psnr_0"] == pytest.approx(lmmse[0.0], abs=1e-3)
    # The last row is what the evaluation protocol scores for the trained run, in linear.
    method = build_method(linear_run / "checkpoint.safetensors", domain="linear")  # the latest
    assert method.domain == "linear"
    final = mean_psnr(method, held_out, [0.0, 15.0], domain="linear")
    assert rows[-1]["val_psnr_0"] == pytest.approx(final[0.0], abs=1e-6)
    assert rows[-1]["val_psnr_15"] == pytest.approx(final[15.0], abs=1e-6)

    path = export_model(linear_run, tmp_path / "lin", storage="float32")
    assert json.loads(path.read_text())["config"]["data"]["domain"] == "linear"
    model = build_model(path, domain="linear")
    assert model.domain == "linear" and build_model(path).domain == "linear"
    assert _holds(model.network, "linear")
    exported = mean_psnr(model, held_out, [0.0], domain="linear")
    assert exported[0.0] == pytest.approx(final[0.0], abs=1e-6)
    with pytest.raises(ValueError, match="trained in the linear domain"):
        build_model(path, domain="srgb")
    with pytest.raises(ValueError, match="trained in the linear domain"):
        build_method(str(path), domain="srgb")
    with pytest.raises(ValueError, match="another light domain"):
        mean_psnr(model, held_out, [0.0])  # the srgb protocol, the default


def test_a_resume_keeps_the_domain(linear_run, images):
    config = tiny_config(images, linear_run, **{**LINEAR, "optim.steps": 6})
    with pytest.raises(ckpt_io.CheckpointError, match="data.domain='linear'"):
        train(config.override({"data.domain": "srgb"}), resume=True, progress=False)
    assert [r["step"] for r in _rows(linear_run)][-1] == 4  # nothing was written


def test_weights_from_an_srgb_run_train_on_with_linear_statistics(images, tmp_path):
    srgb = tmp_path / "srgb"
    train(tiny_config(images, srgb, **{**LINEAR, "data.domain": "srgb"}), progress=False)
    assert _holds(build_method(srgb).network, "srgb")
    linear = tmp_path / "linear"
    changes = {**LINEAR, "optim.steps": 1, "run.init_from": str(srgb)}
    train(tiny_config(images, linear, **changes), progress=False)
    assert _holds(build_method(linear, domain="linear").network, "linear")


def test_photon_noise_in_linear_light_from_the_command_line(images, tmp_path, capsys):
    """``splitcam train --noise photon --domain linear``: validation at each exposure in the
    linear domain, starting from the linear LMMSE under the photon model."""
    out = tmp_path / "run"
    flags = {
        "--data": images,
        "--out": out,
        "--domain": "linear",
        "--noise": "photon",
        "--val-split": 2,
        "--val-images": 2,
        "--val-crop": 32,
        "--patch-size": 16,
        "--batch-size": 4,
        "--features": 8,
        "--blocks": 1,
        "--steps": 4,
        "--warmup-steps": 2,
        "--log-every": 1,
        "--val-every": 4,
        "--checkpoint-every": 4,
        "--threads": 1,
    }
    args = [str(x) for pair in flags.items() for x in pair]
    photons = ["--photons", "20", "2000", "--val-photons", "30", "1000"]
    assert main(["train", *args, *photons, "--quiet"]) == 0
    config = TrainConfig.from_file(out / "config.json")
    assert (config.data.domain, config.noise.model) == ("linear", "photon")
    rows = [r for r in _rows(out) if "val_psnr_N30" in r]
    assert [r["step"] for r in rows] == [0, 4]
    levels = [Exposure(30.0), Exposure(1000.0)]
    lmmse = mean_psnr(
        closed_form_lmmse(patterns.get("D"), domain="linear"),
        val_images(config),
        levels,
        domain="linear",
    )
    assert rows[0]["val_psnr_N30"] == pytest.approx(lmmse[levels[0]], abs=1e-3)
    assert rows[0]["val_psnr_N1000"] == pytest.approx(lmmse[levels[1]], abs=1e-3)
    trained = build_method(out / "checkpoint.safetensors", domain="linear")  # the latest
    final = mean_psnr(trained, val_images(config), levels, domain="linear")
    assert rows[-1]["val_psnr_N30"] == pytest.approx(final[levels[0]], abs=1e-6)

    capsys.readouterr()
    bad = ["--data", str(images), "--out", str(tmp_path / "bad"), "--domain", "log", "--quiet"]
    assert main(["train", *bad]) == 1
    assert "data.domain must be one of srgb, linear" in capsys.readouterr().err
