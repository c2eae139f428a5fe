"""One network for any pattern (SPEC section 16): the random-pattern generator, the universal
network, and training over random patterns."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from conftest import blocky_images, tiny_config

from splitcam import patterns
from splitcam.patterns.random import FAMILIES, MIN_COLOUR_SHARE, PatternMix, random_pattern
from splitcam.physics.noise import Exposure
from splitcam.physics.sensor import SplitterSensor, SwitchingSensor, pattern_pixel_kernels
from splitcam.recon.base import NetworkReconstructor
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.networks import PhysicsReconNet, UniversalReconNet, build_network


def _scene(n: int = 2, h: int = 37, w: int = 43, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, h + 4, w + 4, generator=g)
    return torch.nn.functional.avg_pool2d(x, 5, stride=1)


def _trained_like(net: torch.nn.Module, seed: int = 0) -> torch.nn.Module:
    """Random weights everywhere (the zero-initialised tail included), as after training."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(0.05 * torch.randn(p.shape, generator=g))
    return net


# --- the generator ----------------------------------------------------------------------------


def test_random_patterns_are_valid_over_many_draws() -> None:
    rng = np.random.default_rng(0)
    families, periods, sizes = set(), set(), set()
    for _ in range(600):
        p = random_pattern(rng)
        # Re-validating through the constructor checks non-negativity and sums <= 1 again.
        patterns.Pattern(p.name, p.layout, p.kernels)
        k = p.kernels
        assert (k >= 0).all() and (k.sum((2, 3)) <= 1 + 1e-9).all()
        assert set(np.unique(p.layout)) == set(range(p.num_splitters))  # every splitter used
        # Every colour reaches the sensor: of a flat scene, each colour's mean collected share.
        share = k[p.layout].sum((-1, -2)).reshape(-1, 3).mean(0)
        assert share.min() >= MIN_COLOUR_SHARE
        assert 1 <= min(p.period) and max(p.period) <= 4
        assert max(p.kernel_size) <= 5
        families.add(p.description.split()[1])
        periods.add(p.period)
        sizes.add(p.kernel_size)
    assert families == set(FAMILIES)
    assert (4, 4) in periods and (1, 1) in periods and (1, 3) in periods
    assert (5, 5) in sizes and (1, 1) in sizes


def test_random_patterns_are_a_function_of_the_seed() -> None:
    a = random_pattern(np.random.default_rng(7))
    b = random_pattern(np.random.default_rng(7))
    assert a.equals(b)
    mix = PatternMix([patterns.get("D")], 0.5, seed=3)
    assert all(mix.pattern(t).equals(mix.pattern(t)) for t in range(20))
    named = sum(mix.pattern(t).name == "D" for t in range(400))
    assert 150 < named < 250  # half the steps, within about 5 standard deviations


def test_random_pattern_rejects_bad_limits() -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="max_kernel"):
        random_pattern(rng, max_kernel=4)
    with pytest.raises(ValueError, match="families"):
        random_pattern(rng, families=("lens",))
    with pytest.raises(ValueError, match="named pattern"):
        PatternMix([], 0.5)


# --- the network ------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(4))
def test_untrained_universal_network_is_the_lmmse_of_any_pattern(seed: int) -> None:
    pattern = random_pattern(np.random.default_rng(100 + seed))
    raw = SplitterSensor(pattern)(_scene(seed=seed)) + 0.02 * torch.randn(2, 1, 37, 43)
    net = UniversalReconNet(features=8, blocks=1)
    out = net(raw, 5.0, pattern_pixel_kernels(pattern))
    # The tiled LMMSE reconstructor applies the closed-form filters on its own code path.
    expected = closed_form_lmmse(pattern).reconstruct(raw, 5.0)
    torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-5)


def test_same_output_for_an_equivalent_layout() -> None:
    """Pattern D written with a 4x4 period (its 2x2 period repeated) is the same sensor."""
    d = patterns.get("D")
    d4 = patterns.Pattern("D4", np.tile(d.layout, (2, 2)), d.kernels)
    rgb = _scene(h=38, w=41)
    raw = SplitterSensor(d)(rgb)
    torch.testing.assert_close(raw, SplitterSensor(d4)(rgb))
    net = _trained_like(UniversalReconNet(features=8, blocks=1)).eval()
    out = net(raw, 10.0, pattern_pixel_kernels(d))
    out4 = net(raw, 10.0, pattern_pixel_kernels(d4))
    torch.testing.assert_close(out, out4, rtol=1e-4, atol=1e-5)


def test_with_a_physics_trunk_it_computes_the_physics_network() -> None:
    """Started from a 2x2 physics network (the extra inputs weighted 0) it is that network."""
    physics = _trained_like(PhysicsReconNet((2, 2), features=8, blocks=1), seed=1).eval()
    universal = UniversalReconNet(features=8, blocks=1).eval()
    universal.load_physics_trunk(physics.state_dict())
    raw = SplitterSensor("A")(_scene(h=36, w=40))
    k = pattern_pixel_kernels("A")
    torch.testing.assert_close(universal(raw, 7.0, k), physics(raw, 7.0, k), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="2x2-period physics"):
        UniversalReconNet(features=8, blocks=1).load_physics_trunk(
            PhysicsReconNet((1, 3), features=8, blocks=1).state_dict()
        )


@pytest.mark.parametrize("size", [(33, 35), (64, 61), (2, 3)])
def test_tiles_equal_the_whole_image_for_any_period_and_size(size: tuple[int, int]) -> None:
    pattern = random_pattern(np.random.default_rng(5), max_period=4)
    while pattern.period[1] % 2 == 0:  # a period the 2x2 cells do not divide
        pattern = random_pattern(np.random.default_rng(int(pattern.kernels.sum() * 1e6)))
    net = _trained_like(UniversalReconNet(features=6, blocks=1)).eval()
    raw = SplitterSensor(pattern)(_scene(1, *size))
    whole = NetworkReconstructor(net, pattern, "u", tile=None, precision="fp32")
    tiled = NetworkReconstructor(net, pattern, "u", tile=net.receptive_radius * 2 + 12)
    tiled.precision = "fp32"
    expected = whole.reconstruct(raw, 3.0)
    assert expected.shape == (1, 3, *size)
    torch.testing.assert_close(tiled.reconstruct(raw, 3.0), expected, rtol=1e-4, atol=1e-5)


def test_photon_noise_levels_are_accepted() -> None:
    pattern = patterns.get("E")
    raw = SplitterSensor(pattern)(_scene())
    net = UniversalReconNet(features=8, blocks=1)
    exposures = [Exposure(30.0, read_noise=2.0), Exposure(300.0, read_noise=2.0)]
    out = net(raw, exposures, pattern_pixel_kernels(pattern))
    expected = torch.cat(
        [closed_form_lmmse(pattern).reconstruct(raw[i : i + 1], e) for i, e in enumerate(exposures)]
    )
    torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-5)


def test_gradients_reach_the_kernels() -> None:
    """Through the LMMSE estimate, the residual and the kernel encoder."""
    pattern = patterns.get("A")
    net = _trained_like(UniversalReconNet(features=8, blocks=1))
    rgb = _scene()
    kernels = pattern_pixel_kernels(pattern).clone().requires_grad_(True)
    raw = SplitterSensor(pattern)(rgb)
    loss = (net(raw, 4.0, kernels) - rgb).square().mean()
    loss.backward()
    assert kernels.grad is not None and kernels.grad.abs().sum() > 0
    # And the encoder's path on its own.
    k2 = pattern_pixel_kernels(pattern).clone().requires_grad_(True)
    net.kernel_features(k2).sum().backward()
    assert k2.grad.abs().sum() > 0


def test_bad_kernels_are_refused() -> None:
    net = UniversalReconNet(features=4, blocks=0)
    raw = torch.rand(1, 1, 8, 8)
    with pytest.raises(ValueError, match="up to 5x5"):
        net(raw, 0.0, torch.rand(2, 2, 3, 7, 7) / 50)
    with pytest.raises(ValueError, match="noise level"):
        net(raw)


def test_config_round_trip() -> None:
    net = UniversalReconNet(features=8, blocks=2, embed=4)
    again = build_network(net.config())
    assert again.config() == net.config()
    assert isinstance(again, UniversalReconNet)
    with pytest.raises(ValueError, match="unknown network config"):
        build_network({**net.config(), "colours": 4})


def test_switching_sensor_changes_pattern_without_saving_it() -> None:
    sensor = SwitchingSensor("D")
    rgb = _scene()
    for name in ("A", "E", "bayer"):
        sensor.set_pattern(name)
        torch.testing.assert_close(sensor(rgb), SplitterSensor(name)(rgb))
        assert sensor.period == patterns.get(name).period
    assert sensor.state_dict() == {}


# --- training ---------------------------------------------------------------------------------


def test_training_over_random_patterns_and_resume(tmp_path) -> None:
    from splitcam.training import train

    data = blocky_images(tmp_path / "img", 6)
    settings = {
        "pattern.name": "random",
        "pattern.mix": ["D", "bayer"],
        "pattern.val_patterns": ["D", "E"],
        "network.arch": "universal",
        "optim.steps": 6,
    }
    config = tiny_config(data, tmp_path / "run", **settings)
    result = train(config, progress=False)
    assert result.step == 6
    rows = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").open()]
    val = [r for r in rows if "val_psnr_D_0" in r]
    assert val and all("val_psnr_E_15" in r for r in val)
    assert val[-1]["val_psnr_0"] == pytest.approx(
        (val[-1]["val_psnr_D_0"] + val[-1]["val_psnr_E_0"]) / 2
    )
    # Resuming continues with the patterns of the later steps.
    more = tiny_config(data, tmp_path / "run", **{**settings, "optim.steps": 9})
    assert train(more, resume=True, progress=False).step == 9


def test_random_pattern_needs_the_universal_network(tmp_path) -> None:
    from splitcam.training import ConfigError

    config = tiny_config(tmp_path, tmp_path / "run", **{"pattern.name": "random"})
    with pytest.raises(ConfigError, match="--arch universal"):
        config.validate()


# --- using it: models, the CLI, fine-tuning, design ---------------------------------------------


@pytest.fixture(scope="module")
def tiny_universal(tmp_path_factory):
    """A tiny universal network trained a few steps over random patterns, exported as a model;
    its training images."""
    from splitcam.training import train
    from splitcam.training.models import export_model

    root = tmp_path_factory.mktemp("universal")
    data = blocky_images(root / "img", 6)
    settings = {"pattern.name": "random", "network.arch": "universal", "optim.steps": 3}
    train(tiny_config(data, root / "run", **settings), progress=False)
    model = export_model(root / "run", root / "models" / "uni", name="uni")
    return model, data


def test_model_for_any_pattern_needs_a_pattern_and_names_a_bad_file(tiny_universal, tmp_path):
    from splitcam.recon.registry import build_method, build_model

    model, _ = tiny_universal
    with pytest.raises(ValueError, match="reconstructs any pattern"):
        build_model(model)
    missing = tmp_path / "mine.toml"
    with pytest.raises(patterns.PatternError, match="mine.toml"):
        build_model(model, pattern=str(missing))
    # A pattern file: the label names the file, the reconstruction is that pattern's.
    mine = random_pattern(np.random.default_rng(3))
    patterns.save(mine, tmp_path / "mine.toml")
    method = build_method(str(model), pattern=str(tmp_path / "mine.toml"), precision="fp32")
    assert method.name == "net-uni-mine.toml" and method.pattern.equals(mine)
    raw = SplitterSensor(mine)(_scene(1, 21, 19))
    assert method.reconstruct(raw, 5.0).shape == (1, 3, 21, 19)
    other = build_method(str(model), pattern="D", precision="fp32")
    assert other.fingerprint != method.fingerprint


def test_cli_reconstruct_and_evaluate_with_a_universal_model(tiny_universal, tmp_path, capsys):
    from PIL import Image

    from splitcam.cli import main

    model, data = tiny_universal
    photo = next(data.iterdir())
    out = tmp_path / "rec.png"
    args = ["reconstruct", "--model", str(model), "--image", str(photo), "--out", str(out)]
    assert main([*args, "--pattern", "E", "--sigma", "5", "--quiet"]) == 0
    with Image.open(out) as im:
        assert im.size == (48, 48)
    assert main([*args, "--pattern", str(tmp_path / "nope.toml")]) == 1
    assert "nope.toml" in capsys.readouterr().err
    mine = tmp_path / "mine.toml"
    patterns.save(random_pattern(np.random.default_rng(4)), mine)
    ev = ["evaluate", "--model", str(model), "--patterns", f"D,{mine}", "--datasets", str(data)]
    assert main([*ev, "--sigmas", "0", "--out", str(tmp_path / "ev"), "--quiet"]) == 0
    table = capsys.readouterr().out
    assert "net-uni-D" in table and "net-uni-mine.toml" in table


def test_main_job_uses_the_universal_network_for_patterns_without_one(
    tiny_universal, tmp_path, capsys, monkeypatch
):
    """`splitcam evaluate --patterns FILE`: a pattern no shipped network serves gets the
    shipped universal network, and the output says so."""
    import shutil

    from splitcam.cli import main
    from splitcam.io import weights

    model, data = tiny_universal
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    for suffix in (".json", ".safetensors"):
        shutil.copy(model.with_suffix(suffix), shipped / f"universal{suffix}")
    monkeypatch.setattr(weights, "MODELS_DIR", shipped)
    mine = tmp_path / "mine.toml"
    patterns.save(random_pattern(np.random.default_rng(5)), mine)
    ev = ["evaluate", "--patterns", str(mine), "--datasets", str(data), "--sigmas", "0"]
    assert main([*ev, "--out", str(tmp_path / "ev"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"pattern {mine} has no shipped network: reconstructed by the universal network" in out
    assert "net-uni-mine.toml" in out and "lmmse-mine.toml" in out  # labelled by its own name


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
    # No --steps, --time-limit or --lr: the default fine-tuning budget and rate, announced.
    from splitcam.cli.train import FINE_TUNE_LR, FINE_TUNE_MINUTES, fine_tuning

    capsys.readouterr()
    implied = fine_tuning(str(model), {})
    assert implied["run.time_limit"] == FINE_TUNE_MINUTES and implied["optim.lr"] == FINE_TUNE_LR
    assert f"for {FINE_TUNE_MINUTES:g} minutes" in capsys.readouterr().out
    given = fine_tuning(str(model), {"run.time_limit": 1.0, "optim.lr": 1e-3})
    assert "run.time_limit" not in given and "optim.lr" not in given
    assert fine_tuning("D", {}) == {}  # a network of one pattern implies nothing


def test_design_against_a_frozen_network(tiny_universal):
    """`design --objective network`: the pattern moves to raise the network's PSNR; gradients
    reach the logits through the frozen network."""
    from splitcam.data.patches import ImageCache, PatchSampler, list_images
    from splitcam.design import design_pattern, network_psnr
    from splitcam.recon.loading import load_model

    model, data = tiny_universal
    system = load_model(model)
    files = list_images(data)
    sampler = PatchSampler(ImageCache(files, min_size=16, progress=False), patch_size=16)
    before = [p.detach().clone() for p in system.network.parameters()]
    result = design_pattern(
        "D",
        objective="network",
        network=system.network,
        patches=sampler,
        sigmas=[0, 10],
        steps=15,
        lr=0.1,
    )
    assert not result.pattern.equals(result.start)  # the kernels moved
    assert all(torch.equal(a, b) for a, b in zip(before, system.network.parameters(), strict=True))
    # On a fixed batch, at the objective's noise levels, the network does better on the design.
    held = PatchSampler(ImageCache(files, min_size=16, progress=False), patch_size=16, seed=9)
    held = held.sample(32)
    before_db = network_psnr(result.start, system.network, held, [0, 10])
    after_db = network_psnr(result.pattern, system.network, held, [0, 10])
    assert sum(after_db.values()) > sum(before_db.values())
    with pytest.raises(ValueError, match="needs a network"):
        design_pattern("D", objective="network", steps=1)
