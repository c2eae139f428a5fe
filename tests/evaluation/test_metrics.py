"""Tests of splitcam.evaluation.metrics against published data, scikit-image, hand computation."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
import torch
from scipy.signal import correlate2d
from skimage.color import deltaE_ciede2000, rgb2lab

from splitcam.evaluation.metrics import (
    ImageMean,
    ciede2000,
    compute_all,
    delta_e_ciede2000,
    mean_over_images,
    psnr,
    quantize,
    srgb_to_lab,
    ssim,
)

# Sharma, Wu & Dalal (2005), Table 1: L1, a1, b1, L2, a2, b2, ΔE00 (kL = kC = kH = 1).
SHARMA_TABLE = np.array(
    [
        [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
        [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
        [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
        [50.0000, -1.3802, -84.2814, 50.0000, 0.0000, -82.7485, 1.0000],
        [50.0000, -1.1848, -84.8006, 50.0000, 0.0000, -82.7485, 1.0000],
        [50.0000, -0.9009, -85.5211, 50.0000, 0.0000, -82.7485, 1.0000],
        [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
        [50.0000, -1.0000, 2.0000, 50.0000, 0.0000, 0.0000, 2.3669],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0010, 7.1792],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0011, 7.2195],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0012, 7.2195],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0009, -2.4900, 4.8045],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0010, -2.4900, 4.8045],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0011, -2.4900, 4.7461],
        [50.0000, 2.5000, 0.0000, 50.0000, 0.0000, -2.5000, 4.3065],
        [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
        [50.0000, 2.5000, 0.0000, 61.0000, -5.0000, 29.0000, 22.8977],
        [50.0000, 2.5000, 0.0000, 56.0000, -27.0000, -3.0000, 31.9030],
        [50.0000, 2.5000, 0.0000, 58.0000, 24.0000, 15.0000, 19.4535],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.2972, 0.0000, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 1.8634, 0.5757, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.2592, 0.3350, 1.0000],
        [60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644],
        [63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630],
        [61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731],
        [35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645],
        [22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373],
        [36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146],
        [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
        [90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381],
        [6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377],
        [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
    ]
)


def _random_images(seed: int, shape: tuple[int, ...] = (3, 24, 30)) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, shape, dtype=np.uint8), rng.integers(0, 256, shape, dtype=np.uint8)


def test_delta_e_sharma_table() -> None:
    assert SHARMA_TABLE.shape == (34, 7)
    lab1, lab2, expected = SHARMA_TABLE[:, 0:3], SHARMA_TABLE[:, 3:6], SHARMA_TABLE[:, 6]
    np.testing.assert_allclose(delta_e_ciede2000(lab1, lab2), expected, rtol=0, atol=1e-4)
    # The formula is symmetric; swapping flips the signs of dC' and dH' together.
    np.testing.assert_allclose(
        delta_e_ciede2000(lab2, lab1), delta_e_ciede2000(lab1, lab2), rtol=0, atol=1e-12
    )


def test_delta_e_exactly_opposite_hues_use_plain_mean_hue() -> None:
    # Colour 1 has hue in (0, 180), colour 2 the exactly opposite chroma direction, so
    # h2' - h1' = +180 and the paper's rule gives the plain mean (h1' + h2') / 2. That is the
    # limit from the side where colour 2 is turned slightly clockwise (difference < 180); the
    # other side jumps by 180 degrees in mean hue. Rounded angles alone get this wrong for a
    # noticeable share of such pairs.
    rng = np.random.default_rng(3)
    n = 3000
    ang = rng.uniform(0.01, np.pi - 0.01, n)
    r = rng.uniform(0.1, 30.0, n)
    a, b = r * np.cos(ang), r * np.sin(ang)
    # Powers of two keep the opposite vector exactly opposite and make dC' != 0, so that the
    # sign of dh' = +-180 matters through the R_T term.
    scale = rng.choice([0.5, 1.0, 2.0], n)
    l1, l2 = rng.uniform(0, 100, n), rng.uniform(0, 100, n)
    lab1 = np.stack([l1, a, b], axis=-1)
    opposite = np.stack([l2, -scale * a, -scale * b], axis=-1)
    eps = 1e-9
    ta, tb = a * np.cos(eps) + b * np.sin(eps), -a * np.sin(eps) + b * np.cos(eps)
    turned = np.stack([l2, -scale * ta, -scale * tb], axis=-1)
    expected = delta_e_ciede2000(lab1, turned)
    np.testing.assert_allclose(delta_e_ciede2000(lab1, opposite), expected, rtol=0, atol=1e-6)
    # Reversed order: h2' - h1' = -180, still the plain mean, and dH' changes sign with dC'.
    np.testing.assert_allclose(delta_e_ciede2000(opposite, lab1), expected, rtol=0, atol=1e-6)
    # Why we keep our own: scikit-image decides the +-180 branch from rounded angles and lands
    # on the far side for a share of these pairs, its value jumping away from the limit.
    theirs = deltaE_ciede2000(lab1, opposite)
    wrong = np.abs(theirs - expected) > 1e-3
    assert wrong.mean() > 0.01, "scikit-image now handles opposite hues: reconsider ours"


def test_delta_e_broadcasts_and_checks_shape() -> None:
    rng = np.random.default_rng(1)
    lab1 = rng.uniform([0, -80, -80], [100, 80, 80], size=(4, 5, 3))
    lab2 = rng.uniform([0, -80, -80], [100, 80, 80], size=(3,))
    out = delta_e_ciede2000(lab1, lab2)
    assert out.shape == (4, 5) and out.dtype == np.float64
    expected = [delta_e_ciede2000(lab1[i, j], lab2) for i in range(4) for j in range(5)]
    np.testing.assert_allclose(out.ravel(), expected, rtol=0, atol=1e-12)
    assert delta_e_ciede2000(lab2, lab2) == 0.0
    with pytest.raises(ValueError, match=r"expected \(\.\.\., 3\)"):
        delta_e_ciede2000(np.zeros((5, 4)), np.zeros((5, 4)))


def test_srgb_to_lab_is_d65() -> None:
    # Standard sRGB red in CIELAB under D65 (under D50 it would be about (54.29, 80.80, 69.89)).
    np.testing.assert_allclose(srgb_to_lab([255, 0, 0]), [53.2408, 80.0925, 67.2032], atol=1e-3)
    np.testing.assert_allclose(srgb_to_lab([255, 255, 255]), [100.0, 0.0, 0.0], atol=1e-2)
    np.testing.assert_allclose(srgb_to_lab([0, 0, 0]), [0.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_ciede2000_matches_skimage(seed: int) -> None:
    x, y = _random_images(seed)
    # Include greys (near-zero chroma, noisy hue) and saturated primaries.
    x[:, :4] = x[0:1, :4]
    y[:, :2] = y[1:2, :2]
    y[:, -1, :] = np.array([255, 0, 0], dtype=np.uint8)[:, None]
    expected = deltaE_ciede2000(
        rgb2lab(np.moveaxis(x, 0, -1) / 255.0), rgb2lab(np.moveaxis(y, 0, -1) / 255.0)
    ).mean()
    assert abs(ciede2000(x, y) - expected) < 1e-6
    assert ciede2000(x, x) == 0.0


def test_ciede2000_float_and_torch_inputs_agree_with_uint8() -> None:
    x, y = _random_images(5)
    expected = ciede2000(x, y)
    assert ciede2000(x / 255.0, y / 255.0) == pytest.approx(expected, abs=1e-12)
    xt = torch.from_numpy(x).to(torch.float32) / 255
    yt = torch.from_numpy(y).to(torch.float32) / 255
    assert ciede2000(xt, yt) == pytest.approx(expected, abs=1e-12)


def _reference_ssim(x: np.ndarray, y: np.ndarray, data_range: float = 255.0) -> float:
    """Plain 2-D float64 SSIM: explicit 11x11 Gaussian window, 'valid' correlation."""
    coords = np.arange(11, dtype=np.float64) - 5.0
    yy, xx = np.meshgrid(coords, coords, indexing="ij")
    window = np.exp(-(xx**2 + yy**2) / (2 * 1.5**2))
    window /= window.sum()
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2

    def filt(img: np.ndarray) -> np.ndarray:
        return correlate2d(img, window, mode="valid")

    means = []
    for xc, yc in zip(x.astype(np.float64), y.astype(np.float64), strict=True):
        mx, my = filt(xc), filt(yc)
        sxx = filt(xc * xc) - mx**2
        syy = filt(yc * yc) - my**2
        sxy = filt(xc * yc) - mx * my
        smap = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx**2 + my**2 + c1) * (sxx + syy + c2))
        means.append(smap.mean())
    return float(np.mean(means))


def test_ssim_matches_reference_implementation() -> None:
    x, y = _random_images(2, (3, 23, 31))
    assert abs(ssim(x, y) - _reference_ssim(x, y)) < 1e-10
    # A correlated pair, so that SSIM is far from 0 and the comparison is not trivial.
    rng = np.random.default_rng(4)
    noisy = np.clip(x.astype(np.int64) + rng.integers(-20, 21, x.shape), 0, 255).astype(np.uint8)
    value = ssim(x, noisy)
    assert 0.3 < value < 1.0
    assert abs(value - _reference_ssim(x, noisy)) < 1e-10
    assert abs(ssim(x, noisy, crop=3) - _reference_ssim(x[:, 3:-3, 3:-3], noisy[:, 3:-3, 3:-3])) < (
        1e-10
    )
    assert abs(ssim(x, noisy, data_range=100.0) - _reference_ssim(x, noisy, 100.0)) < 1e-10


def test_ssim_identical_is_one_and_needs_the_window() -> None:
    x, _ = _random_images(6, (3, 11, 11))
    assert ssim(x, x) == pytest.approx(1.0, abs=1e-12)
    assert ssim(x / 255.0, x) == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(ValueError, match="need at least 11x11"):
        ssim(x[:, :10], x[:, :10])
    with pytest.raises(ValueError, match="need at least 11x11"):
        ssim(x, x, crop=1)


def test_psnr_hand_computation() -> None:
    x = np.zeros((3, 2, 2), dtype=np.uint8)
    y = x.copy()
    y[1, 0, 1] = 10
    y[2, 1, 1] = 20
    mse = (10**2 + 20**2) / 12
    expected = 10 * math.log10(255**2 / mse)
    assert psnr(x, y) == pytest.approx(expected, abs=1e-12)
    assert psnr(x / 255.0, y / 255.0) == pytest.approx(expected, abs=1e-12)
    assert psnr(x, y, data_range=1.0) == pytest.approx(10 * math.log10(1 / mse), abs=1e-12)
    assert psnr(x, x) == math.inf
    assert psnr(torch.zeros(3, 2, 2), torch.from_numpy(y)) == pytest.approx(expected, abs=1e-12)


def test_psnr_crop() -> None:
    x = np.zeros((3, 4, 4), dtype=np.uint8)
    y = x.copy()
    y[:, 0, :] = 200  # border row only
    assert psnr(x, y, crop=1) == math.inf
    y[0, 1, 2] = 5  # inside the central 2x2
    assert psnr(x, y, crop=1) == pytest.approx(10 * math.log10(255**2 / (25 / 12)), abs=1e-12)
    assert psnr(x, y) < psnr(x, y, crop=1)


def test_quantize_clamps_and_rounds() -> None:
    values = np.array([-0.3, 1.7, 0.49 / 255, 0.51 / 255, 254.6 / 255, np.inf])
    np.testing.assert_array_equal(quantize(values), [0, 255, 0, 1, 255, 255])
    # Exact ties k + 0.5 go to the even integer.
    ties = np.array([0.5, 1.5, 2.5, 127.5]) / 255
    np.testing.assert_array_equal(quantize(ties), [0, 2, 2, 128])
    out = quantize(np.array([0, 7, 255], dtype=np.uint8))
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out, [0, 7, 255])
    t = torch.tensor([0.2, 0.6], dtype=torch.float32, requires_grad=True)
    np.testing.assert_array_equal(quantize(t), [51, 153])
    np.testing.assert_array_equal(quantize(torch.tensor([3, 250], dtype=torch.uint8)), [3, 250])


def test_quantize_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="NaN"):
        quantize(np.array([0.5, np.nan]))
    with pytest.raises(TypeError, match="int64"):
        quantize(np.array([1, 2], dtype=np.int64))
    with pytest.raises(TypeError, match="int64"):
        quantize(torch.tensor([1, 2]))


def test_compute_all_matches_individual_metrics() -> None:
    x, y = _random_images(7, (3, 16, 20))
    out = compute_all(x, y, crop=2)
    assert set(out) == {"psnr", "ssim", "ciede2000"}
    assert out["psnr"] == psnr(x, y, crop=2)
    assert out["ssim"] == ssim(x, y, crop=2)
    assert out["ciede2000"] == ciede2000(x, y, crop=2)


def test_mean_over_images() -> None:
    result = mean_over_images([30.0, math.inf, 40.0])
    assert result == ImageMean(mean=35.0, n_images=3, n_infinite=1)
    assert mean_over_images(np.array([1.0, 2.0])) == ImageMean(1.5, 2, 0)
    assert mean_over_images([math.inf, math.inf]) == ImageMean(math.inf, 2, 2)
    with pytest.raises(ValueError, match="at least one"):
        mean_over_images([])
    with pytest.raises(ValueError, match="NaN"):
        mean_over_images([1.0, math.nan])
    with pytest.raises(ValueError, match="-inf"):
        mean_over_images([1.0, -math.inf])


METRICS = [psnr, ssim, ciede2000, compute_all]


@pytest.mark.parametrize("metric", METRICS)
@pytest.mark.parametrize("shape", [(1, 3, 16, 16), (16, 16, 3), (16, 16), (4, 16, 16)])
def test_bad_shape(metric, shape) -> None:
    img = np.zeros(shape)
    with pytest.raises(ValueError, match=re.escape(f"expected (3, H, W), got {shape}")):
        metric(img, img)


@pytest.mark.parametrize("metric", METRICS)
def test_mismatched_shapes(metric) -> None:
    with pytest.raises(
        ValueError,
        match=r"expected images of the same shape, got \(3, 16, 16\) and \(3, 16, 17\)",
    ):
        metric(np.zeros((3, 16, 16)), np.zeros((3, 16, 17)))


@pytest.mark.parametrize("metric", METRICS)
def test_bad_crop(metric) -> None:
    img = np.zeros((3, 16, 16))
    with pytest.raises(ValueError, match="crop must be >= 0"):
        metric(img, img, crop=-1)
    with pytest.raises(ValueError, match="leaves 0x0 pixels"):
        metric(img, img, crop=8)
    with pytest.raises(TypeError, match="crop must be an integer"):
        metric(img, img, crop=1.0)


@pytest.mark.parametrize("strip_pixels", [1, 7 * 29, 40 * 29 - 1])
def test_strips_give_the_whole_image_values(monkeypatch, strip_pixels) -> None:
    """Any strip height (1 row, a few rows, all but a last one-row strip) gives the values of
    the whole image: PSNR exactly, SSIM and CIEDE2000 to float rounding."""
    import splitcam.evaluation.metrics as metrics

    x, y = _random_images(11, (3, 41, 29))
    rng = np.random.default_rng(12)
    noisy = np.clip(x.astype(np.int64) + rng.integers(-25, 26, x.shape), 0, 255).astype(np.uint8)
    whole = {f.__name__: f(x, noisy) for f in (psnr, ssim, ciede2000)}
    cropped = {f.__name__: f(x, noisy, crop=4) for f in (psnr, ssim, ciede2000)}
    monkeypatch.setattr(metrics, "STRIP_PIXELS", strip_pixels)
    assert psnr(x, noisy) == whole["psnr"]
    assert abs(ssim(x, noisy) - whole["ssim"]) < 1e-12
    assert abs(ssim(x, noisy) - _reference_ssim(x, noisy)) < 1e-10
    assert abs(ciede2000(x, noisy) - whole["ciede2000"]) < 1e-10
    assert psnr(x, noisy, crop=4) == cropped["psnr"]
    assert abs(ssim(x, noisy, crop=4) - cropped["ssim"]) < 1e-12
    assert abs(ciede2000(x, noisy, crop=4) - cropped["ciede2000"]) < 1e-10


def test_nan_in_the_cropped_border_is_still_reported() -> None:
    x = np.random.default_rng(0).random((3, 30, 30))
    y = x.copy()
    y[1, 0, 0] = np.nan
    for metric in (psnr, ssim, ciede2000):
        with pytest.raises(ValueError, match="NaN"):
            metric(y, x, crop=3)
