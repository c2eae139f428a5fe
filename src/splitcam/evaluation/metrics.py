"""Image-quality metrics with the paper's evaluation conventions (model.md §7).

Every metric first brings both images to 8 bits the same way: clamp to [0, 1], multiply by 255,
round to integers (:func:`quantize`). The metrics are then computed in float64 on those integer
values:

- :func:`psnr`: ``10 log10(255^2 / MSE)``, MSE over all pixels and the 3 channels.
- :func:`ssim`: per channel, 11x11 Gaussian window (sigma 1.5), only the positions where the
  window fits inside the image, ``C1 = (0.01 * 255)^2``, ``C2 = (0.03 * 255)^2``; mean of the
  map, then mean over the 3 channels. Computed by ``skimage.metrics.structural_similarity`` with
  every convention passed explicitly.
- :func:`ciede2000`: 8-bit sRGB -> CIELAB (D65, 2-degree observer), CIEDE2000 per pixel, mean
  over the pixels (what MATLAB's ``imcolordiff`` gives by default, averaged). Lower is better.
  Our own :func:`delta_e_ciede2000`, not scikit-image's (see there why).

Memory stays bounded on large images: the images are quantised to uint8 (one byte per value,
strip by strip, never as a whole float64 copy) and every metric runs over strips of rows of
about :data:`STRIP_PIXELS` pixels, in float64 within the strip. PSNR and CIEDE2000 are sums over
the strips; SSIM strips carry the window's 5-row halo above and below, so every SSIM map value
is the whole-image one and the mean over the strips is the whole-image mean.

Images are channel-first ``(3, H, W)`` torch tensors or numpy arrays, either float in [0, 1]
or uint8 in 0..255 (taken as already quantised). Per-image values are averaged over a test set
with :func:`mean_over_images`, which keeps the infinite PSNR of identical images out of the mean.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
import torch
from skimage.color import rgb2lab
from skimage.metrics import structural_similarity

__all__ = [
    "STRIP_PIXELS",
    "ImageMean",
    "ciede2000",
    "compute_all",
    "delta_e_ciede2000",
    "mean_over_images",
    "psnr",
    "quantize",
    "srgb_to_lab",
    "ssim",
]

#: SSIM window: 11x11 Gaussian with standard deviation 1.5 (Wang et al. 2004).
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03

#: Pixels per row strip (per channel) in which the metrics are computed. The CIEDE2000 of a strip
#: holds a few dozen float64 arrays of this size (about 2 MiB each), SSIM about fifteen; larger
#: strips are not faster.
STRIP_PIXELS = 1 << 18

# 25^7 appears in G and R_C of CIEDE2000; exact in float64.
_POW25_7 = 25.0**7


def _round_to_255(arr: np.ndarray) -> np.ndarray:
    """The one rounding rule: float64 values in [0, 1] (clamped) to integers 0..255, as float64."""
    if np.isnan(arr).any():
        raise ValueError("image contains NaN values")
    return np.rint(np.clip(arr, 0.0, 1.0) * 255.0)


def _as_array(img: torch.Tensor | np.ndarray) -> torch.Tensor | np.ndarray:
    """``img`` without copying: numpy arrays as they are, tensors detached (left on their device).

    Raises:
        TypeError: If the dtype is neither floating point nor uint8.
    """
    if isinstance(img, torch.Tensor):
        t = img.detach()
        if t.dtype != torch.uint8 and not t.is_floating_point():
            raise TypeError(f"expected a floating-point or uint8 image, got {t.dtype}")
        return t
    arr = np.asarray(img)
    if arr.dtype != np.uint8 and arr.dtype.kind != "f":
        raise TypeError(f"expected a floating-point or uint8 image, got {arr.dtype}")
    return arr


def _rows_to_float64(img: torch.Tensor | np.ndarray) -> np.ndarray:
    """A slice of a float image (from :func:`_as_array`) as a float64 numpy array on the CPU."""
    if isinstance(img, torch.Tensor):
        return img.to(device="cpu", dtype=torch.float64).numpy()
    return img.astype(np.float64)


def quantize(img: torch.Tensor | np.ndarray) -> np.ndarray:
    """Bring an image to the 8-bit integer grid used by every metric, as float64.

    Float input is taken as lying in [0, 1]: it is clamped to [0, 1], multiplied by 255 in
    float64 and rounded with ``np.rint`` (round half to even, like ``torch.round``; MATLAB's
    ``im2uint8`` rounds half away from zero instead, which differs only on exact ties
    ``k + 0.5``). uint8 input is taken as already quantised and only converted to float64.
    The metrics themselves use the same rounding but keep the result in uint8, strip by strip
    (8 times less memory than this float64 copy).

    Args:
        img: Image of any shape, a torch tensor or numpy array, float in [0, 1] or uint8.

    Returns:
        float64 array of the same shape holding integers 0..255.

    Raises:
        TypeError: If the dtype is neither floating point nor uint8.
        ValueError: If a float image contains NaN (clamping would hide the failure).

    Shape:
        - img: any, e.g. ``(3, H, W)``.
        - output: same as ``img``.
    """
    arr = _as_array(img)
    if isinstance(arr, torch.Tensor) and arr.dtype == torch.uint8:
        return arr.cpu().numpy().astype(np.float64)
    if isinstance(arr, np.ndarray) and arr.dtype == np.uint8:
        return arr.astype(np.float64)
    return _round_to_255(_rows_to_float64(arr))


def _quantize_uint8(img: torch.Tensor | np.ndarray) -> np.ndarray:
    """:func:`quantize` to uint8, in strips of rows so no whole-image float64 copy is made.

    Shape:
        - img: ``(C, H, W)`` (checked by the caller); output the same, uint8.
    """
    if isinstance(img, torch.Tensor) and img.dtype == torch.uint8:
        return img.cpu().numpy()
    if isinstance(img, np.ndarray) and img.dtype == np.uint8:
        return img
    c, h, w = img.shape
    out = np.empty((c, h, w), dtype=np.uint8)
    rows = _strip_rows(w)
    for top in range(0, h, rows):
        out[:, top : top + rows] = _round_to_255(_rows_to_float64(img[:, top : top + rows]))
    return out


def _strip_rows(width: int) -> int:
    return max(1, STRIP_PIXELS // max(width, 1))


def _strips(h: int, w: int) -> Iterator[slice]:
    rows = _strip_rows(w)
    for top in range(0, h, rows):
        yield slice(top, min(h, top + rows))


def _check_crop(crop: int) -> int:
    if isinstance(crop, bool) or not isinstance(crop, (int, np.integer)):
        raise TypeError(f"crop must be an integer, got {type(crop).__name__}")
    if crop < 0:
        raise ValueError(f"crop must be >= 0, got {crop}")
    return int(crop)


def _prepare_pair(
    x: torch.Tensor | np.ndarray,
    y: torch.Tensor | np.ndarray,
    crop: int,
    min_size: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Validate, quantise and border-crop two images; returns uint8 ``(3, h, w)`` arrays.

    The whole image is quantised (so a NaN in the border is still reported), then cropped as a
    view. ``min_size`` is the smallest height and width that must remain after cropping (SSIM
    needs room for its window).
    """
    crop = _check_crop(crop)
    xa, ya = _as_array(x), _as_array(y)
    for a in (xa, ya):
        if a.ndim != 3 or a.shape[0] != 3:
            raise ValueError(f"expected (3, H, W), got {tuple(a.shape)}")
    if tuple(xa.shape) != tuple(ya.shape):
        raise ValueError(
            f"expected images of the same shape, got {tuple(xa.shape)} and {tuple(ya.shape)}"
        )
    _, h, w = xa.shape
    if min(h, w) - 2 * crop < min_size:
        raise ValueError(
            f"crop={crop} on a {tuple(xa.shape)} image leaves "
            f"{max(h - 2 * crop, 0)}x{max(w - 2 * crop, 0)} pixels, "
            f"need at least {min_size}x{min_size}"
        )
    xq, yq = _quantize_uint8(xa), _quantize_uint8(ya)
    if crop:
        xq = xq[:, crop:-crop, crop:-crop]
        yq = yq[:, crop:-crop, crop:-crop]
    return xq, yq


def _psnr_quantized(xq: np.ndarray, yq: np.ndarray, data_range: float) -> float:
    _, h, w = xq.shape
    # Integer sum of squared differences: exact, whatever the strip order.
    sse = 0
    for rows in _strips(h, w):
        d = xq[:, rows].astype(np.int32) - yq[:, rows].astype(np.int32)
        sse += int(np.square(d).sum(dtype=np.int64))
    if sse == 0:
        return math.inf
    return 10.0 * math.log10(data_range**2 / (sse / xq.size))


def psnr(
    x: torch.Tensor | np.ndarray,
    y: torch.Tensor | np.ndarray,
    *,
    data_range: float = 255.0,
    crop: int = 0,
) -> float:
    """Peak signal-to-noise ratio of two images after 8-bit quantisation.

    ``PSNR = 10 log10(data_range^2 / MSE)``, the MSE taken over all pixels and the 3 channels
    of the quantised (0..255) images (the squared errors are summed exactly, in integers).

    Args:
        x: Reconstructed image, float in [0, 1] or uint8.
        y: Reference image, same convention.
        data_range: Peak value; 255 because the images are compared on the 8-bit grid.
        crop: Border pixels removed from each side before computing (0 = no crop).

    Returns:
        PSNR in dB; ``math.inf`` when the quantised images are identical.

    Raises:
        ValueError: On a shape other than ``(3, H, W)``, mismatched shapes, a negative crop
            or a crop that leaves no pixels.

    Shape:
        - x, y: ``(3, H, W)``.

    >>> import torch
    >>> truth = torch.full((3, 4, 4), 0.5)
    >>> guess = truth.clone()
    >>> guess[0, 0, 0] = 0.6  # one value of 48 off by 25 steps of 255
    >>> round(psnr(guess, truth), 2)  # 10 log10(255^2 / (25^2 / 48))
    36.98
    >>> psnr(guess, truth, crop=1)  # the border left out: identical images
    inf
    """
    xq, yq = _prepare_pair(x, y, crop)
    return _psnr_quantized(xq, yq, data_range)


def _ssim_quantized(xq: np.ndarray, yq: np.ndarray, data_range: float) -> float:
    _, h, w = xq.shape
    halo = SSIM_WINDOW // 2
    # Strips of map rows [top, stop) read image rows [top - halo, stop + halo): exactly what the
    # window at those rows covers, so each map value is the whole-image one. scikit-image then
    # drops `halo` = (win_size - 1) // 2 map rows and columns at every edge of the strip, which
    # are the positions where the window does not fit inside the strip.
    rows = _strip_rows(w)
    total = 0.0
    for top in range(halo, h - halo, rows):
        stop = min(h - halo, top + rows)
        mean = structural_similarity(
            xq[:, top - halo : stop + halo],
            yq[:, top - halo : stop + halo],
            win_size=SSIM_WINDOW,
            gaussian_weights=True,
            sigma=SSIM_SIGMA,
            use_sample_covariance=False,
            data_range=data_range,
            channel_axis=0,
            K1=SSIM_K1,
            K2=SSIM_K2,
        )
        # Every strip row has the same number of map values per channel, so the row count
        # weights the strip means into the mean of the whole map.
        total += float(mean) * (stop - top)
    return total / (h - 2 * halo)


def ssim(
    x: torch.Tensor | np.ndarray,
    y: torch.Tensor | np.ndarray,
    *,
    data_range: float = 255.0,
    crop: int = 0,
) -> float:
    """Structural similarity (Wang et al. 2004) of two images after 8-bit quantisation.

    Per channel, with Gaussian-weighted local statistics (11x11 window, sigma 1.5, weights
    normalised to sum 1, population moments)::

        SSIM = (2 mu_x mu_y + C1)(2 sigma_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(s_x^2 + s_y^2 + C2))

    with ``C1 = (0.01 L)^2``, ``C2 = (0.03 L)^2``, ``L = data_range``, evaluated only where the
    window fits inside the image; the map is averaged per channel, then over the 3 channels, in
    float64. Computed by ``skimage.metrics.structural_similarity`` with each of these choices
    passed explicitly rather than left to its defaults (``gaussian_weights=True, sigma=1.5,
    win_size=11, use_sample_covariance=False, K1, K2, data_range``); it filters in float64 and
    drops the ``(win_size - 1) // 2 = 5`` outermost map rows and columns before the mean, which
    are exactly the positions where the window does not fit. Computed in strips of rows with a
    5-row halo (see the module docstring); the tests check it against an independent float64
    implementation.

    Args:
        x: Reconstructed image, float in [0, 1] or uint8.
        y: Reference image, same convention.
        data_range: Dynamic range L of the quantised images.
        crop: Border pixels removed from each side before computing (0 = no crop).

    Returns:
        Mean SSIM, at most 1 (1 for identical images).

    Raises:
        ValueError: On a shape other than ``(3, H, W)``, mismatched shapes, a negative crop,
            or an image (after cropping) smaller than the 11x11 window.

    Shape:
        - x, y: ``(3, H, W)`` with ``H, W >= 11 + 2 * crop``.
    """
    xq, yq = _prepare_pair(x, y, crop, min_size=SSIM_WINDOW)
    return _ssim_quantized(xq, yq, data_range)


def srgb_to_lab(rgb255: np.ndarray) -> np.ndarray:
    """Convert 8-bit sRGB values to CIELAB.

    Uses ``skimage.color.rgb2lab`` on ``rgb255 / 255`` with illuminant D65 and the CIE 1931
    2-degree observer (the sRGB white point, as MATLAB's ``rgb2lab`` default), in float64.

    Args:
        rgb255: sRGB values in 0..255 (integers, or integer-valued floats), channel last.

    Returns:
        float64 array of ``(L*, a*, b*)`` triples.

    Shape:
        - rgb255: ``(..., 3)``.
        - output: ``(..., 3)``.
    """
    rgb = np.asarray(rgb255, dtype=np.float64)
    if rgb.ndim == 0 or rgb.shape[-1] != 3:
        raise ValueError(f"expected (..., 3), got {tuple(rgb.shape)}")
    return rgb2lab(rgb / 255.0, illuminant="D65", observer="2")


def delta_e_ciede2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """CIEDE2000 colour difference, vectorised, with ``kL = kC = kH = 1``.

    Our own rather than ``skimage.color.deltaE_ciede2000``: that function decides the
    ``|h1' - h2'| <= 180`` branches from the two hue angles after rounding, so for chroma vectors
    that are exactly opposite (hue difference exactly 180 degrees) it takes the other branch for
    a share of the pairs, and its mean hue, hence ΔE00, jumps (e.g. by 0.04 for a pair next to
    Sharma et al.'s test pair 10; see the tests). Elsewhere the two agree to float rounding, so
    on ordinary images the scores are the same; ours follows the published convention at every
    input.

    Follows the equations of Sharma, Wu & Dalal, "The CIEDE2000 color-difference formula:
    implementation notes, supplementary test data, and mathematical observations", Color Res.
    Appl. 30(1):21-30, 2005, including their conventions for the hue angle:

    - when either chroma ``C'`` is 0 the paper fixes ``h' = 0``, ``dh' = 0`` and the mean hue
      ``h1' + h2'``; none of these reach ΔE00, since ``dH' = 2 sqrt(C1' C2') sin(dh' / 2)`` is 0
      and the mean hue only enters through ``S_H`` and ``R_T``, both applied to ``dH'``. They
      are therefore not special-cased here;
    - ``|h1' - h2'| <= 180`` picks the plain mean hue ``(h1' + h2') / 2``, so a hue difference
      of exactly 180 degrees (their test pairs 13-15 sit on either side of and at this point)
      uses the plain mean. Whether two hues are exactly opposite is decided from the chroma
      vectors (zero cross product, negative dot product), which is exact in floating point
      for ``(a', b')`` and ``(-a', -b')``, rather than from the two rounded angles.

    Args:
        lab1: CIELAB colours ``(L*, a*, b*)``.
        lab2: CIELAB colours, broadcastable against ``lab1``.

    Returns:
        float64 array of ΔE00 values, one per colour pair.

    Raises:
        ValueError: If the last axis does not have length 3.

    Shape:
        - lab1, lab2: ``(..., 3)`` (broadcastable).
        - output: ``(...)``.
    """
    lab1 = np.asarray(lab1, dtype=np.float64)
    lab2 = np.asarray(lab2, dtype=np.float64)
    for lab in (lab1, lab2):
        if lab.ndim == 0 or lab.shape[-1] != 3:
            raise ValueError(f"expected (..., 3), got {tuple(lab.shape)}")
    l1, a1, b1 = np.moveaxis(lab1, -1, 0)
    l2, a2, b2 = np.moveaxis(lab2, -1, 0)

    c_bar_ab = 0.5 * (np.hypot(a1, b1) + np.hypot(a2, b2))
    c7 = c_bar_ab**7
    g = 0.5 * (1.0 - np.sqrt(c7 / (c7 + _POW25_7)))
    a1p = (1.0 + g) * a1
    a2p = (1.0 + g) * a2
    c1p = np.hypot(a1p, b1)
    c2p = np.hypot(a2p, b2)
    h1p = _hue_degrees(a1p, b1)
    h2p = _hue_degrees(a2p, b2)

    dh_raw = h2p - h1p
    abs_dh = np.abs(dh_raw)
    opposite = (a1p * b2 - a2p * b1 == 0.0) & (a1p * a2p + b1 * b2 < 0.0)
    abs_dh = np.where(opposite, 180.0, abs_dh)
    dh_raw = np.where(opposite, np.copysign(180.0, dh_raw), dh_raw)

    dhp = np.where(abs_dh <= 180.0, dh_raw, np.where(dh_raw > 0.0, dh_raw - 360.0, dh_raw + 360.0))
    d_lp = l2 - l1
    d_cp = c2p - c1p
    d_hp = 2.0 * np.sqrt(c1p * c2p) * np.sin(np.radians(dhp) / 2.0)

    l_bar = 0.5 * (l1 + l2)
    c_bar = 0.5 * (c1p + c2p)
    h_sum = h1p + h2p
    h_bar = np.where(
        abs_dh <= 180.0,
        0.5 * h_sum,
        np.where(h_sum < 360.0, 0.5 * (h_sum + 360.0), 0.5 * (h_sum - 360.0)),
    )

    t = (
        1.0
        - 0.17 * np.cos(np.radians(h_bar - 30.0))
        + 0.24 * np.cos(np.radians(2.0 * h_bar))
        + 0.32 * np.cos(np.radians(3.0 * h_bar + 6.0))
        - 0.20 * np.cos(np.radians(4.0 * h_bar - 63.0))
    )
    d_theta = 30.0 * np.exp(-(((h_bar - 275.0) / 25.0) ** 2))
    c_bar7 = c_bar**7
    r_c = 2.0 * np.sqrt(c_bar7 / (c_bar7 + _POW25_7))
    l50 = (l_bar - 50.0) ** 2
    s_l = 1.0 + 0.015 * l50 / np.sqrt(20.0 + l50)
    s_c = 1.0 + 0.045 * c_bar
    s_h = 1.0 + 0.015 * c_bar * t
    r_t = -np.sin(np.radians(2.0 * d_theta)) * r_c

    tl = d_lp / s_l
    tc = d_cp / s_c
    th = d_hp / s_h
    return np.sqrt(tl**2 + tc**2 + th**2 + r_t * tc * th)


def _hue_degrees(ap: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hue angle ``atan2(b, a')`` in degrees in [0, 360)."""
    h = np.degrees(np.arctan2(b, ap))
    h = np.where(h < 0.0, h + 360.0, h)
    # A tiny negative angle plus 360 can round to exactly 360.
    return np.where(h >= 360.0, h - 360.0, h)


def _ciede2000_quantized(xq: np.ndarray, yq: np.ndarray) -> float:
    _, h, w = xq.shape
    total = 0.0
    for rows in _strips(h, w):
        lab_x = srgb_to_lab(np.moveaxis(xq[:, rows], 0, -1))
        lab_y = srgb_to_lab(np.moveaxis(yq[:, rows], 0, -1))
        total += float(delta_e_ciede2000(lab_x, lab_y).sum())
    return total / (h * w)


def ciede2000(
    x: torch.Tensor | np.ndarray,
    y: torch.Tensor | np.ndarray,
    *,
    crop: int = 0,
) -> float:
    """Mean CIEDE2000 colour difference of two images after 8-bit quantisation.

    Both images are read as 8-bit sRGB, converted to CIELAB (D65, 2-degree observer, see
    :func:`srgb_to_lab`), compared per pixel with :func:`delta_e_ciede2000` and the differences
    averaged over the pixels. Lower is better.

    Args:
        x: Reconstructed image, float in [0, 1] or uint8.
        y: Reference image, same convention.
        crop: Border pixels removed from each side before computing (0 = no crop).

    Returns:
        Mean ΔE00 over the pixels (0 for identical images).

    Raises:
        ValueError: On a shape other than ``(3, H, W)``, mismatched shapes, a negative crop
            or a crop that leaves no pixels.

    Shape:
        - x, y: ``(3, H, W)``.
    """
    xq, yq = _prepare_pair(x, y, crop)
    return _ciede2000_quantized(xq, yq)


def compute_all(
    x: torch.Tensor | np.ndarray,
    y: torch.Tensor | np.ndarray,
    *,
    crop: int = 0,
) -> dict[str, float]:
    """PSNR, SSIM and CIEDE2000 of one image pair, quantising once.

    Args:
        x: Reconstructed image, float in [0, 1] or uint8.
        y: Reference image, same convention.
        crop: Border pixels removed from each side before computing (0 = no crop).

    Returns:
        ``{"psnr": dB, "ssim": ..., "ciede2000": mean ΔE00}`` with the default data range 255.

    Raises:
        ValueError: As :func:`ssim` (the strictest size requirement of the three).

    Shape:
        - x, y: ``(3, H, W)`` with ``H, W >= 11 + 2 * crop``.
    """
    xq, yq = _prepare_pair(x, y, crop, min_size=SSIM_WINDOW)
    return {
        "psnr": _psnr_quantized(xq, yq, 255.0),
        "ssim": _ssim_quantized(xq, yq, 255.0),
        "ciede2000": _ciede2000_quantized(xq, yq),
    }


@dataclass(frozen=True)
class ImageMean:
    """Average of a per-image metric over a set of images.

    Attributes:
        mean: Mean over the finite values; ``math.inf`` if every value is ``+inf``.
        n_images: Number of values averaged, including the infinite ones.
        n_infinite: Number of ``+inf`` values (identical images under PSNR) left out of ``mean``.
    """

    mean: float
    n_images: int
    n_infinite: int


def mean_over_images(values: Iterable[float]) -> ImageMean:
    """Average per-image metric values, keeping infinite PSNRs out of the mean.

    An identical reconstruction has PSNR ``+inf``; a plain mean would then be ``inf`` and hide
    every other image. The choice here: ``mean`` is taken over the finite values only and the
    number of ``+inf`` values is reported next to it, so a table can print e.g.
    ``"41.2 dB (1 of 24 images identical)"``. If every value is ``+inf`` the mean is ``+inf``
    (there is nothing finite to average, and the images are indeed all identical).

    Args:
        values: Per-image values (floats).

    Returns:
        An :class:`ImageMean` with the mean, the number of images and the number of ``+inf``.

    Raises:
        ValueError: If ``values`` is empty, contains NaN or ``-inf`` (neither comes from a
            valid metric, so they point at a bug upstream rather than something to average).

    Shape:
        - values: ``(N,)``, ``N >= 1``.
    """
    arr = np.asarray(list(values), dtype=np.float64).reshape(-1)
    if arr.size == 0:
        raise ValueError("expected at least one value, got none")
    if np.isnan(arr).any():
        raise ValueError("values contain NaN")
    if (arr == -np.inf).any():
        raise ValueError("values contain -inf")
    finite = arr[np.isfinite(arr)]
    n_inf = int(arr.size - finite.size)
    mean = float(finite.mean()) if finite.size else math.inf
    return ImageMean(mean=mean, n_images=int(arr.size), n_infinite=n_inf)
