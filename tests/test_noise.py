"""Training and evaluation noise."""

from __future__ import annotations

import pytest
import torch

from splitcam.physics.noise import (
    GaussianNoise,
    add_evaluation_noise,
    evaluation_noise,
    evaluation_seed,
)


def test_fixed_sigma_has_the_right_statistics():
    raw = torch.zeros(4, 1, 256, 256)
    noisy, sigma = GaussianNoise(10.0, seed=0)(raw)
    assert torch.all(sigma == 10.0)
    assert noisy.std().item() == pytest.approx(10 / 255, rel=0.01)
    assert abs(noisy.mean().item()) < 1e-3


def test_sigma_range_per_batch_and_per_sample():
    raw = torch.zeros(8, 1, 64, 64)
    noisy, sigma = GaussianNoise((5.0, 20.0), seed=1)(raw)
    assert torch.all(sigma == sigma[0]) and 5 <= sigma[0] <= 20
    noisy, sigma = GaussianNoise((5.0, 20.0), per_sample=True, seed=1)(raw)
    assert len(set(sigma.tolist())) == 8 and torch.all((sigma >= 5) & (sigma <= 20))
    per_image_std = noisy.flatten(1).std(dim=1) * 255
    torch.testing.assert_close(per_image_std, sigma, rtol=0.05, atol=0)


def test_seeded_and_resumable():
    raw = torch.zeros(2, 1, 8, 8)
    a, b = GaussianNoise(seed=3), GaussianNoise(seed=3)
    assert torch.equal(a(raw)[0], b(raw)[0])
    state = a.state_dict()
    first = a(raw)[0]
    c = GaussianNoise(seed=99)
    c.load_state_dict(state)
    assert torch.equal(c(raw)[0], first)
    assert not torch.equal(GaussianNoise(seed=4)(raw)[0], GaussianNoise(seed=5)(raw)[0])


def test_bad_sigma():
    for bad in [(-1.0, 2.0), (3.0, 2.0), (0.0, float("nan")), (0.0, float("inf"))]:
        with pytest.raises(ValueError, match="expected 0 <= sigma_lo <= sigma_hi"):
            GaussianNoise(bad)
    for bad in (-1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="expected a finite sigma >= 0"):
            evaluation_noise((1, 1, 2, 2), "x", bad)
    with pytest.raises(TypeError, match="sigma as a number"):
        evaluation_noise((1, 1, 2, 2), "x", "5")


def test_evaluation_noise_is_deterministic_and_per_image():
    a = evaluation_noise((1, 1, 32, 32), "kodim01", 10)
    assert torch.equal(a, evaluation_noise((1, 1, 32, 32), "kodim01", 10))
    assert torch.equal(a, evaluation_noise((1, 1, 32, 32), "kodim01", 10.0))
    assert not torch.equal(a, evaluation_noise((1, 1, 32, 32), "kodim02", 10))
    assert evaluation_seed("kodim01", 10) != evaluation_seed("kodim01", 15)
    # Same normalised draw at every sigma would correlate the noise levels; check they differ.
    b = evaluation_noise((1, 1, 32, 32), "kodim01", 20)
    assert not torch.allclose(b, 2 * a)
    raw = torch.ones(1, 1, 32, 32, dtype=torch.float64)
    assert torch.equal(add_evaluation_noise(raw, "kodim01", 0), raw)
    noisy = add_evaluation_noise(raw, "kodim01", 10)
    assert noisy.dtype == torch.float64
    torch.testing.assert_close((noisy - raw).float(), a, rtol=0, atol=1e-7)
