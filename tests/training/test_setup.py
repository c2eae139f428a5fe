"""Building a run's system (splitcam.training.setup): designed starting kernels, metasurface
sensors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import blocky_images, tiny_config

from splitcam import patterns
from splitcam.io import checkpoints as ckpt_io
from splitcam.physics.optics import pattern_of
from splitcam.training import CheckpointError, load_system, train
from splitcam.training.config import ConfigError


def test_training_a_metasurface_with_the_network(tmp_path) -> None:
    """`train --metasurface random`: the height map is learned through the optics and the
    reconstruction; the run's checkpoint holds the pattern it makes."""
    from conftest import tiny_config

    from splitcam.physics.optics import MetasurfaceSensor
    from splitcam.training import build_system, train

    folder = blocky_images(tmp_path / "img", 4)
    config = tiny_config(
        folder,
        tmp_path / "run",
        **{"pattern.metasurface": "random", "optim.steps": 2, "pattern.lr": 0.5},
    )
    start = build_system(config).sensor
    assert isinstance(start, MetasurfaceSensor)
    train(config, progress=False)
    system = load_system(tmp_path / "run")
    learned = system.sensor.to_pattern()
    assert learned.provenance == "optics" and learned.kernels.sum((2, 3)).max() <= 1.0
    assert not np.allclose(learned.kernels, start.to_pattern().kernels, atol=1e-4)
    # the run exports the learned profile and the pattern it makes
    height = np.load(tmp_path / "run/height.npy")
    remade = pattern_of(torch.from_numpy(height), (2, 2), start.optics)  # the optics again
    np.testing.assert_allclose(remade.kernels, learned.kernels, atol=1e-5)
    assert (tmp_path / "run/height.png").is_file()
    from splitcam import patterns

    exported = patterns.load(tmp_path / "run/pattern.toml")
    np.testing.assert_allclose(exported.kernels, learned.kernels, atol=1e-6)
    with pytest.raises(Exception, match="metasurface"):
        build_system(
            tiny_config(
                folder, tmp_path / "x", **{"pattern.metasurface": str(tmp_path / "none.npy")}
            )
        )


def test_joint_run_with_design_steps_starts_from_the_designed_kernels(
    image_folder, tmp_path, monkeypatch
):
    """pattern.design_steps: the learned kernels start where `design` takes the initialisation
    (lower closed-form error than the support start), and a resume keeps the trained kernels
    instead of designing again."""
    from splitcam.design import design_pattern
    from splitcam.recon.closed_form import closed_form_mse
    from splitcam.training import setup
    from splitcam.training.setup import build_system

    learn = {"pattern.learn": True, "pattern.design_steps": 30, "optim.steps": 3}
    config = tiny_config(image_folder, tmp_path / "j", **learn)
    expected = design_pattern(
        patterns.get("D"), init="support", steps=30, seed=config.run.seed + 17
    )
    start = build_system(config).sensor.pixel_kernels().detach()
    support = (
        build_system(
            tiny_config(image_folder, tmp_path / "s", **{**learn, "pattern.design_steps": 0})
        )
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
        tiny_config(image_folder, tmp_path / "j", **{**learn, "optim.steps": 4}),
        resume=True,
        progress=False,
    )
    assert ckpt_io.load(tmp_path / "j").meta["step"] == 4
    with pytest.raises(CheckpointError, match="design_steps"):
        train(
            tiny_config(
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


def _rg_correlation(mean: torch.Tensor, second: torch.Tensor) -> float:
    """Correlation of red and green at one pixel, from first and second moments."""
    c = second.shape[-1] // 2
    var_r = second[0, 0, c, c] - mean[0] ** 2
    var_g = second[1, 1, c, c] - mean[1] ** 2
    return float((second[0, 1, c, c] - mean[0] * mean[1]) / (var_r * var_g).sqrt())


def test_colour_statistics_give_the_network_a_prior_of_free_colour(tmp_path) -> None:
    """data.colour_statistics: the LMMSE inside the network is solved from the statistics of
    the photos and their chroma-moved copies: red and green correlate less than in the photos'
    own statistics (estimated independently here), and a resumed run keeps them."""
    from PIL import Image

    from splitcam.data.patches import ImageCache
    from splitcam.recon.closed_form import estimate_image_statistics

    # Muted photos: one texture in every channel, a little colour (red and green correlate).
    data = tmp_path / "img"
    data.mkdir()
    rng = np.random.default_rng(0)
    for i in range(6):
        grey = rng.uniform(40, 215, (10, 12)).repeat(8, 0).repeat(8, 1)[:72, :90]
        tint = rng.uniform(-12, 12, 3)
        rgb = np.stack([grey + t for t in tint], -1) + rng.normal(0, 3, (72, 90, 3))
        Image.fromarray(rgb.clip(0, 255).astype(np.uint8)).save(data / f"{i}.png")
    settings = {"optim.steps": 2, "run.val_every": 1000, "data.colour_statistics": True}
    config = tiny_config(data, tmp_path / "r", **settings)
    train(config, progress=False)
    system = load_system(tmp_path / "r")
    mean, second = system.network.stat_mean.double(), system.network.stat_second.double()
    cache = ImageCache(data, min_size=16, progress=False)
    own = estimate_image_statistics(
        [cache.image(i) for i in range(len(cache))], max_offset=second.shape[-1] // 2
    )
    assert _rg_correlation(mean, second) < _rg_correlation(own.mean, own.second) - 0.005
    resumed = config.override({"optim.steps": 3})
    train(resumed, resume=True, progress=False)
    again = load_system(tmp_path / "r").network
    assert torch.equal(again.stat_second.double(), second)


def test_photo_statistics_are_the_photos_as_the_run_keeps_them(tmp_path) -> None:
    """data.photo_statistics: the LMMSE inside the network is solved from the statistics of the
    run's own training photos at its data.scales (estimated independently here from the same
    files at half size), also when the run starts from another's weights, whose statistics
    (the shipped ones) it would otherwise take."""
    from PIL import Image

    from splitcam.data.patches import ImageCache, list_images
    from splitcam.recon.closed_form import estimate_image_statistics, shipped_image_statistics
    from splitcam.training.validation import held_out

    data = tmp_path / "img"
    data.mkdir()
    rng = np.random.default_rng(0)
    for i in range(6):  # 96x96: a 33x33 window fits at half size; noise: a full-rank prior
        img = np.kron(rng.random((12, 12, 3)), np.ones((8, 8, 1))) * 230 + 10
        img += rng.normal(0, 6, img.shape)
        Image.fromarray(img.clip(0, 255).astype(np.uint8)).save(data / f"im{i}.png")
    first = tiny_config(data, tmp_path / "a", **{"optim.steps": 2, "run.val_every": 1000})
    train(first, progress=False)
    settings = {
        "data.photo_statistics": True,
        "data.scales": [0.5],
        "run.init_from": str(first.run.out),
    }
    config = first.override({**settings, "run.out": str(tmp_path / "b")})
    result = train(config, progress=False)
    assert not result.failure, result.failure
    network = load_system(tmp_path / "b").network
    files = [f for f in list_images(data) if f not in held_out(config)]
    lo = network.stat_second.shape[-1] // 2
    cache = ImageCache(files, min_size=2 * lo + 2, scales=[0.5], progress=False)
    own = estimate_image_statistics(cache, max_offset=lo)
    torch.testing.assert_close(network.stat_second.double(), own.second.double())
    torch.testing.assert_close(network.stat_mean.double(), own.mean.double())
    shipped = shipped_image_statistics()
    assert not torch.allclose(network.stat_second.double(), shipped.second.double(), atol=1e-4)
    # A run from it without the setting keeps them: the statistics come with the weights.
    after = config.override(
        {
            "data.photo_statistics": False,
            "run.init_from": str(tmp_path / "b"),
            "run.out": str(tmp_path / "d"),
        }
    )
    assert not train(after, progress=False).failure
    kept = load_system(tmp_path / "d").network
    assert torch.equal(kept.stat_second, network.stat_second)
    # Photos too small for the statistics' window at that size: one line saying so.
    small = blocky_images(tmp_path / "small", 4)  # 48x48: 24x24 at half size
    config = config.override({"data.train": str(small), "run.out": str(tmp_path / "c")})
    with pytest.raises(ConfigError, match=r"data.photo_statistics: .*33x33.*at 0.5 of their size"):
        train(config, progress=False)
