"""Closed-form LMMSE from pattern-free image statistics (splitcam.recon.closed_form), in both light
domains and under signal-dependent noise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import SHARED_DATA, blocky_images

from splitcam import patterns
from splitcam.data.imageio import read_image
from splitcam.data.patches import ImageCache, list_images
from splitcam.physics import srgb_to_linear
from splitcam.physics.noise import Exposure
from splitcam.physics.sensor import (
    SplitterSensor,
    pattern_pixel_kernels,
    pixel_kernels,
)
from splitcam.recon.closed_form import (
    _RIDGE,
    ClosedFormFilters,
    ImageStatistics,
    _moments,
    closed_form_filters,
    closed_form_lmmse,
    closed_form_mse,
    estimate_image_statistics,
    shipped_image_statistics,
)
from splitcam.recon.lmmse import LMMSEFileError, fit_lmmse

TRAIN = SHARED_DATA / "train"


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


def test_a_mixture_of_statistics_is_the_statistics_of_the_pooled_images() -> None:
    # Two sets of different sizes: the pooled estimate weighs each by its pixel positions, so
    # the mixture at weight count_b / (count_a + count_b) must equal it.
    a, b = _smooth_images(3, 13, 1), _smooth_images(1, 13, 2) ** 2
    sa, sb = (estimate_image_statistics(x, max_offset=3) for x in (a, b))
    pooled = estimate_image_statistics(torch.cat([a, b]), max_offset=3)
    mix = sa.mixed(sb, sb.count / (sa.count + sb.count))
    torch.testing.assert_close(mix.mean, pooled.mean, rtol=1e-12, atol=1e-15)
    torch.testing.assert_close(mix.second, pooled.second, rtol=1e-12, atol=1e-15)
    assert mix.count == pooled.count and mix.domain == sa.domain
    torch.testing.assert_close(sa.mixed(sb, 0.0).second, sa.second)
    torch.testing.assert_close(sa.mixed(sb, 1.0).mean, sb.mean)
    for bad in (-0.1, 1.5, True):
        with pytest.raises(ValueError, match="weight in"):
            sa.mixed(sb, bad)
    with pytest.raises(ValueError, match="cannot mix"):
        sa.mixed(estimate_image_statistics(b, max_offset=2), 0.5)
    with pytest.raises(ValueError, match="cannot mix"):
        sa.mixed(estimate_image_statistics(b, max_offset=3, domain="linear"), 0.5)


def test_statistics_of_a_folder_record_it_as_it_is_found_on_any_machine(tmp_path, monkeypatch):
    """The source of statistics estimated on the training photos is written relative to the
    data root (``train``), as the shipped ones are, not as this machine's folder."""
    monkeypatch.setenv("SPLITCAM_DATA", str(tmp_path))
    folder = blocky_images(tmp_path / "train", 2)
    stats = estimate_image_statistics(folder, max_offset=2)
    assert stats.info["source"] == "train" and stats.info["images"] == 2
    again = estimate_image_statistics(str(folder), max_offset=2)
    torch.testing.assert_close(again.second, stats.second)


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


#: One pattern of each kind runs in the default suite (a filter array, a router of the paper, a
#: full-wave router); the rest are ``slow`` (each about 2 s; the 6x6 X-Trans and the measured
#: RGBW filter arrays among them).
_FIT_QUICK = {"bayer", "A", "router-zou-fullwave-f2"}


@pytest.mark.skipif(not TRAIN.is_dir(), reason="training images not available")
@pytest.mark.parametrize(
    "name",
    [
        pytest.param(name, marks=() if name in _FIT_QUICK else pytest.mark.slow)
        for name in patterns.names()
    ],
)
def test_closed_form_matches_simulated_fit(name: str) -> None:
    """Same images: the closed form and the simulated-moments fit give the same LMMSE error
    (in-sample expected MSE) and the same PSNR on a held-out image, up to sampling error."""
    files = list_images(TRAIN)
    cache = ImageCache(files[:40], min_size=48, progress=False)
    stats = _train_statistics(tuple(files[:40]))
    fit = fit_lmmse(patterns.get(name), cache, patches=1024, seed=0)
    held_out = torch.from_numpy(read_image(files[-1])).permute(2, 0, 1)[None, :, :160, :160]
    raw = SplitterSensor(name).double()(held_out.double())
    target = held_out[0, :, 8:-8, 8:-8].double()
    for sigma in (0.0, 15.0):
        mse_fit = fit.expected_mse(sigma)
        mse_cf = float(closed_form_mse(patterns.get(name), sigma, statistics=stats))
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
    w, b = closed_form_filters(patterns.get("A"), sig)
    mse = closed_form_mse(patterns.get("A"), sig)
    for i, s in enumerate(sig.tolist()):
        w1, b1 = closed_form_filters(patterns.get("A"), s)
        torch.testing.assert_close(w[i], w1)
        torch.testing.assert_close(b[i], b1)
        torch.testing.assert_close(mse[i], closed_form_mse(patterns.get("A"), s))
    assert bool((mse[1:] > mse[:-1]).all())  # more noise, more error


def test_shipped_statistics_and_reconstructor() -> None:
    stats = shipped_image_statistics()
    assert stats.max_offset >= 12 and stats.count > 10**6
    # A covariance: variance on the diagonal at offset 0, decaying with distance.
    cov = stats.covariance()
    lo = stats.max_offset
    assert all(cov[c, c, lo, lo] > cov[c, c, lo, lo + 8] > 0 for c in range(3))
    lmmse = closed_form_lmmse(patterns.get("D"))
    assert lmmse.pattern.name == "D"
    rgb = _smooth_images(1, 48, 3).float()
    raw = SplitterSensor("D")(rgb)
    out = lmmse.reconstruct(raw, 0.0)
    assert out.shape == (1, 3, 48, 48)
    assert float(((out - rgb)[..., 8:-8, 8:-8] ** 2).mean()) < 2e-3


def test_radius_beyond_statistics_and_bad_input_are_refused(tmp_path: Path) -> None:
    stats = estimate_image_statistics(_smooth_images(1, 24, 4), max_offset=4)
    with pytest.raises(ValueError, match="needs image statistics up to offset"):
        closed_form_filters(patterns.get("D"), 0.0, statistics=stats, radius=4)
    with pytest.raises(ValueError, match="sigma"):
        closed_form_filters(patterns.get("D"), float("nan"), statistics=stats, radius=1)
    with pytest.raises(ValueError, match="larger than"):
        estimate_image_statistics(_smooth_images(1, 6, 0), max_offset=4)
    path = stats.save(tmp_path / "stats")
    again = ImageStatistics.load(path)
    torch.testing.assert_close(again.second, stats.second)
    blob = (tmp_path / "stats.safetensors").read_bytes()
    (tmp_path / "stats.safetensors").write_bytes(blob[:-8] + b"\0" * 8)
    with pytest.raises(LMMSEFileError, match="checksum"):
        ImageStatistics.load(path)


def test_shipped_linear_statistics() -> None:
    srgb, linear = shipped_image_statistics(), shipped_image_statistics("linear")
    assert srgb.domain == "srgb" and linear.domain == "linear"
    assert linear.info["images"] == srgb.info["images"] and linear.max_offset == srgb.max_offset
    assert bool((linear.mean < srgb.mean).all())  # decoding darkens mid-tones
    assert shipped_image_statistics("LINEAR") is linear


def test_linear_statistics_are_those_of_the_decoded_images() -> None:
    gen = torch.Generator().manual_seed(4)
    images = torch.rand(2, 3, 20, 22, generator=gen)
    linear = estimate_image_statistics(images, max_offset=3, domain="linear")
    decoded = estimate_image_statistics(srgb_to_linear(images.double()), max_offset=3)
    assert linear.domain == "linear" and decoded.domain == "srgb"
    torch.testing.assert_close(linear.second, decoded.second, rtol=1e-12, atol=1e-15)
    torch.testing.assert_close(linear.mean, decoded.mean, rtol=1e-12, atol=1e-15)


def test_closed_form_filters_under_signal_dependent_noise() -> None:
    """The filters equal an explicit solve with the diagonal noise variance ``a g + b`` at each
    window pixel's expected signal; more light lowers the expected error; several exposures at
    once equal one by one."""
    stats = shipped_image_statistics()
    kernels = pattern_pixel_kernels(patterns.get("A"))
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


def _scene(n: int = 2, size: int = 40, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, size + 4, size + 4, generator=g)
    return torch.nn.functional.avg_pool2d(x, 5, stride=1)


def test_batched_estimate_equals_per_image_estimates_and_their_gradients() -> None:
    """One solve and one grouped convolution for a batch of noise levels give the values and the
    kernel gradients of one call per image (float64)."""
    from splitcam.recon.closed_form import lmmse_estimate, shipped_image_statistics

    stats = shipped_image_statistics()
    raw = SplitterSensor("D")(_scene(3, 20).double())
    sig = torch.tensor([0.0, 7.0, 25.0], dtype=torch.float64)
    target = torch.rand(
        3, 3, 20, 20, generator=torch.Generator().manual_seed(5), dtype=torch.float64
    )
    grads, values = [], []
    for batched in (True, False):
        k = pattern_pixel_kernels(patterns.get("D")).clone().requires_grad_(True)
        if batched:
            out = lmmse_estimate(raw, k, sig, stats)
        else:
            out = torch.cat(
                [lmmse_estimate(raw[i : i + 1], k, float(sig[i]), stats) for i in range(3)]
            )
        (out * target).sum().backward()
        values.append(out.detach())
        grads.append(k.grad)
    torch.testing.assert_close(values[0], values[1], rtol=0, atol=1e-12)
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-10, atol=1e-10)


def test_a_kernel_too_large_for_the_statistics_says_what_to_do():
    import torch

    from splitcam.recon.closed_form import closed_form_mse

    with pytest.raises(ValueError, match="kernels up to 9x9 work with radius 4"):
        closed_form_mse(torch.full((1, 1, 3, 15, 15), 1 / 300), 0.0)
