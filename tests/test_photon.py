"""The photon-limited sensor model (SPEC section 11) and the LMMSE under its signal-dependent noise
(SPEC section 10)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from conftest import blocky_images, tiny_config

from splitcam.physics.noise import Exposure, PhotonNoise, add_exposure_noise
from splitcam.physics.sensor import SplitterSensor, pattern_pixel_kernels
from splitcam.recon.closed_form import (
    _RIDGE,
    _moments,
    closed_form_filters,
    closed_form_mse,
    shipped_image_statistics,
)


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
    full = Exposure(300.0, read_noise=1.0, full_well=60.0).apply(_flat(1.0, 50), gen)
    assert float(full.max()) == pytest.approx(60.0 * 3 / 300)  # 100 e- clipped at 60
    adc = Exposure(300.0, read_noise=0.0, gain=1.0, bits=6).apply(_flat(1.0, 50), gen)
    assert float(adc.max()) == pytest.approx(63 * 3 / 300)  # 2^6 - 1 DN at 1 e-/DN
    dark = Exposure(300.0, read_noise=3.0, gain=1.0).apply(_flat(0.0, 50), gen)
    assert float(dark.min()) == 0.0  # the ADC clips at 0


def test_evaluation_noise_is_deterministic_per_image_and_exposure() -> None:
    raw = torch.rand(1, 1, 32, 32, generator=torch.Generator().manual_seed(4))
    e = Exposure(100.0)
    a = add_exposure_noise(raw, "kodim01", e)
    assert torch.equal(a, add_exposure_noise(raw, "kodim01", e))
    assert not torch.equal(a, add_exposure_noise(raw, "kodim02", e))
    assert not torch.equal(a, add_exposure_noise(raw, "kodim01", Exposure(200.0)))


def test_equal_exposure_pattern_a_red_pixel_gathers_four_times_bayer() -> None:
    """On a white scene the R pixel of pattern A collects 4 times the light of a Bayer R pixel
    at the same exposure (SPEC section 11): 4N/3 against N/3 photo-electrons."""
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
    weights, bias = closed_form_filters("D", exposure)
    w_g, b_g = closed_form_filters("D", sigma)
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


def test_closed_form_filters_under_signal_dependent_noise() -> None:
    """The filters equal an explicit solve with the diagonal noise variance ``a g + b`` at each
    window pixel's expected signal; more light lowers the expected error; several exposures at
    once equal one by one."""
    stats = shipped_image_statistics()
    kernels = pattern_pixel_kernels("A")
    exposure = Exposure(50.0, read_noise=3.0)
    weights, bias = closed_form_filters(kernels, exposure, statistics=stats, radius=2)
    cxx, cyx, mean_x, _ = (t.numpy() for t in _moments(kernels, stats, 2))
    a, b = exposure.variance_coefficients()
    for p in range(cxx.shape[0]):
        noise = np.diag(a * mean_x[p] + b)
        ridge = _RIDGE * np.trace(cxx[p]) / cxx.shape[-1]  # what the solver adds for stability
        expected = np.linalg.solve(cxx[p] + noise + ridge * np.eye(cxx.shape[-1]), cyx[p].T).T
        np.testing.assert_allclose(
            weights[p].reshape(3, -1).numpy(), expected, rtol=1e-9, atol=1e-12
        )
    levels = [Exposure(n, read_noise=3.0) for n in (10.0, 100.0, 1000.0)]
    mse = closed_form_mse(kernels, levels, statistics=stats, radius=2)
    assert bool((mse[1:] < mse[:-1]).all())
    one = closed_form_mse(kernels, levels[1], statistics=stats, radius=2)
    assert float(one) == pytest.approx(float(mse[1]), rel=1e-12)


def test_crossover_interpolates_in_log_exposure() -> None:
    from splitcam.evaluation.exposure import crossover

    ref = {1.0: 10.0, 10.0: 20.0, 100.0: 30.0}
    assert crossover({1.0: 12.0, 10.0: 20.0 + 1.0, 100.0: 29.0}, ref) == pytest.approx(10**1.5)
    assert crossover({1.0: 11.0, 10.0: 21.0, 100.0: 31.0}, ref) == math.inf
    assert crossover({1.0: 9.0, 10.0: 21.0, 100.0: 31.0}, ref) is None
    # lower is better (CIEDE2000): wins below N = 10
    assert crossover(
        {1.0: 1.0, 10.0: 2.0, 100.0: 3.0}, {1.0: 2.0, 10.0: 2.0, 100.0: 2.0}, higher_is_better=False
    ) == pytest.approx(10.0)


def test_raw_snr_follows_the_signal_gain() -> None:
    """On a flat grey scene a lossless splitter gathers k = 3 times the filter's signal; its raw
    SNR gain is near 10 log10 k shot-limited and 20 log10 k read-limited (not exactly: its
    pixels are not k times the filter's one by one)."""
    from splitcam.evaluation.exposure import raw_snr_check

    grey = [("grey", torch.full((3, 64, 64), 0.5))]
    snr = raw_snr_check(grey, patterns=["A", "D", "bayer"])
    for name in ("A", "D"):
        assert snr[name]["k"] == pytest.approx(3.0, rel=0.03)  # borders lose a little
        assert abs(snr[name]["shot_gain_db"] - snr[name]["shot_theory_db"]) < 0.6
        assert abs(snr[name]["read_gain_db"] - snr[name]["read_theory_db"]) < 0.6
    assert snr["bayer"]["k"] == 1.0 and snr["bayer"]["read_gain_db"] == 0.0


def test_study_exposure_cli(tmp_path, capsys) -> None:
    from splitcam.cli import main

    assert (
        main(
            [
                "study",
                "exposure",
                "--max-images",
                "1",
                "--photons",
                "3",
                "300",
                "--patterns",
                "D,bayer",
                "--out",
                str(tmp_path),
                "--quiet",
            ]
        )
        == 0
    )
    text = (tmp_path / "exposure.md").read_text()
    assert "| D |" in text and "Crossover" in text and "Raw SNR" in text
    assert (tmp_path / "exposure.png").is_file()
    data = json_load(tmp_path / "exposure.json")
    assert data["results"]["D"]["300"]["psnr"] > data["results"]["D"]["3"]["psnr"]
    assert main(["study", "exposure", "--photons", "-1", "--out", str(tmp_path)]) == 1
    assert "photons" in capsys.readouterr().err


def json_load(path):
    import json

    return json.loads(path.read_text())


def test_training_under_the_photon_model(tmp_path) -> None:
    """`train --noise photon`: the physics network is told each patch's exposure, validation is
    per exposure, the checkpoint records the noise model, and an untrained network is the LMMSE
    under signal-dependent noise."""

    from splitcam.evaluation.protocol import mean_psnr
    from splitcam.recon.closed_form import closed_form_lmmse
    from splitcam.training import TrainConfig, train
    from splitcam.training import checkpoint as ckpt_io
    from splitcam.training.trainer import _val_images

    folder = blocky_images(tmp_path / "img", 5)
    config = tiny_config(
        folder,
        tmp_path / "run",
        **{
            "optim.steps": 4,
            "optim.warmup_steps": 2,
            "run.val_every": 4,
            "run.checkpoint_every": 4,
            "noise.model": "photon",
            "noise.photons": [20.0, 2000.0],
            "noise.val_photons": [30.0, 1000.0],
        },
    )
    train(config, progress=False)
    rows = [
        json_load_line(x) for x in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()
    ]
    first = next(r for r in rows if "val_psnr_N30" in r)
    assert first["step"] == 0 and "val_psnr_N1000" in first
    assert first["val_psnr_N1000"] > first["val_psnr_N30"]
    levels = [Exposure(30.0), Exposure(1000.0)]
    lmmse = mean_psnr(closed_form_lmmse("D"), _val_images(config), levels)
    assert first["val_psnr_N30"] == pytest.approx(lmmse[levels[0]], abs=1e-3)
    assert ckpt_io.load(tmp_path / "run").meta["config"]["noise"]["model"] == "photon"
    # The exposure study takes the trained network beside the LMMSE of its pattern.
    from splitcam.evaluation.exposure import exposure_study
    from splitcam.methods import build_method

    study = exposure_study(
        _val_images(config),
        patterns=["D"],
        photons=[30.0, 1000.0],
        methods=[build_method(str(tmp_path / "run"))],
        progress=False,
    )
    assert set(study) == {"D", "run"}
    assert study["run"][1000.0]["psnr"] > study["run"][30.0]["psnr"]
    from splitcam.training.config import ConfigError

    with pytest.raises(ConfigError, match="noise"):
        TrainConfig().override({"noise.model": "photon", "noise.photons": [100.0, 10.0]}).validate()
    with pytest.raises(ConfigError, match="bits"):
        TrainConfig().override({"noise.model": "photon", "noise.bits": 0}).validate()


def json_load_line(text):
    import json

    return json.loads(text)
