"""LMMSE: the linear minimum-mean-square-error reconstructor of any pattern.

Each phase ``(i, j)`` of the period gets its own linear filter (plus bias) over the
``(2r+1) x (2r+1)`` neighbourhood of the raw image, predicting the RGB of the centre pixel. The
filters are solved in closed form from second moments gathered once from training patches
(:func:`fit_lmmse`). The noise is white, Gaussian and independent of the signal, so the
noisy-raw second moment is the clean one plus ``(sigma/255)^2 I``: one pass over the data gives
the exact LMMSE filters for every sigma. Fits of the built-in patterns ship with splitcam
(:func:`shipped_lmmse`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F

from ..checks import check_raw
from ..data.patches import ImageCache, PatchSampler
from ..data.registry import portable_path
from ..io.domains import SRGB
from ..io.tensorfiles import load_pair, save_pair
from ..io.weights import LMMSE_DIR
from ..patterns import Pattern, PatternError, check_pattern, get
from ..physics.light import check_domain
from ..physics.noise import NoiseModel, as_noise, check_level
from ..physics.periodic import phase_conv, phase_map
from ..physics.sensor import SplitterSensor
from .tiling import DEFAULT_TILE, tiled

__all__ = [
    "DEFAULT_PATCHES",
    "DEFAULT_PATCH_SIZE",
    "DEFAULT_RADIUS",
    "LMMSE",
    "LMMSEFileError",
    "LMMSEStatistics",
    "apply_filters",
    "fit_lmmse",
    "shipped_lmmse",
]

#: Default number of training patches for :func:`fit_lmmse`. Measured on data/train (shared 2-core
#: Xeon, fit on 400 images, scored on 12 held-out training images): 1024, 4096 and 16384 patches
#: of 48x48 give the same PSNR to 0.02 dB for patterns A and D, and 2048 take 5-9 s per pattern
#: (after 1.5 s to decode the images once).
DEFAULT_PATCHES = 2048
DEFAULT_PATCH_SIZE = 48
DEFAULT_RADIUS = 4

# Relative ridge on the non-bias diagonal: only there to keep the solve well defined when the
# training data do not excite every direction (e.g. flat images); far below any noise level.
_RIDGE = 1e-8
_BATCH = 64
_FORMAT = "splitcam-lmmse-statistics"
_VERSION = 1


class LMMSEFileError(ValueError):
    """A saved LMMSE statistics file is missing, damaged or inconsistent; the message says why."""


def _phase_slices(size: int, period: int, phase: int, radius: int, margin: int) -> tuple[int, int]:
    """Start and stop (in unfold coordinates) of the valid centres of one phase along one axis.

    Unfold position ``u`` is the neighbourhood centred on pixel ``u + radius``. A centre is valid
    when its whole neighbourhood lies at least ``margin`` (the pattern kernel's half size) from
    the patch edge, because raw pixels nearer the edge miss the light that would arrive from
    outside the patch and so differ from the same pixels of a whole image.
    """
    first = margin
    first += (phase - (first + radius)) % period
    return first, size - 2 * radius - margin


@dataclass(eq=False)
class LMMSEStatistics:
    """Sums of the second moments of clean raw neighbourhoods and RGB targets, per phase.

    ``x`` is the ``d = (2r+1)^2`` raw values of a neighbourhood (row-major, offset
    ``(a - r, b - r)`` at index ``a * (2r+1) + b``) with a constant 1 appended; ``y`` is the RGB
    of the centre pixel. Sums (not means) are kept so statistics of separate runs can be added.

    Attributes:
        pattern: The sensor pattern the raw images came from.
        radius: Neighbourhood radius ``r``.
        xx: ``sum x x^T`` per phase, float64, shape ``(P, d + 1, d + 1)``, ``P = Ph * Pw``.
        xy: ``sum x y^T`` per phase, float64, shape ``(P, d + 1, 3)``.
        yy: ``sum y y^T`` per phase, float64, shape ``(P, 3, 3)``.
        counts: Number of neighbourhoods per phase, int64, shape ``(P,)``.
        info: Free-form description of the fit (source, patches, seed), saved with the file.
    """

    pattern: Pattern
    radius: int
    xx: torch.Tensor
    xy: torch.Tensor
    yy: torch.Tensor
    counts: torch.Tensor
    info: dict[str, Any] = field(default_factory=dict)
    _cache: dict[float | NoiseModel, tuple[torch.Tensor, torch.Tensor]] = field(
        default_factory=dict, init=False, repr=False
    )

    def __post_init__(self) -> None:
        ph, pw = self.pattern.period
        p, d = ph * pw, (2 * self.radius + 1) ** 2
        expected = {
            "xx": (p, d + 1, d + 1),
            "xy": (p, d + 1, 3),
            "yy": (p, 3, 3),
            "counts": (p,),
        }
        for key, shape in expected.items():
            got = tuple(getattr(self, key).shape)
            if got != shape:
                raise ValueError(
                    f"expected {key} of shape {shape} for period {(ph, pw)} and radius "
                    f"{self.radius}, got {got}"
                )

    @property
    def kernel_size(self) -> int:
        return 2 * self.radius + 1

    def __add__(self, other: LMMSEStatistics) -> LMMSEStatistics:
        """Pool the statistics of two fits of the same pattern and radius."""
        if not (self.pattern.equals(other.pattern) and self.radius == other.radius):
            raise ValueError(
                f"expected statistics of the same pattern and radius, got "
                f"{self.pattern.name}/r={self.radius} and {other.pattern.name}/r={other.radius}"
            )
        return LMMSEStatistics(
            self.pattern,
            self.radius,
            self.xx + other.xx,
            self.xy + other.xy,
            self.yy + other.yy,
            self.counts + other.counts,
            {"pooled": [self.info, other.info]},
        )

    def _solve(self, sigma: float | NoiseModel) -> torch.Tensor:
        """The ``(P, d + 1, 3)`` LMMSE solution (filters and bias) at ``sigma``, float64."""
        if bool((self.counts == 0).any()):
            raise ValueError("expected statistics with at least one sample per phase, got none")
        n = self.counts.to(torch.float64).view(-1, 1, 1)
        mxx = self.xx / n
        mxy = self.xy / n
        d = mxx.shape[-1] - 1
        trace = torch.diagonal(mxx[:, :d, :d], dim1=-2, dim2=-1).sum(-1)
        a, b = as_noise(sigma).variance_coefficients()
        if a == 0 and b == 0 and bool((trace == 0).any()):
            dark = int((trace == 0).nonzero()[0, 0])
            raise ValueError(
                f"pattern {self.pattern.name!r}: the pixels of phase {dark} receive no light in "
                f"the training data, so no noise-free LMMSE exists (does the pattern collect "
                f"any light?)"
            )
        # Noise independent of the signal given the signal, and zero-mean: it adds its variance
        # to the second moment of every raw value and nothing to any other moment (the bias
        # entry included). Its variance at a pixel of expected value g is a g + b (Gaussian:
        # a = 0; photon model: shot noise a = 3 / N), so on average a E[g] + b, with E[g] the
        # mean raw value at that window position, the moment with the constant entry.
        mean_x = mxx[:, :d, d]  # (P, d)
        var = a * mean_x + b + (_RIDGE * trace / d)[:, None]
        mxx = mxx + torch.diag_embed(torch.cat([var, torch.zeros_like(var[:, :1])], 1))
        return torch.linalg.solve(mxx, mxy)

    def filters(self, sigma: float | NoiseModel) -> tuple[torch.Tensor, torch.Tensor]:
        """The LMMSE filters and biases for noise level ``sigma`` (cached per sigma), a Gaussian
        sigma or a photon-model :class:`~splitcam.physics.noise.Exposure` (signal-dependent
        noise, its variance at each window position's mean signal).

        Filter ``[p, c, a, b]`` multiplies the raw value at offset ``(a - r, b - r)`` from a pixel
        of phase ``p = i * Pw + j``, to predict colour ``c`` of that pixel.

        Args:
            sigma: Noise standard deviation in 8-bit units (``0`` for noise-free raw images),
                or an :class:`~splitcam.physics.noise.Exposure`.

        Returns:
            ``(weights, bias)`` in float64.

        Shape:
            - weights: ``(Ph * Pw, 3, 2r + 1, 2r + 1)``.
            - bias: ``(Ph * Pw, 3)``.
        """
        sigma = check_level(sigma)
        if sigma not in self._cache:
            w = self._solve(sigma)
            k = self.kernel_size
            weights = w[:, :-1, :].transpose(1, 2).reshape(-1, 3, k, k).contiguous()
            self._cache[sigma] = (weights, w[:, -1, :].contiguous())
        return self._cache[sigma]

    def expected_mse(self, sigma: float | NoiseModel) -> float:
        """Mean squared error of the LMMSE filters on the training neighbourhoods themselves.

        ``E|y - W^T x|^2 = tr(E[y y^T] - E[x y^T]^T W)`` at the optimum ``W``, averaged over the 3
        colours and over all neighbourhoods, in [0, 1] units. A score that needs no test
        images; being in-sample it is slightly optimistic, and it ignores image borders.
        """
        sigma = check_level(sigma)
        n = self.counts.to(torch.float64)
        w = self._solve(sigma)
        resid = torch.diagonal(self.yy, dim1=-2, dim2=-1).sum(-1) - (self.xy * w).sum((-2, -1))
        return float(resid.sum() / (3.0 * n.sum()))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the statistics as ``<path>.safetensors`` plus ``<path>.json``; no pickle.

        The tensor file holds the moment sums; the JSON file holds the pattern
        (``Pattern.to_dict()``), the radius, the counts, the fit description and the SHA-256 of
        the tensor file, so a damaged or mismatched pair is detected on loading.

        Args:
            path: Target; a ``.safetensors`` or ``.json`` suffix is replaced, anything else kept.

        Returns:
            The path of the ``.json`` file (what :meth:`load` takes, as does either file name).
        """
        tensors = {"xx": self.xx, "xy": self.xy, "yy": self.yy, "counts": self.counts}
        meta = {
            "pattern": self.pattern.to_dict(),
            "radius": self.radius,
            "counts": [int(c) for c in self.counts],
            "info": self.info,
        }
        return save_pair(path, tensors, _FORMAT, _VERSION, meta)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LMMSEStatistics:
        """Read statistics written by :meth:`save`.

        Raises:
            LMMSEFileError: A file is missing, unreadable or damaged, the tensor file's checksum
                differs from the one recorded, or the contents are inconsistent.
        """
        tensors, meta, meta_path = load_pair(
            path, _FORMAT, _VERSION, "LMMSE statistics", LMMSEFileError
        )
        try:
            pattern = Pattern.from_dict(meta["pattern"], source=str(meta_path))
            stats = cls(
                pattern,
                int(meta["radius"]),
                tensors["xx"],
                tensors["xy"],
                tensors["yy"],
                tensors["counts"],
                dict(meta.get("info", {})),
            )
        except (PatternError, KeyError, TypeError, ValueError) as exc:
            raise LMMSEFileError(f"damaged LMMSE statistics '{meta_path}': {exc}") from None
        if [int(c) for c in stats.counts] != meta.get("counts"):
            raise LMMSEFileError(f"'{meta_path}': counts differ from those in its tensor file")
        return stats


def _accumulate(
    stats: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor],
    raw: torch.Tensor,
    rgb: torch.Tensor,
    period: tuple[int, int],
    radius: int,
    margins: tuple[int, int],
) -> None:
    """Add the moments of every valid neighbourhood of a batch to ``stats`` (in place).

    Shape:
        raw: ``(B, 1, H, W)``, rgb: ``(B, 3, H, W)``, both float64.
    """
    xx, xy, yy, counts = stats
    ph, pw = period
    k = 2 * radius + 1
    _, _, h, w = raw.shape
    # A strided view (B, H - 2r, W - 2r, k, k): only the neighbourhoods a phase uses get copied,
    # ten times faster than F.unfold, which materialises every neighbourhood of the batch.
    windows = raw[:, 0].unfold(1, k, 1).unfold(2, k, 1)
    for i in range(ph):
        y0, y1 = _phase_slices(h, ph, i, radius, margins[0])
        for j in range(pw):
            x0, x1 = _phase_slices(w, pw, j, radius, margins[1])
            x = windows[:, y0:y1:ph, x0:x1:pw].reshape(-1, k * k)
            t = rgb[:, :, y0 + radius : y1 + radius : ph, x0 + radius : x1 + radius : pw]
            t = t.permute(0, 2, 3, 1).reshape(-1, 3)
            x = torch.cat([x, x.new_ones(x.shape[0], 1)], dim=1)
            p = i * pw + j
            xx[p] += x.T @ x
            xy[p] += x.T @ t
            yy[p] += t.T @ t
            counts[p] += x.shape[0]


def fit_lmmse(
    pattern: Pattern,
    source: torch.Tensor | PatchSampler | ImageCache | str | os.PathLike[str],
    *,
    radius: int = DEFAULT_RADIUS,
    patches: int = DEFAULT_PATCHES,
    patch_size: int = DEFAULT_PATCH_SIZE,
    seed: int = 0,
    progress: bool = False,
) -> LMMSEStatistics:
    """Gather the LMMSE statistics of ``pattern`` from clean training images, in one pass.

    The sensor is applied to each patch in float64 and every neighbourhood whose raw values are
    unaffected by the patch border is used (the centre lies at least ``radius`` plus the
    pattern kernel's half size from each edge). Patches start at phase ``(0, 0)``, as whole
    images do.

    Args:
        pattern: The pattern.
        source: Where the training patches come from:
            a tensor ``(N, 3, H, W)`` of images used whole (``patches``, ``patch_size`` and
            ``seed`` ignored); a :class:`PatchSampler` (``patches`` patches are drawn from it,
            advancing its generator; its own patch size applies); an :class:`ImageCache`, or a
            folder of images, from which a sampler with ``patch_size`` and ``seed`` is built.
            Build the cache once and pass it when fitting several patterns: the same seed then
            gives every pattern the same patches.
        radius: Neighbourhood radius ``r``; the filters are ``(2r+1) x (2r+1)``.
        patches: Number of patches to draw.
        patch_size: Side of the patches.
        seed: Seed of the sampler built from a cache or folder.
        progress: Show a progress bar over the batches.

    Returns:
        The accumulated statistics.

    Raises:
        ValueError: Bad arguments, or patches too small to hold one valid neighbourhood of
            every phase.

    Shape:
        - source (tensor): ``(N, 3, H, W)``, values in [0, 1].
    """
    pattern = check_pattern(pattern)
    if isinstance(radius, bool) or not isinstance(radius, int) or radius < 0:
        raise ValueError(f"expected radius as an integer >= 0, got {radius!r}")
    if not isinstance(source, (torch.Tensor, PatchSampler)):
        if patches < 1:
            raise ValueError(f"expected patches >= 1, got {patches}")
        cache = (
            source
            if isinstance(source, ImageCache)
            else ImageCache(source, min_size=patch_size, progress=progress)
        )
        source = PatchSampler(cache, patch_size=patch_size, seed=seed)
    ph, pw = pattern.period
    kh, kw = pattern.kernel_size
    margins = (kh // 2, kw // 2)
    side = source.patch_size if isinstance(source, PatchSampler) else min(source.shape[-2:])
    need = 2 * (radius + max(margins)) + max(ph, pw)
    if side < need:
        raise ValueError(
            f"expected patches of at least {need}x{need} pixels for radius {radius} and pattern "
            f"{pattern.name!r}, got {side}"
        )
    p, d = ph * pw, (2 * radius + 1) ** 2 + 1
    stats = (
        torch.zeros(p, d, d, dtype=torch.float64),
        torch.zeros(p, d, 3, dtype=torch.float64),
        torch.zeros(p, 3, 3, dtype=torch.float64),
        torch.zeros(p, dtype=torch.int64),
    )
    sensor = SplitterSensor(pattern)
    if isinstance(source, torch.Tensor):
        if source.ndim != 4 or source.shape[1] != 3:
            raise ValueError(f"expected images of shape (N, 3, H, W), got {tuple(source.shape)}")
        batches: Iterable[torch.Tensor] = source.double().split(_BATCH)
        info: dict[str, Any] = {"source": "tensor", "images": int(source.shape[0])}
    else:
        sampler = source
        sizes = [_BATCH] * (patches // _BATCH) + ([patches % _BATCH] if patches % _BATCH else [])
        batches = (sampler.sample(n).double() for n in sizes)
        if progress:
            from tqdm.auto import tqdm

            batches = tqdm(batches, total=len(sizes), desc=f"LMMSE {pattern.name}", leave=False)
        info = {
            "source": portable_path(sampler.cache.paths[0].parent) if sampler.cache.paths else "",
            "images": len(sampler.cache),
            "patches": patches,
            "patch_size": sampler.patch_size,
            "seed": sampler.seed,
        }
    with torch.no_grad():
        for rgb in batches:
            _accumulate(stats, sensor(rgb), rgb, (ph, pw), radius, margins)
    return LMMSEStatistics(pattern, radius, *stats, info=info)


def apply_filters(
    raw: torch.Tensor, weights: torch.Tensor, bias: torch.Tensor, period: tuple[int, int]
) -> torch.Tensor:
    """Per-phase linear filters plus bias: one convolution, then a per-pixel phase pick.

    The filters are cast to the dtype and device of ``raw``; the raw image is taken as 0 outside
    the image, and its top-left pixel has phase ``(0, 0)``. With a leading batch axis on the
    filters, image ``n`` gets filters ``n`` (one grouped convolution for the whole batch, e.g.
    a different noise level per image).

    Shape:
        - raw: ``(N, 1, H, W)``; weights ``(Ph * Pw, 3, k, k)`` or ``(N, Ph * Pw, 3, k, k)``;
          bias ``(Ph * Pw, 3)`` or ``(N, Ph * Pw, 3)``.
        - output: ``(N, 3, H, W)``.
    """
    weights = weights.to(device=raw.device, dtype=raw.dtype)
    bias = bias.to(device=raw.device, dtype=raw.dtype)
    phase = phase_map(*raw.shape[-2:], period, raw.device)
    if weights.ndim == 4:
        out = phase_conv(raw, weights.unsqueeze(2), period)
        return out + bias[phase].permute(2, 0, 1).unsqueeze(0)
    n, p, o, kh, kw = weights.shape
    if n != raw.shape[0] or bias.shape != (n, p, o):
        raise ValueError(
            f"expected per-image filters for {raw.shape[0]} images, got weights "
            f"{tuple(weights.shape)} and bias {tuple(bias.shape)}"
        )
    h, w = raw.shape[-2:]
    out = F.conv2d(
        raw.reshape(1, n, h, w),
        weights.reshape(n * p * o, 1, kh, kw),
        padding=(kh // 2, kw // 2),
        groups=n,
    ).view(n, p, o, h, w)
    out = out.gather(1, phase.expand(n, 1, o, h, w)).squeeze(1)
    return out + bias[:, phase].permute(0, 3, 1, 2)


class LMMSE:
    """Linear MMSE reconstruction of any pattern, from precomputed :class:`LMMSEStatistics`.

    Every pixel's RGB is a linear function (plus bias) of the raw values in its
    ``(2r+1) x (2r+1)`` neighbourhood, with one filter per phase of the period, solved for the
    noise level passed to :meth:`reconstruct`. Outside the image the raw image is taken as 0.

    Args:
        statistics: The fitted statistics (see :func:`fit_lmmse`, :meth:`LMMSEStatistics.load`).
        name: Label for tables.
        pattern: The pattern it is labelled with (default: that of ``statistics``; a pattern
            file with the same kernels as a shipped fit's keeps its own name this way).
        domain: The light domain of its raw images and estimates.
        fingerprint: What, beyond the pattern, tells its results apart (image statistics of
            another domain); see :mod:`splitcam.evaluation.protocol`.
    """

    def __init__(
        self,
        statistics: LMMSEStatistics,
        name: str = "lmmse",
        *,
        pattern: Pattern | None = None,
        domain: str = SRGB,
        fingerprint: str | None = None,
    ) -> None:
        self.statistics = statistics
        self.pattern = pattern if pattern is not None else statistics.pattern
        self.name = name
        self.domain = check_domain(domain)
        self.fingerprint = fingerprint

    @classmethod
    def fit(
        cls,
        pattern: Pattern | str,
        source: torch.Tensor | PatchSampler | ImageCache | str | os.PathLike[str],
        name: str = "lmmse",
        **kwargs: Any,
    ) -> LMMSE:
        """``LMMSE(fit_lmmse(pattern, source, **kwargs), name)``; ``pattern`` may be a name or
        a pattern file."""
        # a constructor users call: names and files read here
        return cls(fit_lmmse(get(pattern), source, **kwargs), name)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LMMSE:
        """Load statistics saved by :meth:`save` (see :meth:`LMMSEStatistics.load`)."""
        return cls(LMMSEStatistics.load(path))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Save the statistics (see :meth:`LMMSEStatistics.save`)."""
        return self.statistics.save(path)

    def reconstruct(self, raw: torch.Tensor, sigma: float | NoiseModel) -> torch.Tensor:
        """Apply the phase filters for ``sigma``: one convolution, then a per-pixel phase pick.

        Runs in tiles of :data:`splitcam.recon.tiling.DEFAULT_TILE` pixels
        (:func:`splitcam.recon.tiling.tiled`, overlap = the filter radius rounded up to whole
        periods): the convolution holds every phase's output for every pixel, ``Ph * Pw`` times
        the size of the result, which on a whole 24-megapixel image is over a gigabyte. Each
        output pixel reads only its ``(2r+1) x (2r+1)`` neighbourhood and its phase, so the
        tiled result equals the whole-image one up to float rounding.

        Args:
            raw: Raw image of :attr:`pattern` (phase ``(0, 0)`` at the top-left pixel).
            sigma: Noise standard deviation in 8-bit units that the filters are solved for, or
                a photon-model :class:`~splitcam.physics.noise.Exposure`.

        Returns:
            RGB estimate, not clamped, in ``raw``'s dtype and device.

        Shape:
            - raw: ``(N, 1, H, W)``.
            - output: ``(N, 3, H, W)``.
        """
        check_raw(raw)
        weights, bias = self.statistics.filters(sigma)
        period = self.pattern.period

        def run(tile: torch.Tensor) -> torch.Tensor:
            return apply_filters(tile, weights, bias, period)

        return tiled(run, raw, period, self.statistics.radius, tile=DEFAULT_TILE)

    def __repr__(self) -> str:
        return (
            f"LMMSE(pattern={self.pattern.name!r}, radius={self.statistics.radius}, "
            f"samples={int(self.statistics.counts.sum())})"
        )


#: Folder of the shipped LMMSE fits (see ``scripts/fit_shipped_lmmse.py``).
SHIPPED_DIR = LMMSE_DIR


def shipped_lmmse(pattern: Pattern, name: str = "lmmse") -> LMMSE:
    """The shipped LMMSE fit of a built-in pattern (fitted on CBSD432), labelled ``name``.

    A pattern file whose kernels differ from the built-in pattern of the same name gets no
    shipped fit: its raw images are not the built-in's.

    Raises:
        FileNotFoundError: No shipped fit for this pattern; the message says how to fit one.
    """
    pattern = check_pattern(pattern)
    path = SHIPPED_DIR / f"{pattern.name}.json"
    if path.is_file():
        statistics = LMMSEStatistics.load(path)
        if statistics.pattern.equals(pattern):
            return LMMSE(statistics, name, pattern=pattern)
        raise FileNotFoundError(
            f"pattern {pattern.name!r} has other kernels than the built-in {pattern.name!r}, "
            f"so the shipped LMMSE fit does not apply; fit one with --lmmse-train DIR"
        )
    raise FileNotFoundError(
        f"no shipped LMMSE fit for pattern {pattern.name!r}; fit one with --lmmse-train DIR"
    )
