"""Noise (splitcam.physics.noise): Gaussian training and evaluation noise, and the photon-limited
sensor model (model.md §11)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.physics.noise import (
    Exposure,
    Gaussian,
    GaussianNoise,
    PhotonNoise,
    add_evaluation_noise,
    add_exposure_noise,
    evaluation_noise,
    evaluation_seed,
)
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.closed_form import (
    closed_form_filters,
)


def test_fixed_sigma_has_the_right_statistics():
    raw = torch.zeros(4, 1, 256, 256)
    noisy, levels = GaussianNoise(10.0, seed=0)(raw)
    assert levels == [Gaussian(10.0)] * 4  # the objects evaluation uses
    assert noisy.std().item() == pytest.approx(10 / 255, rel=0.01)
    assert abs(noisy.mean().item()) < 1e-3


def test_sigma_range_per_batch_and_per_sample():
    raw = torch.zeros(8, 1, 64, 64)
    noisy, levels = GaussianNoise((5.0, 20.0), seed=1)(raw)
    assert len(set(levels)) == 1 and 5 <= levels[0].sigma <= 20
    noisy, levels = GaussianNoise((5.0, 20.0), per_sample=True, seed=1)(raw)
    sigma = torch.tensor([level.sigma for level in levels])
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


def _flat(value: float, size: int = 400) -> torch.Tensor:
    return torch.full((1, 1, size, size), value, dtype=torch.float64)


def test_shot_noise_has_poisson_mean_and_variance() -> None:
    exposure = Exposure(300.0, read_noise=0.0)  # g = 1 -> 100 electrons
    out = exposure.apply(_flat(1.0), torch.Generator().manual_seed(1))
    electrons = out * 100.0
    assert torch.allclose(electrons, electrons.round(), atol=1e-9)  # whole electrons
    assert float(electrons.mean()) == pytest.approx(100.0, rel=0.005)
    assert float(electrons.var()) == pytest.approx(100.0, rel=0.03)  # Poisson: var = mean
    a, b = exposure.variance_coefficients()
    assert float(out.var()) == pytest.approx(a * 1.0 + b, rel=0.03)


def test_read_and_quantisation_noise_add_their_variance() -> None:
    exposure = Exposure(300.0, read_noise=5.0, gain=3.0, bits=16)
    out = exposure.apply(_flat(0.5), torch.Generator().manual_seed(2))
    dn = out * 100.0 / 3.0
    assert torch.allclose(dn, dn.round(), atol=1e-9)  # an ADC output: whole DN times the gain
    a, b = exposure.variance_coefficients()
    # 0.5 -> 50 e-: shot 50 + read 25 + quantisation 3^2/12, in raw units (3/300)^2.
    assert a * 0.5 + b == pytest.approx((50 + 25 + 9 / 12) * (3 / 300) ** 2, rel=1e-12)
    assert float(out.var()) == pytest.approx(a * 0.5 + b, rel=0.03)


def test_full_well_and_adc_range_saturate() -> None:
    gen = torch.Generator().manual_seed(3)
    full = Exposure(300.0, read_noise=0.0, full_well=60.0).apply(_flat(1.0, 50), gen)
    assert float(full.max()) == pytest.approx(60.0 * 3 / 300)  # 100 e- clipped at 60
    # Read noise is added after the well: a full pixel reads 60 e- give or take 1 e-.
    read = Exposure(300.0, read_noise=1.0, full_well=60.0).apply(_flat(1.0, 100), gen) * 100
    assert float(read.mean()) == pytest.approx(60.0, abs=0.05)
    assert float(read.std()) == pytest.approx(1.0, rel=0.05)
    adc = Exposure(300.0, read_noise=0.0, gain=1.0, bits=6).apply(_flat(1.0, 50), gen)
    assert float(adc.max()) == pytest.approx(63 * 3 / 300)  # 2^6 - 1 DN at 1 e-/DN
    dark = Exposure(300.0, read_noise=3.0, gain=1.0).apply(_flat(0.0, 50), gen)
    assert float(dark.min()) == 0.0  # the ADC clips at 0


def test_a_black_level_keeps_read_noise_below_zero() -> None:
    """Without a black level the ADC clips a dark pixel's read noise at 0 DN: its mean is that
    of ``max(0, round(X))`` for X ~ N(0, 2^2) e⁻ at 1 e⁻/DN, summed here from the normal
    distribution. A pedestal of 64 DN keeps the noise whole: mean 0, variance read^2 + 1/12.
    The top of the range moves down by the pedestal."""
    gen = torch.Generator().manual_seed(11)

    def phi(x: float) -> float:
        return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))

    clipped_mean = sum(k * (phi((k + 0.5) / 2.0) - phi((k - 0.5) / 2.0)) for k in range(1, 40))
    dark = _flat(0.0, 500)
    clipped = Exposure(300.0, read_noise=2.0, gain=1.0).apply(dark, gen) * 100.0  # e-
    assert float(clipped.mean()) == pytest.approx(clipped_mean, abs=0.01)  # about 0.80 e-
    kept = Exposure(300.0, read_noise=2.0, gain=1.0, black=64)
    electrons = kept.apply(dark, gen) * 100.0
    assert float(electrons.mean()) == pytest.approx(0.0, abs=0.01)
    assert float(electrons.min()) < -4.0  # below zero, in whole DN
    assert torch.allclose(electrons, electrons.round(), atol=1e-9)
    a, b = kept.variance_coefficients()
    assert float(electrons.var()) == pytest.approx(b * 100.0**2, rel=0.02)  # 4 + 1/12 e-^2
    bright = Exposure(300.0, read_noise=0.0, gain=1.0, bits=8, black=64).apply(_flat(3.0, 20), gen)
    assert float(bright.max()) * 100.0 == pytest.approx(255 - 64)  # 300 e-: 364 DN, clipped at 255
    plain = Exposure(300.0, read_noise=2.0, gain=1.0)
    assert plain.key() == "N300|r2|fwNone|g1.0|b12|s1" and kept.key() == plain.key() + "|k64"
    assert "black" not in plain.sensor_settings() and kept.sensor_settings()["black"] == 64
    for bad in ({"black": 8}, {"black": -1, "gain": 1.0}, {"black": 4095, "gain": 1.0}):
        with pytest.raises(ValueError, match="black"):
            Exposure(300.0, **bad)
    with pytest.raises(ValueError, match="black"):
        Exposure(300.0, gain=1.0, black=2.5)


def test_a_full_well_leaves_dim_pixels_unbiased() -> None:
    """The well saturates collected electrons, not the readout: at 1 e- a pixel with a full
    well reads the same mean and spread as one without (read noise below zero kept, as a
    sensor's black level keeps it), where clipping the readout at 0 would raise the mean."""
    raw = _flat(0.03, 200)  # 0.03 of the raw scale at N = 100: 1 e- a pixel
    a = Exposure(100.0, read_noise=2.0).apply(raw, torch.Generator().manual_seed(5))
    b = Exposure(100.0, read_noise=2.0, full_well=6000.0).apply(
        raw, torch.Generator().manual_seed(5)
    )
    assert torch.equal(a, b)
    assert float(b.mean()) == pytest.approx(0.03, abs=0.002)  # clipped at 0 it would be ~0.049


def test_evaluation_noise_is_deterministic_per_image_and_exposure() -> None:
    raw = torch.rand(1, 1, 32, 32, generator=torch.Generator().manual_seed(4))
    e = Exposure(100.0)
    a = add_exposure_noise(raw, "kodim01", e)
    assert torch.equal(a, add_exposure_noise(raw, "kodim01", e))
    assert not torch.equal(a, add_exposure_noise(raw, "kodim02", e))
    assert not torch.equal(a, add_exposure_noise(raw, "kodim01", Exposure(200.0)))


def test_equal_exposure_pattern_a_red_pixel_gathers_four_times_bayer() -> None:
    """On a white scene the R pixel of pattern A collects 4 times the light of a Bayer R pixel
    at the same exposure (model.md §11): 4N/3 against N/3 photo-electrons."""
    white = torch.ones(1, 3, 12, 12, dtype=torch.float64)
    exposure = Exposure(300.0, read_noise=0.0, shot=False)
    gen = torch.Generator().manual_seed(0)
    a = exposure.apply(SplitterSensor("A")(white), gen) * exposure.electrons_per_unit
    bayer = exposure.apply(SplitterSensor("bayer")(white), gen) * exposure.electrons_per_unit
    assert float(bayer[0, 0, 4, 4]) == pytest.approx(100.0)  # bayer R at (0, 0) of its period
    interior = a[0, 0, 4:8, 4:8]
    assert float(interior.max()) == pytest.approx(400.0)  # A's R (and B) pixels: 4N/3
    assert float(interior.max()) / float(bayer[0, 0, 4, 4]) == pytest.approx(4.0)


def test_without_shot_noise_and_adc_it_is_the_gaussian_model() -> None:
    sigma, photons = 12.0, 500.0
    exposure = Exposure(photons, read_noise=photons * sigma / (3 * 255), shot=False)
    assert exposure.variance_coefficients() == pytest.approx((0.0, (sigma / 255) ** 2))
    clean = _flat(0.7)
    noise = exposure.apply(clean, torch.Generator().manual_seed(5)) - clean
    assert float(noise.std()) == pytest.approx(sigma / 255, rel=0.01)
    assert abs(float(noise.mean())) < 3 * sigma / 255 / 400
    weights, bias = closed_form_filters(patterns.get("D"), exposure)
    w_g, b_g = closed_form_filters(patterns.get("D"), sigma)
    torch.testing.assert_close(weights, w_g, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(bias, b_g, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"photons": -1.0}, "photons"),
        ({"photons": 0.0}, "photons"),
        ({"photons": math.inf}, "photons"),
        ({"photons": 10.0, "read_noise": -1.0}, "read_noise"),
        ({"photons": 10.0, "gain": 0.0}, "gain"),
        ({"photons": 10.0, "full_well": -5.0}, "full_well"),
        ({"photons": 10.0, "bits": 0}, "bits"),
    ],
)
def test_bad_parameters_are_refused(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        Exposure(**kwargs)


def test_training_draws_exposures_log_uniformly_and_resumes() -> None:
    noise = PhotonNoise((10.0, 1e4), per_sample=True, seed=3)
    raw = torch.full((400, 1, 2, 2), 0.5)
    _, exposures = noise(raw)
    logs = np.log10([e.photons for e in exposures])
    assert logs.min() >= 1 - 1e-6 and logs.max() <= 4 + 1e-6
    assert abs(np.mean(logs) - 2.5) < 0.1 and abs(np.mean(logs < 2) - 1 / 3) < 0.08
    state = noise.state_dict()
    a = noise(raw[:4])
    noise.load_state_dict(state)
    b = noise(raw[:4])
    assert torch.equal(a[0], b[0]) and a[1] == b[1]
    with pytest.raises(ValueError, match="lo <= hi"):
        PhotonNoise((100.0, 10.0))


def test_linear_white_gives_n_photo_electrons_in_a_lossless_filterless_pixel() -> None:
    """model.md §11 and 13: an 8-bit white scene decodes to linear radiance 1 in every colour; a
    pixel with no filter and no loss (all three colours' light lands on it) then collects N
    photo-electrons at exposure N on average, with Poisson shot noise (variance N)."""
    from splitcam.patterns import Pattern
    from splitcam.physics.light import decode_scene

    white = decode_scene(torch.full((1, 3, 48, 48), 255 / 255, dtype=torch.float64), "linear")
    assert torch.equal(white, torch.ones_like(white))
    bare = Pattern("bare", [[0]], np.ones((1, 3, 1, 1)))
    raw = SplitterSensor(bare).double()(white)
    exposure = Exposure(250.0, read_noise=0.0)
    clean = exposure.electrons_per_unit * raw
    assert torch.allclose(clean, torch.full_like(clean, 250.0))
    electrons = exposure.apply(raw, torch.Generator().manual_seed(5)) * exposure.electrons_per_unit
    assert float(electrons.mean()) == pytest.approx(250.0, rel=0.01)
    assert float(electrons.var()) == pytest.approx(250.0, rel=0.1)
    assert torch.allclose(electrons, electrons.round(), rtol=0, atol=1e-9)  # whole electrons


# --- training noise drawn where the batch is ------------------------------------------------

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def test_gaussian_training_noise_on_the_cpu_is_the_one_stream() -> None:
    """On the CPU the noise field comes from the sigma generator, after the sigma: the stream
    CPU runs have always drawn (a naive re-draw in that order gives the same numbers)."""
    raw = torch.zeros(3, 1, 8, 8)
    noisy, levels = GaussianNoise((0.0, 30.0), seed=7)(raw)
    gen = torch.Generator().manual_seed(7)
    expected_sigma = 30.0 * torch.rand(1, generator=gen, dtype=torch.float64)
    field = torch.randn(raw.shape, generator=gen, dtype=torch.float32)
    assert levels == [Gaussian(float(expected_sigma.float()))] * 3
    torch.testing.assert_close(noisy, field * (expected_sigma.float() / 255))
    assert GaussianNoise(seed=7).state_dict().keys() == {"generator"}


@pytest.mark.parametrize("device", DEVICES)
def test_batched_photon_noise_matches_the_exposure_model(device) -> None:
    """The whole batch at once, one exposure per image, on the noise's device: per image the
    mean and the variance a g + b of :meth:`Exposure.variance_coefficients`."""
    noise = PhotonNoise((30.0, 3000.0), per_sample=True, seed=11, read_noise=3.0, device=device)
    g = 0.4
    raw = torch.full((6, 1, 96, 96), g, device=device)
    out, exposures = noise(raw)
    assert out.device.type == device and len({e.photons for e in exposures}) == 6
    for image, exposure in zip(out.double().cpu(), exposures, strict=True):
        a, b = exposure.variance_coefficients()
        assert float(image.mean()) == pytest.approx(
            g, abs=4 * math.sqrt((a * g + b) / image.numel())
        )
        assert float(image.var()) == pytest.approx(a * g + b, rel=0.06)


def test_batched_photon_noise_saturates_and_quantises_like_one_exposure() -> None:
    gen = torch.Generator().manual_seed(12)
    settings = {"read_noise": 1.0, "full_well": 60.0, "gain": 2.0, "bits": 5}
    from splitcam.physics.noise import photon_noise

    exposures = [Exposure(300.0, **settings), Exposure(150.0, **settings)]
    out = photon_noise(torch.full((2, 1, 40, 40), 1.0, dtype=torch.float64), exposures, gen)
    for image, e in zip(out, exposures, strict=True):
        dn = image * e.electrons_per_unit / 2.0
        assert torch.allclose(dn, dn.round(), atol=1e-9)  # whole DN times the gain
        # 100 or 50 e- collected, the well holds 60 (30 DN); 1 e- of read noise after it.
        held = min(e.photons / 3, 60.0) / 2.0
        assert float(dn.mean()) == pytest.approx(held, abs=0.1) and float(dn.max()) <= 31
        if e.photons / 3 > 60:  # full: no shot noise left, only the readout's
            assert float(dn.std()) < 1.0
    with pytest.raises(ValueError, match="same sensor settings"):
        photon_noise(torch.ones(2, 1, 4, 4), [Exposure(10.0), Exposure(10.0, bits=8)], gen)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("kind", [GaussianNoise, PhotonNoise])
def test_device_noise_resumes_exactly(kind) -> None:
    """A second generator on the device draws the field; both states round-trip."""
    raw = torch.rand(4, 1, 32, 32, device="cuda")
    noise = kind(seed=5, device="cuda")
    assert noise.device.type == "cuda" and set(noise.state_dict()) == {"generator", "field"}
    state = noise.state_dict()
    first, _ = noise(raw)
    again = kind(seed=99, device="cuda")
    again.load_state_dict(state)
    second, _ = again(raw)
    assert first.device.type == "cuda" and torch.equal(first, second)


def test_dark_current_adds_its_poisson_noise_and_no_signal():
    """Dark electrons: Poisson counts whose mean a dark frame removes. On a flat raw image the
    mean stays the signal and the variance is a g + b with the dark term in b, by simulation
    (both the evaluation path and the training batch path); without dark current the key,
    hence every seed and stored result, is as before."""
    import torch

    from splitcam.physics.noise import Exposure, photon_noise

    g = 0.6
    raw = torch.full((1, 1, 300, 300), g, dtype=torch.float64)
    exposure = Exposure(90.0, read_noise=1.5, dark=40.0)
    a, b = exposure.variance_coefficients()
    assert b == pytest.approx((3 / 90 * 1.5) ** 2 + (3 / 90) ** 2 * 40.0)
    for noisy in (
        exposure.add(raw, "flat"),
        photon_noise(raw, [exposure], torch.Generator().manual_seed(3)),
    ):
        assert float(noisy.mean()) == pytest.approx(g, abs=3e-3)
        assert float(noisy.var()) == pytest.approx(a * g + b, rel=0.03)
    plain = Exposure(90.0, read_noise=1.5)
    assert plain.key() == "N90|r1.5|fwNone|gNone|b12|s1"
    assert "dark" not in plain.sensor_settings() and exposure.sensor_settings()["dark"] == 40.0
    assert exposure.key() != plain.key()
    with pytest.raises(ValueError, match="dark"):
        Exposure(90.0, dark=-1.0)


def test_dark_current_costs_the_closed_form_lmmse():
    from splitcam.physics.noise import Exposure
    from splitcam.recon.closed_form import closed_form_mse, shipped_image_statistics

    stats = shipped_image_statistics("linear")
    clean = float(closed_form_mse(patterns.get("bayer"), Exposure(30.0), statistics=stats))
    dark = float(
        closed_form_mse(patterns.get("bayer"), Exposure(30.0, dark=20.0), statistics=stats)
    )
    assert dark > clean * 1.05
