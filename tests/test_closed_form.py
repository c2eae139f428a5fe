"""Closed-form LMMSE from pattern-free image statistics (splitcam.recon.closed_form)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.data.imageio import read_image
from splitcam.data.patches import ImageCache, list_images
from splitcam.physics.sensor import SplitterSensor, pixel_kernels
from splitcam.recon.closed_form import (
    ClosedFormFilters,
    ImageStatistics,
    closed_form_filters,
    closed_form_lmmse,
    closed_form_mse,
    estimate_image_statistics,
    shipped_image_statistics,
)
from splitcam.recon.lmmse import LMMSEFileError, fit_lmmse

TRAIN = Path(__file__).resolve().parents[2] / "shared" / "data" / "train"


def _smooth_images(n: int, size: int, seed: int) -> torch.Tensor:
    """Random images with spatial and cross-channel correlation, in [0, 1]."""
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, size + 4, size + 4, generator=g, dtype=torch.float64)
    x = torch.nn.functional.avg_pool2d(x, 5, stride=1)
    mix = torch.tensor([[0.6, 0.3, 0.1], [0.2, 0.6, 0.2], [0.1, 0.3, 0.6]], dtype=torch.float64)
    return torch.einsum("dc,nchw->ndhw", mix, x)


def test_statistics_equal_direct_sums() -> None:
    imgs = _smooth_images(2, 13, 0)
    lo = 3
    stats = estimate_image_statistics(imgs, max_offset=lo)
    f = imgs.numpy()
    h = w = 13
    expected = np.zeros((3, 3, 2 * lo + 1, 2 * lo + 1))
    total = np.zeros(3)
    count = 0
    for img in f:
        for y in range(lo, h - lo):
            for x in range(lo, w - lo):
                total += img[:, y, x]
                count += 1
                for dy in range(-lo, lo + 1):
                    for dx in range(-lo, lo + 1):
                        expected[:, :, dy + lo, dx + lo] += np.outer(
                            img[:, y, x], img[:, y + dy, x + dx]
                        )
    expected /= count
    expected = 0.5 * (expected + np.flip(expected.transpose(1, 0, 2, 3), (-1, -2)))
    assert stats.count == count
    np.testing.assert_allclose(stats.mean.numpy(), total / count, rtol=1e-12)
    np.testing.assert_allclose(stats.second.numpy(), expected, rtol=1e-10, atol=1e-13)


def _brute_force_filters(
    pattern: patterns.Pattern, stats: ImageStatistics, radius: int, sigma: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Filters from design matrices measured by running the sensor on impulse scenes."""
    ph, pw = pattern.period
    kh, kw = pattern.kernel_size
    k = 2 * radius + 1
    wh, ww = k + kh - 1, k + kw - 1
    sensor = SplitterSensor(pattern).double()
    pad = 2 * max(ph, pw) + max(kh, kw)
    lo = stats.max_offset
    cov = stats.covariance()
    n = 3 * wh * ww
    cff = torch.zeros(n, n, dtype=torch.float64)
    pos = [(c, y, x) for c in range(3) for y in range(wh) for x in range(ww)]
    for i, (c1, y1, x1) in enumerate(pos):
        for j, (c2, y2, x2) in enumerate(pos):
            cff[i, j] = cov[c1, c2, y2 - y1 + lo, x2 - x1 + lo]
    mean_f = stats.mean.repeat_interleave(wh * ww)
    weights, biases = [], []
    for i in range(ph):
        for j in range(pw):
            # Centre pixel of phase (i, j) placed at (cy, cx) of a big scene, window from there.
            cy = ph * pad + i
            cx = pw * pad + j
            size = cy + radius + kh + pad, cx + radius + kw + pad
            a = torch.zeros(k * k, n, dtype=torch.float64)
            for col, (c, y, x) in enumerate(pos):
                scene = torch.zeros(1, 3, *size, dtype=torch.float64)
                scene[0, c, cy - radius - kh // 2 + y, cx - radius - kw // 2 + x] = 1.0
                raw = sensor(scene)[0, 0]
                a[:, col] = raw[
                    cy - radius : cy + radius + 1, cx - radius : cx + radius + 1
                ].reshape(-1)
            cxx = a @ cff @ a.T
            centre = [c * wh * ww + (wh // 2) * ww + ww // 2 for c in range(3)]
            cyx = cff[centre] @ a.T
            system = cxx + ((sigma / 255) ** 2 + 1e-8 * cxx.trace() / (k * k)) * torch.eye(k * k)
            w = torch.linalg.solve(system, cyx.T).T
            weights.append(w.reshape(3, k, k))
            biases.append(stats.mean - w @ (a @ mean_f))
    return torch.stack(weights), torch.stack(biases)


@pytest.mark.parametrize("name", ["A", "C", "D", "bayer"])
def test_closed_form_equals_filters_of_measured_design_matrices(name: str) -> None:
    stats = estimate_image_statistics(_smooth_images(3, 40, 1), max_offset=8)
    pattern = patterns.get(name)
    for sigma in (0.0, 10.0):
        w, b = closed_form_filters(pattern, sigma, statistics=stats, radius=2)
        w_ref, b_ref = _brute_force_filters(pattern, stats, 2, sigma)
        torch.testing.assert_close(w, w_ref, rtol=1e-6, atol=1e-8)
        torch.testing.assert_close(b, b_ref, rtol=1e-6, atol=1e-8)


@pytest.mark.skipif(not TRAIN.is_dir(), reason="training images not available")
@pytest.mark.parametrize("name", patterns.names())
def test_closed_form_matches_simulated_fit(name: str) -> None:
    """Same images: the closed form and the simulated-moments fit give the same LMMSE error
    (in-sample expected MSE) and the same PSNR on a held-out image, up to sampling error."""
    files = list_images(TRAIN)
    cache = ImageCache(files[:40], min_size=48, progress=False)
    stats = _train_statistics(tuple(files[:40]))
    fit = fit_lmmse(name, cache, patches=1024, seed=0)
    held_out = torch.from_numpy(read_image(files[-1])).permute(2, 0, 1)[None, :, :160, :160]
    raw = SplitterSensor(name).double()(held_out.double())
    target = held_out[0, :, 8:-8, 8:-8].double()
    for sigma in (0.0, 15.0):
        mse_fit = fit.expected_mse(sigma)
        mse_cf = float(closed_form_mse(name, sigma, statistics=stats))
        assert mse_cf == pytest.approx(mse_fit, rel=0.05)
        errs = []
        for filters in (fit, ClosedFormFilters(name, stats)):
            from splitcam.recon.lmmse import LMMSE

            out = LMMSE(filters).reconstruct(raw, sigma)[0, :, 8:-8, 8:-8]  # type: ignore[arg-type]
            errs.append(float(((out - target) ** 2).mean()))
        psnr = [10 * np.log10(1 / e) for e in errs]
        assert abs(psnr[0] - psnr[1]) < 0.15, psnr


_STATS_CACHE: dict[tuple, ImageStatistics] = {}


def _train_statistics(files: tuple) -> ImageStatistics:
    if files not in _STATS_CACHE:
        _STATS_CACHE[files] = estimate_image_statistics(list(files))
    return _STATS_CACHE[files]


def test_filters_are_differentiable_in_the_kernels() -> None:
    stats = estimate_image_statistics(_smooth_images(2, 24, 2), max_offset=4)
    pattern = patterns.get("D")
    w0 = torch.from_numpy(np.array(pattern.kernels, dtype=np.float64))
    w0 = (w0 + 0.05 * torch.rand_like(w0)).requires_grad_()

    def f(weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        k = pixel_kernels(weights, pattern.layout)
        w, b = closed_form_filters(k, 5.0, statistics=stats, radius=1)
        return w, b, closed_form_mse(k, 5.0, statistics=stats, radius=1)

    assert torch.autograd.gradcheck(f, (w0,), eps=1e-6, atol=1e-5, rtol=1e-4)


def test_several_sigmas_at_once_equal_one_by_one() -> None:
    sig = torch.tensor([0.0, 7.5, 20.0], dtype=torch.float64)
    w, b = closed_form_filters("A", sig)
    mse = closed_form_mse("A", sig)
    for i, s in enumerate(sig.tolist()):
        w1, b1 = closed_form_filters("A", s)
        torch.testing.assert_close(w[i], w1)
        torch.testing.assert_close(b[i], b1)
        torch.testing.assert_close(mse[i], closed_form_mse("A", s))
    assert bool((mse[1:] > mse[:-1]).all())  # more noise, more error


def test_shipped_statistics_and_reconstructor() -> None:
    stats = shipped_image_statistics()
    assert stats.max_offset >= 12 and stats.count > 10**6
    # A covariance: variance on the diagonal at offset 0, decaying with distance.
    cov = stats.covariance()
    lo = stats.max_offset
    assert all(cov[c, c, lo, lo] > cov[c, c, lo, lo + 8] > 0 for c in range(3))
    lmmse = closed_form_lmmse("D")
    assert lmmse.pattern.name == "D"
    rgb = _smooth_images(1, 48, 3).float()
    raw = SplitterSensor("D")(rgb)
    out = lmmse.reconstruct(raw, 0.0)
    assert out.shape == (1, 3, 48, 48)
    assert float(((out - rgb)[..., 8:-8, 8:-8] ** 2).mean()) < 2e-3


def test_radius_beyond_statistics_and_bad_input_are_refused(tmp_path: Path) -> None:
    stats = estimate_image_statistics(_smooth_images(1, 24, 4), max_offset=4)
    with pytest.raises(ValueError, match="needs image statistics up to offset"):
        closed_form_filters("D", 0.0, statistics=stats, radius=4)
    with pytest.raises(ValueError, match="sigma"):
        closed_form_filters("D", float("nan"), statistics=stats, radius=1)
    with pytest.raises(ValueError, match="larger than"):
        estimate_image_statistics(_smooth_images(1, 6, 0), max_offset=4)
    path = stats.save(tmp_path / "stats")
    again = ImageStatistics.load(path)
    torch.testing.assert_close(again.second, stats.second)
    blob = (tmp_path / "stats.safetensors").read_bytes()
    (tmp_path / "stats.safetensors").write_bytes(blob[:-8] + b"\0" * 8)
    with pytest.raises(LMMSEFileError, match="checksum"):
        ImageStatistics.load(path)
