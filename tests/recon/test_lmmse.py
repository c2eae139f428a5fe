"""The fitted LMMSE reconstructor (splitcam.recon.lmmse): filters, statistics, files, and
signal-dependent noise."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.physics.noise import Exposure
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.base import Reconstructor as Method
from splitcam.recon.lmmse import LMMSE, LMMSEFileError, LMMSEStatistics, fit_lmmse


def _smooth_images(n: int, h: int, w: int, seed: int) -> torch.Tensor:
    """Random images with some spatial correlation (a 3x3 box blur of uniform noise)."""
    gen = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, h + 2, w + 2, generator=gen, dtype=torch.float64)
    return torch.nn.functional.avg_pool2d(x, 3, stride=1)


def _design(
    pattern: patterns.Pattern,
    images: torch.Tensor,
    radius: int,
    noise: float = 0.0,
    repeats: int = 1,
    seed: int = 0,
):
    """Explicit neighbourhood design matrices per phase, by plain loops (the independent path).

    Valid centres: at least ``radius`` + the pattern kernel's half size from every edge.
    """
    ph, pw = pattern.period
    kh, kw = pattern.kernel_size
    raw = SplitterSensor(pattern)(images.double()).numpy()[:, 0]
    rgb = images.double().numpy()
    rng = np.random.default_rng(seed)
    xs = {p: [] for p in range(ph * pw)}
    ys = {p: [] for p in range(ph * pw)}
    n, h, w = raw.shape
    my, mx = radius + kh // 2, radius + kw // 2
    for _ in range(repeats):
        noisy = raw + noise * rng.standard_normal(raw.shape)
        for b in range(n):
            for y in range(my, h - my):
                for x in range(mx, w - mx):
                    patch = noisy[b, y - radius : y + radius + 1, x - radius : x + radius + 1]
                    p = (y % ph) * pw + x % pw
                    xs[p].append(np.append(patch.ravel(), 1.0))
                    ys[p].append(rgb[b, :, y, x])
    return {p: (np.array(xs[p]), np.array(ys[p])) for p in xs}


@pytest.mark.parametrize("name", ["A", "C"])
def test_lmmse_filters_equal_least_squares(name):
    pattern = patterns.get(name)
    radius = 2
    # Uncorrelated pixels keep the normal equations well conditioned, so the tiny ridge of the
    # solver stays far below the tolerance.
    gen = torch.Generator().manual_seed(3)
    images = torch.rand(3, 3, 18, 19, dtype=torch.float64, generator=gen)
    stats = fit_lmmse(pattern, images, radius=radius)
    design = _design(pattern, images, radius)
    k = 2 * radius + 1
    d = k * k
    assert stats.counts.tolist() == [len(design[p][0]) for p in sorted(design)]
    residual = 0.0
    for sigma in (0.0, 7.0):
        weights, bias = stats.filters(sigma)
        assert weights.shape == (len(design), 3, k, k) and bias.shape == (len(design), 3)
        for p, (x, y) in design.items():
            if sigma == 0:
                solution, *_ = np.linalg.lstsq(x, y, rcond=None)
                residual += float(((x @ solution - y) ** 2).sum())
            else:
                gram = x.T @ x / len(x)
                gram[np.arange(d), np.arange(d)] += (sigma / 255) ** 2
                solution = np.linalg.solve(gram, x.T @ y / len(x))
            ours = np.concatenate([weights[p].reshape(3, d).numpy().T, bias[p][None].numpy()])
            np.testing.assert_allclose(ours, solution, rtol=0, atol=1e-6 * np.abs(solution).max())
    expected = residual / (3 * stats.counts.sum().item())
    assert stats.expected_mse(0.0) == pytest.approx(expected, rel=1e-5)


def test_statistics_of_two_fits_add_up():
    images = _smooth_images(4, 14, 14, seed=13)
    whole = fit_lmmse(patterns.get("E"), images, radius=1)
    pooled = fit_lmmse(patterns.get("E"), images[:1], radius=1) + fit_lmmse(
        patterns.get("E"), images[1:], radius=1
    )
    assert torch.equal(pooled.counts, whole.counts)
    for a, b in zip(pooled.filters(4.0), whole.filters(4.0), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="same pattern and radius"):
        whole + fit_lmmse(patterns.get("E"), images, radius=2)


def test_lmmse_filters_match_a_fit_on_explicitly_noised_samples():
    pattern = patterns.get("D")
    radius, sigma = 1, 20.0
    images = _smooth_images(16, 24, 24, seed=4)
    stats = fit_lmmse(pattern, images, radius=radius)
    weights, bias = stats.filters(sigma)
    clean_weights, _ = stats.filters(0.0)
    design = _design(pattern, images, radius, noise=sigma / 255, repeats=30, seed=5)
    for p, (x, y) in design.items():
        solution, *_ = np.linalg.lstsq(x, y, rcond=None)
        ours = np.concatenate([weights[p].reshape(3, -1).numpy().T, bias[p][None].numpy()])
        error = np.linalg.norm(ours - solution) / np.linalg.norm(solution)
        assert error < 0.05
        # The noisy filters differ clearly from the noise-free ones, so the check has teeth.
        clean = clean_weights[p].reshape(3, -1).numpy().T
        assert np.linalg.norm(clean - ours[:-1]) / np.linalg.norm(ours) > 5 * error


@pytest.mark.parametrize("name", ["A", "C"])
def test_lmmse_reconstruct_equals_per_pixel_dot_products(name):
    pattern = patterns.get(name)
    radius = 2
    method = LMMSE(fit_lmmse(pattern, _smooth_images(2, 16, 16, seed=6), radius=radius))
    raw = torch.rand(2, 1, 7, 8, dtype=torch.float64, generator=torch.Generator().manual_seed(7))
    sigma = 3.0
    out = method.reconstruct(raw, sigma)
    weights, bias = method.statistics.filters(sigma)
    ph, pw = pattern.period
    padded = torch.nn.functional.pad(raw, (radius,) * 4)
    expected = torch.empty_like(out)
    for n in range(2):
        for y in range(7):
            for x in range(8):
                p = (y % ph) * pw + x % pw
                hood = padded[n, 0, y : y + 2 * radius + 1, x : x + 2 * radius + 1]
                expected[n, :, y, x] = (weights[p] * hood).sum((-2, -1)) + bias[p]
    torch.testing.assert_close(out, expected, rtol=1e-12, atol=1e-12)
    out32 = method.reconstruct(raw.float(), sigma)
    assert out32.dtype == torch.float32
    torch.testing.assert_close(out32, expected.float(), rtol=1e-4, atol=1e-4)
    assert isinstance(method, Method)


def test_lmmse_recovers_constant_colours_of_pattern_d_exactly():
    # For pattern D a flat scene of colour c gives raw values (2R+G+B, G+B, R+G, R+G+2B) on the
    # four phases: the colour is a linear function of any neighbourhood, so a fit on flat
    # scenes must reproduce every flat scene (away from the image border).
    gen = torch.Generator().manual_seed(8)
    colours = torch.rand(8, 3, 1, 1, generator=gen, dtype=torch.float64)
    method = LMMSE(fit_lmmse(patterns.get("D"), colours.expand(8, 3, 12, 12), radius=2))
    scene = torch.tensor([0.2, 0.7, 0.4], dtype=torch.float64).view(1, 3, 1, 1).expand(1, 3, 20, 20)
    out = method.reconstruct(SplitterSensor("D")(scene), 0.0)
    inner = slice(3, -3)
    torch.testing.assert_close(out[..., inner, inner], scene[..., inner, inner], atol=1e-6, rtol=0)


def test_lmmse_input_validation():
    with pytest.raises(ValueError, match="expected patches of at least"):
        fit_lmmse(patterns.get("A"), torch.rand(1, 3, 8, 8), radius=4)
    with pytest.raises(ValueError, match="expected radius"):
        fit_lmmse(patterns.get("A"), torch.rand(1, 3, 16, 16), radius=-1)
    method = LMMSE(fit_lmmse(patterns.get("E"), _smooth_images(1, 12, 12, seed=9), radius=1))
    with pytest.raises(ValueError, match=r"expected \(N, 1, H, W\)"):
        method.reconstruct(torch.rand(1, 3, 8, 8), 0.0)
    with pytest.raises(ValueError, match="expected a finite sigma >= 0"):
        method.reconstruct(torch.rand(1, 1, 8, 8), -1.0)


def test_save_load_round_trip_and_damaged_files(tmp_path):
    method = LMMSE(fit_lmmse(patterns.get("B"), _smooth_images(2, 16, 16, seed=10), radius=2))
    meta_path = method.save(tmp_path / "lmmse_b")
    tensors_path = tmp_path / "lmmse_b.safetensors"
    assert meta_path == tmp_path / "lmmse_b.json" and tensors_path.exists()
    loaded = LMMSE.load(tmp_path / "lmmse_b.safetensors")
    assert loaded.pattern.equals(method.pattern) and loaded.pattern.name == "B"
    raw = torch.rand(1, 1, 9, 11, generator=torch.Generator().manual_seed(11))
    for sigma in (0.0, 12.0):
        assert torch.equal(loaded.reconstruct(raw, sigma), method.reconstruct(raw, sigma))

    blob = tensors_path.read_bytes()
    tensors_path.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(LMMSEFileError, match="checksum"):
        LMMSEStatistics.load(meta_path)
    flipped = bytearray(blob)
    flipped[-5] ^= 0xFF
    tensors_path.write_bytes(bytes(flipped))
    with pytest.raises(LMMSEFileError, match="checksum"):
        LMMSEStatistics.load(meta_path)
    tensors_path.write_bytes(blob)

    text = meta_path.read_text()
    meta_path.write_text(text[: len(text) // 2])
    with pytest.raises(LMMSEFileError, match="not valid JSON"):
        LMMSEStatistics.load(meta_path)
    meta = json.loads(text)
    meta["radius"] = 3
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(LMMSEFileError, match="changed after it was written"):
        LMMSEStatistics.load(meta_path)
    # A file from before the fields had a checksum: the shapes are still checked.
    del meta["meta_sha256"]
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(LMMSEFileError, match="damaged LMMSE statistics"):
        LMMSEStatistics.load(meta_path)
    tensors_path.unlink()
    with pytest.raises(LMMSEFileError, match="cannot read"):
        LMMSEStatistics.load(meta_path)


def _fitted(pattern: str = "D"):
    from splitcam.recon.lmmse import fit_lmmse

    gen = torch.Generator().manual_seed(3)
    images = torch.nn.functional.interpolate(
        torch.rand(4, 3, 8, 8, generator=gen), size=(40, 40), mode="bilinear"
    )
    return fit_lmmse(patterns.get(pattern), images, radius=2)


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
