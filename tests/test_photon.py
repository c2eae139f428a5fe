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
    from splitcam.io import checkpoints as ckpt_io
    from splitcam.recon.closed_form import closed_form_lmmse
    from splitcam.training import TrainConfig, train
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
    from splitcam.recon.registry import build_method

    study = exposure_study(
        _val_images(config),
        patterns=["D"],
        photons=[30.0, 1000.0],
        methods=[build_method(str(tmp_path / "run"))],
        progress=False,
        domain="srgb",  # the network was trained on sRGB values
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


# --- the photon model in `evaluate` and in the fitted LMMSE --------------------------------------


def _fitted(pattern: str = "D"):
    from splitcam.recon.lmmse import fit_lmmse

    gen = torch.Generator().manual_seed(3)
    images = torch.nn.functional.interpolate(
        torch.rand(4, 3, 8, 8, generator=gen), size=(40, 40), mode="bilinear"
    )
    return fit_lmmse(pattern, images, radius=2)


def test_fitted_lmmse_under_signal_dependent_noise_is_the_explicit_solve() -> None:
    """The fitted statistics' filters for an Exposure equal a solve of the noisy second moment
    written out by hand: the clean moment plus ``a E[g] + b`` on the diagonal of the raw entries
    (``E[g]``: the mean raw value at that window position), the bias entry untouched."""
    from splitcam.recon.lmmse import _RIDGE

    stats = _fitted()
    exposure = Exposure(40.0, read_noise=3.0)
    weights, bias = stats.filters(exposure)
    a, b = exposure.variance_coefficients()
    n = stats.counts.numpy().astype(float)
    for p in range(len(n)):
        mxx = stats.xx[p].numpy() / n[p]
        mxy = stats.xy[p].numpy() / n[p]
        d = mxx.shape[0] - 1
        noisy = mxx.copy()
        for i in range(d):
            noisy[i, i] += a * mxx[i, d] + b + _RIDGE * np.trace(mxx[:d, :d]) / d
        w = np.linalg.solve(noisy, mxy)
        got = weights[p].reshape(3, -1).numpy()
        np.testing.assert_allclose(got, w[:d].T, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(bias[p].numpy(), w[d], rtol=1e-8, atol=1e-10)


def test_fitted_lmmse_exposure_without_shot_noise_is_the_gaussian_filter() -> None:
    """Read noise only, ``r = N sigma / (3 * 255)`` electrons: the same filters as sigma."""
    stats = _fitted("A")
    n, sigma = 300.0, 12.0
    exposure = Exposure(n, read_noise=n * sigma / (3 * 255), shot=False)
    for got, want in zip(stats.filters(exposure), stats.filters(sigma), strict=True):
        torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-12)
    assert stats.expected_mse(exposure) == pytest.approx(stats.expected_mse(sigma), rel=1e-10)
    # Shot noise adds variance where there is signal: the expected error grows.
    assert stats.expected_mse(Exposure(n, read_noise=exposure.read_noise)) > stats.expected_mse(
        sigma
    )


def _photos(count: int = 2) -> list[tuple[str, torch.Tensor]]:
    gen = torch.Generator().manual_seed(5)
    small = torch.rand(count, 3, 6, 6, generator=gen)
    big = torch.nn.functional.interpolate(small, size=(36, 40), mode="bilinear")
    return [(f"ph{i}", big[i]) for i in range(count)]


def test_evaluate_at_exposures_scores_what_the_exposure_study_scores(tmp_path) -> None:
    """`evaluate` with Exposures: rows labelled N<photons> beside the Gaussian ones, the same
    numbers as `study exposure` for the same method and images (two paths, one protocol)."""
    from splitcam.evaluation import evaluate
    from splitcam.evaluation.exposure import exposure_study
    from splitcam.evaluation.tables import read_rows
    from splitcam.recon.closed_form import closed_form_lmmse

    images = _photos()
    levels = [5.0, Exposure(30.0, read_noise=2.0), Exposure(3000.0, read_noise=2.0)]
    rows = evaluate([closed_form_lmmse("D")], [("set", images)], levels, tmp_path, progress=False)
    assert {r.level for r in rows} == {"5", "N30", "N3000"}
    study = exposure_study(
        images, patterns=["D"], photons=[30.0, 3000.0], progress=False, domain="srgb"
    )
    for n in (30.0, 3000.0):
        mine = [r.psnr for r in rows if r.photons == n]
        assert np.mean(mine) == pytest.approx(study["D"][n]["psnr"], rel=1e-12)
    summary = json_load(tmp_path / "summary.json")
    assert summary["lmmse"]["all"]["N3000"]["psnr"] > summary["lmmse"]["all"]["N30"]["psnr"]
    assert list(summary["lmmse"]["all"]) == ["5", "N30", "N3000"]  # sigmas first
    assert "N=30 e⁻" in (tmp_path / "table.md").read_text()
    assert read_rows(tmp_path / "per_image.csv") == rows


def test_evaluate_resumes_photon_rows_only_under_the_same_sensor(tmp_path) -> None:
    from splitcam.evaluation import evaluate

    class Counter:
        name = "count"
        pattern = __import__("splitcam").patterns.get("D")

        def __init__(self) -> None:
            self.calls = 0

        def reconstruct(self, raw, sigma):
            self.calls += 1
            return raw.expand(-1, 3, -1, -1) / 3

    images = _photos()
    first = Counter()
    evaluate([first], [("s", images)], [0.0, Exposure(100.0)], tmp_path, progress=False)
    assert first.calls == 4
    again = Counter()
    evaluate([again], [("s", images)], [0.0, Exposure(100.0)], tmp_path, progress=False)
    assert again.calls == 0
    other_sensor = Counter()  # another read noise: the photon rows are recomputed, sigma 0 kept
    evaluate(
        [other_sensor],
        [("s", images)],
        [0.0, Exposure(100.0, read_noise=5.0)],
        tmp_path,
        progress=False,
    )
    assert other_sensor.calls == 2
    with pytest.raises(ValueError, match="share their sensor settings"):
        evaluate(
            [Counter()],
            [("s", images)],
            [Exposure(10.0), Exposure(100.0, read_noise=5.0)],
            tmp_path,
            progress=False,
        )


def test_results_written_before_the_photons_column_still_read(tmp_path) -> None:
    from splitcam.evaluation.tables import read_rows

    path = tmp_path / "per_image.csv"
    path.write_text(
        "method,pattern,dataset,image,sigma,psnr,ssim,ciede2000\n"
        "m,D,set,a,5,30.5,0.9,2.0\n"
        "m,D,set,b,5,31.5,0.9\n"  # cut short by a kill
    )
    (row,) = read_rows(path)
    assert (row.sigma, row.photons, row.level, row.psnr) == (5.0, 0.0, "5", 30.5)


def test_evaluate_photons_cli(tmp_path, capsys) -> None:
    from splitcam.cli import main

    args = [
        "evaluate",
        "--method",
        "lmmse",
        "--method",
        "malvar2004",
        "--patterns",
        "A,bayer",
        "--max-images",
        "1",
        "--quiet",
        "--out",
        str(tmp_path),
    ]
    assert main([*args, "--photons", "20", "2000", "--read-noise", "1.5"]) == 0
    out = capsys.readouterr().out
    assert "N=20 e⁻" in out and "σ=" not in out  # --photons alone: no Gaussian levels
    summary = json_load(tmp_path / "summary.json")
    assert set(summary["bayer+malvar2004"]["all"]) == {"N20", "N2000"}
    assert json_load(tmp_path / "evaluation.json")["photon_sensor"]["read_noise"] == 1.5
    assert main([*args, "--photons", "-3"]) == 1
    assert "photons" in capsys.readouterr().err
