"""Tests of the training-free baselines: classical demosaicking and the LMMSE reconstructor."""

from __future__ import annotations

import json
import math

import colour_demosaicing as cd
import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.data.patches import ImageCache
from splitcam.evaluation.metrics import psnr
from splitcam.evaluation.screening import evaluate_method, screen_patterns
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.base import Reconstructor as Method
from splitcam.recon.demosaic import ClassicalDemosaic
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


# ---------------------------------------------------------------------------------------------
# Bayer and classical demosaicking


def test_bayer_raw_is_the_rggb_mosaic_exactly():
    rgb = torch.rand(2, 3, 7, 10, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    raw = SplitterSensor("bayer")(rgb)
    for n in range(2):
        mosaic = cd.mosaicing_CFA_Bayer(rgb[n].permute(1, 2, 0).numpy(), "RGGB")
        assert torch.equal(raw[n, 0], torch.from_numpy(mosaic))


@pytest.mark.parametrize("method", ClassicalDemosaic.METHODS)
def test_classical_demosaic_equals_the_package(method):
    rgb = _smooth_images(2, 16, 20, seed=2)
    raw = SplitterSensor("bayer")(rgb)
    demosaic = ClassicalDemosaic(method)
    out = demosaic.reconstruct(raw, 0.0)
    function = getattr(
        cd,
        {
            "bilinear": "demosaicing_CFA_Bayer_bilinear",
            "malvar2004": "demosaicing_CFA_Bayer_Malvar2004",
            "menon2007": "demosaicing_CFA_Bayer_Menon2007",
        }[method],
    )
    for n in range(2):
        mosaic = cd.mosaicing_CFA_Bayer(rgb[n].permute(1, 2, 0).numpy(), "RGGB")
        expected = torch.from_numpy(function(mosaic, "RGGB")).permute(2, 0, 1)
        assert torch.equal(out[n], expected)
    assert out.dtype == torch.float64
    # sigma is ignored: no denoising.
    assert torch.equal(demosaic.reconstruct(raw, 25.0), out)
    assert demosaic.reconstruct(raw.float(), 0).dtype == torch.float32
    assert isinstance(demosaic, Method) and demosaic.pattern.name == "bayer"


def test_bilinear_on_a_smooth_image():
    yy, xx = torch.meshgrid(torch.arange(64.0), torch.arange(64.0), indexing="ij")
    rgb = torch.stack(
        [
            0.5 + 0.3 * torch.sin(2 * math.pi * xx / 40),
            0.5 + 0.3 * torch.cos(2 * math.pi * yy / 50),
            0.5 + 0.2 * torch.sin(2 * math.pi * (xx + yy) / 60),
        ]
    ).double()
    out = ClassicalDemosaic("bilinear").reconstruct(SplitterSensor("bayer")(rgb[None]), 0)
    # The package's reflective border handling mixes the mosaic's zeros into the outermost
    # pixels (errors up to 0.6 there), so only the interior is held to a tight bound.
    assert psnr(out[0], rgb, crop=2) > 45


def test_unknown_demosaic_method():
    with pytest.raises(ValueError, match="bilinear, malvar2004, menon2007.*'ahd'"):
        ClassicalDemosaic("ahd")


# ---------------------------------------------------------------------------------------------
# LMMSE filters against an independent least-squares computation


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
    whole = fit_lmmse("E", images, radius=1)
    pooled = fit_lmmse("E", images[:1], radius=1) + fit_lmmse("E", images[1:], radius=1)
    assert torch.equal(pooled.counts, whole.counts)
    for a, b in zip(pooled.filters(4.0), whole.filters(4.0), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="same pattern and radius"):
        whole + fit_lmmse("E", images, radius=2)


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


# ---------------------------------------------------------------------------------------------
# LMMSE reconstruction


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
    method = LMMSE(fit_lmmse("D", colours.expand(8, 3, 12, 12), radius=2))
    scene = torch.tensor([0.2, 0.7, 0.4], dtype=torch.float64).view(1, 3, 1, 1).expand(1, 3, 20, 20)
    out = method.reconstruct(SplitterSensor("D")(scene), 0.0)
    inner = slice(3, -3)
    torch.testing.assert_close(out[..., inner, inner], scene[..., inner, inner], atol=1e-6, rtol=0)


def test_lmmse_input_validation():
    with pytest.raises(ValueError, match="expected patches of at least"):
        fit_lmmse("A", torch.rand(1, 3, 8, 8), radius=4)
    with pytest.raises(ValueError, match="expected radius"):
        fit_lmmse("A", torch.rand(1, 3, 16, 16), radius=-1)
    method = LMMSE(fit_lmmse("E", _smooth_images(1, 12, 12, seed=9), radius=1))
    with pytest.raises(ValueError, match=r"expected \(N, 1, H, W\)"):
        method.reconstruct(torch.rand(1, 3, 8, 8), 0.0)
    with pytest.raises(ValueError, match="expected a finite sigma >= 0"):
        method.reconstruct(torch.rand(1, 1, 8, 8), -1.0)


# ---------------------------------------------------------------------------------------------
# Saving and loading


def test_save_load_round_trip_and_damaged_files(tmp_path):
    method = LMMSE(fit_lmmse("B", _smooth_images(2, 16, 16, seed=10), radius=2))
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


# ---------------------------------------------------------------------------------------------
# Evaluation and screening


def test_screen_patterns_on_a_few_training_images(shared_data):
    cache = ImageCache(shared_data / "train", min_size=32, max_images=3, progress=False)
    tests = [(f"synthetic{i}", img.float()) for i, img in enumerate(_smooth_images(2, 24, 30, 12))]
    result = screen_patterns(
        ["D", "bayer"], cache, tests, sigmas=(0, 10), radius=2, patches=16, patch_size=32
    )
    assert len(result.rows) == 4 and len(result.per_image) == 8
    for sigma, order in result.ranking.items():
        assert sorted(order) == ["D", "bayer"]
        ranked = sorted((r for r in result.rows if r["sigma"] == sigma), key=lambda r: r["rank"])
        assert [r["pattern"] for r in ranked] == order
        assert ranked[0]["psnr"] >= ranked[1]["psnr"]
    for row in result.rows:
        assert row["fit_seconds"] > 0 and row["eval_seconds"] > 0
        assert 0 < row["ssim"] <= 1 and row["ciede2000"] >= 0
    # The screen scores exactly what evaluate_method gives for the same fit.
    again = evaluate_method(LMMSE(result.statistics["D"]), tests, [10])
    mine = [r for r in result.per_image if r["pattern"] == "D" and r["sigma"] == 10]
    assert [r["psnr"] for r in again] == [r["psnr"] for r in mine]
