"""A new noise model is one module plus one table entry (splitcam.training.noise,
splitcam.physics.noise): a toy model written here, in the test, trains through ``splitcam
train``, simulates, reconstructs, evaluates and saves itself, with no library file touched."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import pytest
import torch
from conftest import tiny_config

from splitcam import patterns
from splitcam.cli import main
from splitcam.evaluation.protocol import mean_psnr
from splitcam.physics import noise as physics_noise
from splitcam.physics.noise import NoiseModel, noise_from_dict
from splitcam.physics.sensor import SplitterSensor
from splitcam.physics.system import simulate
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.registry import build_method
from splitcam.training import noise as training_noise


@dataclass(frozen=True)
class DarkGaussian(NoiseModel):
    """Gaussian read noise (8-bit sigma) plus a dark-current variance ``dark`` in raw units."""

    sigma: float
    dark: float = 1e-3

    def apply(self, raw: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        std = math.sqrt(sum(self.variance_coefficients()))
        noise = torch.randn(tuple(raw.shape), generator=generator, dtype=torch.float64)
        return raw + (std * noise).to(device=raw.device, dtype=raw.dtype)

    def variance_coefficients(self) -> tuple[float, float]:
        return 0.0, (self.sigma / 255.0) ** 2 + self.dark

    def label(self) -> str:
        return f"DG{self.sigma:g}"


def _levels(n: int, generator: torch.Generator) -> list[DarkGaussian]:
    return [DarkGaussian(float(s)) for s in 20.0 * torch.rand(n, generator=generator)]


@pytest.fixture
def toy(monkeypatch):
    entry = training_noise.NoiseType(
        sampler=lambda config: _levels,
        validation=lambda config: [DarkGaussian(5.0), DarkGaussian(15.0)],
    )
    monkeypatch.setitem(training_noise.TRAINING_NOISE, "dark-gaussian", entry)
    monkeypatch.setitem(physics_noise.NOISE_MODELS, "dark-gaussian", DarkGaussian)


def test_a_toy_noise_model_trains_simulates_reconstructs_and_evaluates(toy, image_folder, tmp_path):
    out = tmp_path / "run"
    steps = {"optim.steps": 4, "optim.warmup_steps": 2, "run.val_every": 4}
    config = tiny_config(image_folder, out, **steps, **{"run.checkpoint_every": 4})
    path = config.write(tmp_path / "toy.json")
    assert main(["train", "--config", str(path), "--noise", "dark-gaussian", "--quiet"]) == 0
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    validated = [r for r in rows if "val_psnr_DG5" in r]
    assert [r["step"] for r in validated] == [0, 4]
    # At step 0 the physics network is the LMMSE told this model's variance: the scores agree.
    level = DarkGaussian(10.0)
    d = patterns.get("D")
    scene = torch.rand(1, 3, 24, 30, generator=torch.Generator().manual_seed(2))
    raw = simulate(SplitterSensor(d), scene, "scene", level)
    assert float((raw - SplitterSensor(d)(scene)).var()) == pytest.approx(
        sum(level.variance_coefficients()), rel=0.15
    )
    net = build_method(str(out))
    assert net.reconstruct(raw, level).shape == (1, 3, 24, 30)
    images = [("scene", scene[0])]
    lmmse = mean_psnr(closed_form_lmmse(d), images, [level])
    assert set(lmmse) == {level} and math.isfinite(lmmse[level])
    # The level saves and loads itself.
    assert level.to_dict() == {"model": "dark-gaussian", "sigma": 10.0, "dark": 1e-3}
    assert noise_from_dict(level.to_dict()) == level


def test_the_table_refuses_unknown_models_with_the_known_ones(tmp_path, image_folder, capsys):
    assert main(["train", "--noise", "nope", "--data", str(image_folder), "--out",
                 str(tmp_path / "r"), "--steps", "1"]) != 0  # fmt: skip
    assert "noise.model must be gaussian or photon, got 'nope'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown noise model 'nope'; known: gaussian, photon"):
        noise_from_dict({"model": "nope"})


def test_the_shipped_models_save_and_load_themselves():
    from splitcam.physics.noise import Exposure, Gaussian

    for level in (Gaussian(15.0), Exposure(300.0, read_noise=3.0, gain=0.5, bits=10, dark=2.0)):
        saved = json.loads(json.dumps(level.to_dict()))
        assert noise_from_dict(saved) == level
    assert Gaussian(15.0).to_dict() == {"model": "gaussian", "sigma": 15.0}


def test_training_noise_draws_through_the_levels_own_batch_model():
    """The one training class: a step's levels from the sampler, the noise from the levels'
    apply_batch (the photon model's batch draw is Exposure.apply's, image by image)."""
    from splitcam.physics.noise import Exposure, LogUniformExposure, TrainingNoise

    raw = torch.full((3, 1, 16, 16), 0.5, dtype=torch.float64)
    noise = TrainingNoise(LogUniformExposure(50.0, 50.0, {"read_noise": 1.0}), seed=4)
    noisy, levels = noise(raw)
    assert len(set(levels)) == 1 and levels[0].photons == pytest.approx(50.0)
    assert levels[0].read_noise == 1.0 and isinstance(levels[0], Exposure)
    gen = torch.Generator().manual_seed(4)
    torch.rand(1, generator=gen, dtype=torch.float64)  # the level drawn first
    torch.testing.assert_close(noisy, Exposure.apply_batch(raw, levels, gen), rtol=0, atol=0)
    # one image at a time with one exposure = the batch draw on the same stream
    gen = torch.Generator().manual_seed(9)
    whole = levels[0].apply(raw, gen)
    torch.testing.assert_close(
        whole, Exposure.apply_batch(raw, levels, torch.Generator().manual_seed(9)), rtol=0, atol=0
    )
