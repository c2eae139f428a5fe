"""Closed-form LMMSE for any kernels, from pattern-free image statistics (differentiable).

The raw neighbourhood ``x`` of a pixel of phase ``p`` is a linear function of the RGB scene in a
slightly larger window, ``x = A_p f`` (plus noise), where ``A_p`` holds the pixel kernels of Eq. 2
(:func:`splitcam.physics.sensor.pixel_kernels`) placed at each neighbour's offset. Natural images
are (to a good approximation) stationary, so the second-order statistics of ``f`` are those of
one small table that does not depend on the pattern: the mean colour ``mu`` and the
cross-channel autocovariance ``C[c, c', dy, dx] = Cov(f_c(y, x), f_c'(y + dy, x + dx))``
(:class:`ImageStatistics`, estimated once from training images and shipped). The LMMSE filters of
every pattern and every sigma then follow in closed form::

    W_p = C_yf A_pᵀ (A_p C_ff A_pᵀ + σ² I)⁻¹,      b_p = mu - W_p A_p mu_f

where ``C_ff`` is the covariance of the scene window, ``C_yf`` its rows at the centre pixel, and the
expected squared error per colour is ``tr(C_yy - W_p A_p C_fy) / 3``, with no images at all.

Compared with :func:`splitcam.recon.lmmse.fit_lmmse` (simulate the sensor on training patches and
gather the moments of its raw neighbourhoods) this needs no simulation, works for kernels that
change at every step of an optimisation, and is differentiable in the kernels, so gradients reach
a learned pattern through it (:func:`closed_form_filters`).

Statistics are shipped for both light domains (model.md §13): of the training images' sRGB
display values (``srgb``, the paper's protocol) and of their linear radiance (``linear``: each
image decoded with the sRGB transfer function before the moments are taken);
:func:`shipped_image_statistics` takes the domain, and an LMMSE built from statistics works in
theirs (:attr:`ImageStatistics.domain`).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..data.patches import ImageCache
from ..data.registry import portable_path
from ..io.domains import LINEAR, SRGB
from ..io.tensorfiles import load_pair, save_pair
from ..io.weights import IMAGE_STATISTICS, IMAGE_STATISTICS_LINEAR
from ..patterns import Pattern, check_pattern, get
from ..physics.light import check_domain, srgb_to_linear
from ..physics.noise import NoiseLevels, NoiseModel, check_level
from ..physics.sensor import pattern_pixel_kernels
from .lmmse import DEFAULT_RADIUS, LMMSE, LMMSEFileError, apply_filters

__all__ = [
    "DEFAULT_MAX_OFFSET",
    "SHIPPED_PATHS",
    "ClosedFormFilters",
    "ImageStatistics",
    "closed_form_filters",
    "closed_form_lmmse",
    "closed_form_mse",
    "estimate_image_statistics",
    "lmmse_estimate",
    "shipped_image_statistics",
]

#: Largest offset (pixels, per axis) of the shipped autocovariance. The closed form needs offsets
#: up to ``2 * (radius + kernel half size)``: 12 for the default radius 4 and the built-in
#: kernels (at most 5 wide), so 16 leaves room for radius 6.
DEFAULT_MAX_OFFSET = 16

# Relative ridge added to the raw covariance, as in fit_lmmse: it only keeps the solve defined
# when a direction carries no signal (a dark pixel at sigma 0); far below any noise level.
_RIDGE = 1e-8
_FORMAT = "splitcam-image-statistics"
_VERSION = 1
SHIPPED_PATH = IMAGE_STATISTICS
#: The shipped statistics of each light domain.
SHIPPED_PATHS = {SRGB: IMAGE_STATISTICS, LINEAR: IMAGE_STATISTICS_LINEAR}


@dataclass(eq=False)
class ImageStatistics:
    """Second-order statistics of RGB images, independent of any pattern.

    Attributes:
        mean: Mean colour ``mu``, float64, shape ``(3,)``, values in [0, 1] units.
        second: Non-centred second moment ``E[f_c(y, x) f_c'(y + dy, x + dx)]`` at
            ``[c, c', dy + L, dx + L]``, float64, shape ``(3, 3, 2L + 1, 2L + 1)``; symmetric
            (``second[c, c', d] == second[c', c, -d]``).
        count: Number of pixel positions the moments were averaged over.
        info: Free-form description of the estimate (source, images, ``domain``), saved with
            the file.
    """

    mean: torch.Tensor
    second: torch.Tensor
    count: int
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        s = self.second
        if self.mean.shape != (3,):
            raise ValueError(f"expected mean of shape (3,), got {tuple(self.mean.shape)}")
        if s.ndim != 4 or s.shape[:2] != (3, 3) or s.shape[2] != s.shape[3] or s.shape[2] % 2 == 0:
            raise ValueError(f"expected second of shape (3, 3, 2L+1, 2L+1), got {tuple(s.shape)}")
        if not (torch.isfinite(self.mean).all() and torch.isfinite(s).all()):
            raise ValueError("expected finite image statistics")
        self.mean = self.mean.to(torch.float64)
        self.second = s.to(torch.float64)

    @property
    def domain(self) -> str:
        """The light domain of the images the moments were taken of (``info["domain"]``;
        statistics that do not record one are of sRGB values)."""
        return check_domain(self.info.get("domain", SRGB))

    @property
    def max_offset(self) -> int:
        """``L``: the largest offset (per axis) the autocovariance covers."""
        return (self.second.shape[-1] - 1) // 2

    def covariance(self) -> torch.Tensor:
        """``C[c, c', dy + L, dx + L]``: the autocovariance (second moment minus mean product)."""
        return self.second - (self.mean[:, None] * self.mean[None, :])[:, :, None, None]

    def mixed(self, other: ImageStatistics, weight: float) -> ImageStatistics:
        """The statistics of the mixture ``(1 - weight) self + weight other``: a pixel drawn from
        ``other``'s images with probability ``weight``. Moments of a mixture are the mixed
        moments, so the mean and the second moment mix linearly (the autocovariance does not:
        it is derived from them). E.g. the photos' statistics mixed with those of copies whose
        chroma was moved, for a prior that holds on saturated colour
        (``docs/results/colour/lmmse-statistics.md``).

        Raises:
            ValueError: A weight outside [0, 1], or statistics of another window or light domain.
        """
        if isinstance(weight, bool) or not 0.0 <= float(weight) <= 1.0:
            raise ValueError(f"expected a mixture weight in [0, 1], got {weight!r}")
        if other.second.shape != self.second.shape or other.domain != self.domain:
            raise ValueError(
                f"cannot mix image statistics of window {tuple(self.second.shape)} ({self.domain}) "
                f"with {tuple(other.second.shape)} ({other.domain})"
            )
        w = float(weight)
        info = {
            "domain": self.domain,
            "mixture": {"weight": w, "first": dict(self.info), "second": dict(other.info)},
        }
        return ImageStatistics(
            (1 - w) * self.mean + w * other.mean,
            (1 - w) * self.second + w * other.second,
            self.count + other.count,
            info,
        )

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write ``<path>.safetensors`` plus ``<path>.json`` (checksum of the tensors); no pickle.

        Returns:
            The path of the ``.json`` file.
        """
        tensors = {"mean": self.mean, "second": self.second}
        meta = {"max_offset": self.max_offset, "count": int(self.count), "info": self.info}
        return save_pair(path, tensors, _FORMAT, _VERSION, meta)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ImageStatistics:
        """Read statistics written by :meth:`save`.

        Raises:
            LMMSEFileError: A file is missing, damaged, or does not match its checksum.
        """
        tensors, meta, meta_path = load_pair(
            path, _FORMAT, _VERSION, "image statistics", LMMSEFileError
        )
        try:
            return cls(
                tensors["mean"], tensors["second"], int(meta["count"]), dict(meta.get("info", {}))
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise LMMSEFileError(f"damaged image statistics '{meta_path}': {exc}") from None


def shipped_image_statistics(domain: str = SRGB) -> ImageStatistics:
    """The statistics shipped with splitcam for a light domain (``srgb`` or ``linear``),
    estimated by ``scripts/estimate_image_statistics.py [--domain linear]``.

    Raises:
        ValueError: An unknown domain.
    """
    return _shipped(check_domain(domain))


@functools.lru_cache(maxsize=2)
def _shipped(domain: str) -> ImageStatistics:
    with torch.inference_mode(False):  # cached: must not become inference tensors
        stats = ImageStatistics.load(SHIPPED_PATHS[domain])
    if stats.domain != domain:
        raise LMMSEFileError(
            f"{SHIPPED_PATHS[domain]} holds statistics of the {stats.domain} domain, "
            f"expected {domain}"
        )
    return stats


def estimate_image_statistics(
    source: torch.Tensor | ImageCache | str | os.PathLike[str] | list,
    *,
    max_offset: int = DEFAULT_MAX_OFFSET,
    max_images: int | None = None,
    progress: bool = False,
    domain: str = SRGB,
) -> ImageStatistics:
    """Estimate :class:`ImageStatistics` from whole training images.

    For every image, the second moment at offset ``d`` is summed over the pixels ``q`` at least
    ``L`` from every edge, ``sum_q f_c(q) f_c'(q + d)``, so every product is of two real pixels
    (no padding); it is computed for all offsets at once by FFT cross-correlation. The sums of all
    images are divided by the number of terms and symmetrised (``d`` and ``-d`` with the channels
    swapped estimate the same moment). The mean is taken over the same interior pixels.

    Args:
        source: Images ``(N, 3, H, W)`` in [0, 1], a list of ``(3, H, W)`` images of any sizes,
            an :class:`ImageCache`, a folder, or a list of image files.
        max_offset: ``L``, the largest offset per axis.
        max_images: Use at most this many images (from the start of the sorted list).
        progress: Show a progress bar over the images.
        domain: ``srgb``: the moments of the display values themselves; ``linear``: of the
            linear radiance each image decodes to (model.md §13), taken in float64.

    Raises:
        ValueError: No image larger than ``2L + 1`` pixels in each direction, or an unknown
            domain.
    """
    domain = check_domain(domain)
    if isinstance(max_offset, bool) or not isinstance(max_offset, int) or max_offset < 0:
        raise ValueError(f"expected max_offset as an integer >= 0, got {max_offset!r}")
    lo = max_offset
    if isinstance(source, torch.Tensor):
        if source.ndim != 4 or source.shape[1] != 3:
            raise ValueError(f"expected images of shape (N, 3, H, W), got {tuple(source.shape)}")
        images: Any = list(source[:max_images] if max_images else source)
        info: dict[str, Any] = {"source": "tensor"}
    elif isinstance(source, list) and source and isinstance(source[0], torch.Tensor):
        images = source[:max_images] if max_images else source
        if any(img.ndim != 3 or img.shape[0] != 3 for img in images):
            raise ValueError("expected a list of images of shape (3, H, W)")
        info = {"source": "tensors", "images": len(images)}
    else:
        cache = (
            source
            if isinstance(source, ImageCache)
            else ImageCache(source, min_size=2 * lo + 2, max_images=max_images, progress=progress)
        )
        images = (cache.image(i) for i in range(len(cache)))
        folder = portable_path(cache.paths[0].parent) if cache.paths else ""
        info = {"source": folder, "images": len(cache)}
        if progress:
            from tqdm.auto import tqdm

            images = tqdm(images, total=len(cache), desc="image statistics", leave=False)
    k = 2 * lo + 1
    second = torch.zeros(3, 3, k, k, dtype=torch.float64)
    total = torch.zeros(3, dtype=torch.float64)
    count = 0
    for img in images:
        f = img.to(torch.float64)
        if domain == LINEAR:
            f = srgb_to_linear(f)
        _, h, w = f.shape
        if h <= 2 * lo or w <= 2 * lo:
            continue
        interior = torch.zeros_like(f)
        interior[:, lo : h - lo, lo : w - lo] = f[:, lo : h - lo, lo : w - lo]
        size = (h + lo, w + lo)  # no wrap-around for |d| <= L
        spec_in = torch.fft.rfft2(interior, s=size)
        spec = torch.fft.rfft2(f, s=size)
        # corr[c, c', d] = sum_q interior_c(q) f_c'(q + d): ifft(conj(F_interior) F_f).
        corr = torch.fft.irfft2(spec_in.conj()[:, None] * spec[None, :], s=size)
        rows = torch.arange(-lo, lo + 1) % size[0]
        cols = torch.arange(-lo, lo + 1) % size[1]
        second += corr[:, :, rows][:, :, :, cols]
        total += interior.sum((1, 2))
        count += (h - 2 * lo) * (w - 2 * lo)
    if count == 0:
        raise ValueError(f"expected images larger than {k}x{k} pixels, got none")
    second /= count
    second = 0.5 * (second + second.transpose(0, 1).flip(-1, -2))
    info["max_offset"] = lo
    info["domain"] = domain
    return ImageStatistics(total / count, second, count, info)


@functools.lru_cache(maxsize=64)
def _design_index(
    period: tuple[int, int], kh: int, kw: int, radius: int
) -> tuple[np.ndarray, tuple[int, int]]:
    """Index table of the matrices ``A_p`` (raw neighbourhood from scene window), per phase.

    ``A[p, a * k + b, c * wh * ww + y * ww + x]`` (``k = 2r + 1``, window ``wh x ww`` with
    ``wh = 2 (r + kh//2) + 1``) is the pixel-kernel entry ``pixel_kernels[q, c, u, v]`` with which
    the raw pixel at offset ``(a - r, b - r)`` from a pixel of phase ``p`` (that raw pixel has phase
    ``q``) collects scene pixel ``(y, x) = (a + u, b + v)`` of the window; the table holds the flat
    index of that entry in ``pixel_kernels`` (shape ``(Ph, Pw, 3, kh, kw)``), or the index of one
    extra zero slot where no tap lands.
    """
    ph, pw = period
    k = 2 * radius + 1
    wh, ww = k + kh - 1, k + kw - 1
    zero = ph * pw * 3 * kh * kw
    index = np.full((ph * pw, k * k, 3, wh, ww), zero, dtype=np.int64)
    for i in range(ph):
        for j in range(pw):
            for a in range(k):
                for b in range(k):
                    qi, qj = (i + a - radius) % ph, (j + b - radius) % pw
                    for c in range(3):
                        for u in range(kh):
                            for v in range(kw):
                                flat = (((qi * pw + qj) * 3 + c) * kh + u) * kw + v
                                index[i * pw + j, a * k + b, c, a + u, b + v] = flat
    return index.reshape(ph * pw, k * k, 3 * wh * ww), (wh, ww)


@functools.lru_cache(maxsize=16)
def _window_index(wh: int, ww: int, lo: int) -> np.ndarray:
    """Flat index into the ``(3, 3, 2L+1, 2L+1)`` autocovariance of every pair of window entries."""
    c = np.arange(3)[:, None, None]
    y = np.arange(wh)[None, :, None]
    x = np.arange(ww)[None, None, :]
    c, y, x = (np.broadcast_to(t, (3, wh, ww)).reshape(-1) for t in (c, y, x))
    k = 2 * lo + 1
    dy = y[None, :] - y[:, None] + lo
    dx = x[None, :] - x[:, None] + lo
    return ((c[:, None] * 3 + c[None, :]) * k + dy) * k + dx


def _moments(
    kernels: torch.Tensor, stats: ImageStatistics, radius: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(C_xx, C_yx, mean_x, C_yy)`` of the clean raw neighbourhoods, per phase (float64)."""
    ph, pw, _, kh, kw = kernels.shape
    index, (wh, ww) = _design_index((ph, pw), kh, kw, radius)
    lo = stats.max_offset
    if max(wh, ww) - 1 > lo:
        largest = lo + 1 - 2 * radius
        raise ValueError(
            f"the closed-form LMMSE of {kh}x{kw} kernels with radius {radius} needs image "
            f"statistics up to offset {max(wh, ww) - 1}, these cover {lo}: kernels up to "
            f"{largest - (largest + 1) % 2}x{largest - (largest + 1) % 2} work with radius "
            f"{radius}; for larger ones, estimate statistics with a larger max_offset "
            f"(splitcam.recon.closed_form.estimate_image_statistics) or use --lmmse-train DIR"
        )
    flat = torch.cat([kernels.reshape(-1), kernels.new_zeros(1)])
    # The caches hold numpy arrays: a tensor made under inference_mode (validation) could not
    # be saved for backward when training reuses it.
    a = flat[torch.from_numpy(index).to(kernels.device)]  # (P, d, n)
    cov = stats.covariance().to(kernels.device)
    cff = cov.reshape(-1)[torch.from_numpy(_window_index(wh, ww, lo)).to(kernels.device)]
    mean_f = stats.mean.to(kernels.device).repeat_interleave(wh * ww)
    centre = torch.tensor([c * wh * ww + (wh // 2) * ww + ww // 2 for c in range(3)])
    cxx = a @ cff @ a.transpose(1, 2)
    cyx = cff[centre.to(kernels.device)] @ a.transpose(1, 2)  # (P, 3, d)
    mean_x = a @ mean_f
    cyy = cov[:, :, lo, lo]
    return cxx, cyx, mean_x, cyy


def _solve(
    kernels: torch.Tensor, stats: ImageStatistics, radius: int, levels: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Filters ``(S, P, 3, d)``, biases ``(S, P, 3)`` and per-phase MSE ``(S, P)`` per noise
    level. ``levels`` ``(S, 2)`` holds ``(a, b)``: the noise variance of a raw pixel of expected
    value ``g`` is ``a g + b`` (Gaussian: ``a = 0``, ``b = (sigma/255)^2``; photon model:
    :meth:`~splitcam.physics.noise.Exposure.variance_coefficients`), evaluated at each window
    pixel's expected signal ``A_p mu_M`` (model.md §10)."""
    cxx, cyx, mean_x, cyy = _moments(kernels, stats, radius)
    d = cxx.shape[-1]
    trace = torch.diagonal(cxx, dim1=-2, dim2=-1).sum(-1)
    levels = levels.to(cxx)
    ridge = _RIDGE * trace.detach()[None, :, None] / d  # (1, P, 1)
    var = levels[:, 0, None, None] * mean_x[None] + levels[:, 1, None, None]  # (S, P, d)
    system = cxx[None] + torch.diag_embed(var + ridge)
    # W^T = (C_xx + s^2 I)^-1 C_xy
    wt = torch.linalg.solve(system, cyx.transpose(-1, -2).expand(system.shape[0], -1, -1, -1))
    weights = wt.transpose(-1, -2)  # (S, P, 3, d)
    bias = stats.mean.to(cxx)[None, None] - (weights @ mean_x[None, ..., None]).squeeze(-1)
    mse = (torch.diagonal(cyy).sum() - (weights * cyx[None]).sum((-2, -1))) / 3.0
    return weights, bias, mse


def _as_kernels(pattern_or_kernels: Pattern | torch.Tensor) -> torch.Tensor:
    if isinstance(pattern_or_kernels, torch.Tensor):
        k = pattern_or_kernels
        if k.ndim != 5 or k.shape[2] != 3:
            raise ValueError(
                f"expected pixel kernels of shape (Ph, Pw, 3, kh, kw), got {tuple(k.shape)}"
            )
        return k.to(torch.float64)
    return pattern_pixel_kernels(pattern_or_kernels)


def _as_sigmas(sigma: Any) -> tuple[torch.Tensor, bool]:
    """Noise level(s) → ``((S, 2) variance coefficients, several?)``: a sigma (8-bit units) or
    a :class:`~splitcam.physics.noise.NoiseModel`, a 1-D tensor of sigmas, or a list of
    levels (:class:`~splitcam.physics.noise.NoiseLevels`)."""
    several = isinstance(sigma, (list, tuple)) or (
        isinstance(sigma, torch.Tensor) and sigma.ndim == 1
    )
    return NoiseLevels.of(sigma).variance_coefficients(), several


def closed_form_filters(
    kernels: Pattern | torch.Tensor,
    sigma: float | torch.Tensor,
    *,
    statistics: ImageStatistics | None = None,
    radius: int = DEFAULT_RADIUS,
) -> tuple[torch.Tensor, torch.Tensor]:
    """LMMSE filters and biases of any kernels at noise level(s) ``sigma``, differentiable.

    Args:
        kernels: A :class:`Pattern`, or pixel kernels
            ``(Ph, Pw, 3, kh, kw)`` (:func:`splitcam.physics.sensor.pixel_kernels`; gradients
            flow back to them).
        sigma: Noise standard deviation in 8-bit units, a number or a 1-D tensor of several; or
            a photon-model :class:`~splitcam.physics.noise.Exposure` (signal-dependent noise,
            model.md §10), or a list of them.
        statistics: Image statistics (default: the shipped ones).
        radius: Neighbourhood radius ``r``; filters are ``(2r+1) x (2r+1)``.

    Returns:
        ``(weights, bias)`` in float64, laid out as :meth:`LMMSEStatistics.filters`:
        weights ``(P, 3, 2r+1, 2r+1)``, bias ``(P, 3)``; with a 1-D ``sigma`` a leading
        ``(S,)`` axis.
    """
    k = _as_kernels(kernels)
    sig, many = _as_sigmas(sigma)
    stats = statistics if statistics is not None else shipped_image_statistics()
    weights, bias, _ = _solve(k, stats, radius, sig)
    side = 2 * radius + 1
    weights = weights.reshape(*weights.shape[:3], side, side)
    return (weights, bias) if many else (weights[0], bias[0])


def closed_form_mse(
    kernels: Pattern | torch.Tensor,
    sigma: float | torch.Tensor,
    *,
    statistics: ImageStatistics | None = None,
    radius: int = DEFAULT_RADIUS,
) -> torch.Tensor:
    """Expected squared error of the LMMSE per colour (``[0, 1]`` units), averaged over phases.

    ``mean_p tr(C_yy - W_p C_xy,p) / 3``: what the LMMSE filters of these kernels achieve on
    images with these statistics, away from image borders; no images needed. Differentiable in
    the kernels. A scalar tensor, or one value per sigma for a 1-D ``sigma``.
    """
    k = _as_kernels(kernels)
    sig, many = _as_sigmas(sigma)
    stats = statistics if statistics is not None else shipped_image_statistics()
    _, _, mse = _solve(k, stats, radius, sig)
    mse = mse.mean(-1)
    return mse if many else mse[0]


class ClosedFormFilters:
    """The LMMSE filters of one pattern from :class:`ImageStatistics` (cached per sigma).

    Filters are of the statistics' light domain (:attr:`ImageStatistics.domain`). Provides what
    :class:`splitcam.recon.lmmse.LMMSE` needs of its statistics (``pattern``,
    ``radius``, ``filters(sigma)``, ``expected_mse(sigma)``), so ``LMMSE(ClosedFormFilters(...))``
    reconstructs with the closed-form filters through the same tiled code path.
    """

    def __init__(
        self,
        pattern: Pattern | str,
        statistics: ImageStatistics | None = None,
        radius: int = DEFAULT_RADIUS,
    ) -> None:
        self.pattern = get(pattern)  # a constructor users call: names and files read here
        self.statistics = statistics if statistics is not None else shipped_image_statistics()
        self.radius = radius
        self._kernels = _as_kernels(self.pattern)
        self._cache: dict[float, tuple[torch.Tensor, torch.Tensor]] = {}

    def filters(self, sigma: float | NoiseModel) -> tuple[torch.Tensor, torch.Tensor]:
        """Filters for a Gaussian sigma (8-bit units) or a
        :class:`~splitcam.physics.noise.NoiseModel`."""
        sigma = check_level(sigma)
        if sigma not in self._cache:
            self._cache[sigma] = closed_form_filters(
                self._kernels, sigma, statistics=self.statistics, radius=self.radius
            )
        return self._cache[sigma]

    def expected_mse(self, sigma: float | NoiseModel) -> float:
        return float(
            closed_form_mse(self._kernels, sigma, statistics=self.statistics, radius=self.radius)
        )


def closed_form_lmmse(
    pattern: Pattern,
    statistics: ImageStatistics | None = None,
    *,
    radius: int = DEFAULT_RADIUS,
    name: str = "lmmse",
    domain: str | None = None,
) -> LMMSE:
    """An :class:`LMMSE` reconstructor of any pattern, from image statistics.

    Args:
        pattern: The pattern.
        statistics: Image statistics (default: the shipped ones of ``domain``).
        radius: Filter radius.
        name: Label in tables.
        domain: The light domain it reconstructs in (its ``domain`` attribute); default: that
            of ``statistics``, or ``srgb``.

    Raises:
        ValueError: ``domain`` differs from the domain of ``statistics``, or is unknown.
    """
    if statistics is None:
        statistics = shipped_image_statistics(domain or SRGB)
    elif domain is not None and check_domain(domain) != statistics.domain:
        raise ValueError(
            f"image statistics of the {statistics.domain} domain cannot make an LMMSE of the "
            f"{check_domain(domain)} domain"
        )
    filters = ClosedFormFilters(check_pattern(pattern), statistics, radius)
    # Image statistics of another domain tell its results apart from the sRGB LMMSE's.
    other = statistics.domain != SRGB
    return LMMSE(
        filters,  # type: ignore[arg-type]
        name,
        pattern=filters.pattern,
        domain=statistics.domain,
        fingerprint=f":statistics:{statistics.domain}:{statistics.count}" if other else None,
    )


def lmmse_estimate(
    raw: torch.Tensor,
    kernels: torch.Tensor,
    sigma: float | torch.Tensor,
    statistics: ImageStatistics,
    radius: int = DEFAULT_RADIUS,
) -> torch.Tensor:
    """The closed-form LMMSE reconstruction of a raw batch, differentiable in the kernels.

    The filters are solved in float64 for the kernels and noise level(s) given, then applied in
    the dtype of ``raw`` with autocast off (a reduced-precision estimate would cap the accuracy of
    whatever is built on it). The raw image is taken as 0 outside the image, as in
    :class:`~splitcam.recon.lmmse.LMMSE`; its top-left pixel has phase ``(0, 0)``.

    Args:
        raw: Raw images.
        kernels: Pixel kernels ``(Ph, Pw, 3, kh, kw)`` of the sensor that recorded them.
        sigma: Noise level in 8-bit units: one for the batch, or one per image ``(N,)``.
        statistics: Image statistics.
        radius: Filter radius.

    Shape:
        - raw: ``(N, 1, H, W)``; output ``(N, 3, H, W)``.
    """
    ph, pw = kernels.shape[:2]
    levels = NoiseLevels.of(sigma).for_batch(raw.shape[0])
    shared = levels.shared  # one solve where the batch shares its level
    sigma = shared if shared is not None else levels
    with torch.autocast(raw.device.type, enabled=False):
        # One solve for every noise level of the batch, then one grouped convolution.
        weights, bias = closed_form_filters(
            kernels.to(torch.float64), sigma, statistics=statistics, radius=radius
        )
        if weights.ndim == 5 and weights.shape[0] == 1:
            weights, bias = weights[0], bias[0]
        return apply_filters(raw, weights, bias, (ph, pw))
