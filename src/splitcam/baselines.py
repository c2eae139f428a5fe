"""Reconstruction methods that need no network training, behind one interface (:class:`Method`).

- :class:`ClassicalDemosaic`: bilinear, Malvar 2004 and Menon 2007 demosaicking of the ``bayer``
  pattern with the ``colour-demosaicing`` package. Our bayer raw image is exactly the standard
  RGGB mosaic, so the published algorithms apply unchanged. They do not denoise.
- :class:`LMMSE`: the linear minimum-mean-square-error reconstructor of any pattern. Each phase
  ``(i, j)`` of the period gets its own linear filter (plus bias) over the ``(2r+1) x (2r+1)``
  neighbourhood of the raw image, predicting the RGB of the centre pixel. The filters are solved
  in closed form from second moments gathered once from training patches (:func:`fit_lmmse`).
  The noise is white, Gaussian and independent of the signal, so the noisy-raw second moment is
  the clean one plus ``(sigma/255)^2 I``: one pass over the data gives the exact LMMSE filters
  for every sigma.
- :func:`screen_patterns`: fit and score many patterns in minutes, to rank them before spending
  hours training networks.

A :class:`Method` maps a raw image ``(N, 1, H, W)`` and the noise level to an RGB estimate
``(N, 3, H, W)`` (not clamped), like a trained network, so one evaluation loop scores both.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from numbers import Real
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
import torch
import torch.nn.functional as F

from .data import ImageCache, PatchSampler, load_validation
from .metrics import compute_all, mean_over_images, psnr
from .networks import check_raw
from .patterns import Pattern, PatternError, get
from .sensor import SplitterSensor

__all__ = [
    "DEFAULT_PATCHES",
    "DEFAULT_PATCH_SIZE",
    "DEFAULT_RADIUS",
    "LMMSE",
    "ClassicalDemosaic",
    "LMMSEFileError",
    "LMMSEStatistics",
    "Method",
    "ScreenResult",
    "evaluate_method",
    "fit_lmmse",
    "screen_patterns",
    "summarise",
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


def _check_sigma(sigma: float) -> float:
    if isinstance(sigma, bool) or not isinstance(sigma, Real):
        raise TypeError(f"expected sigma as a number (8-bit units), got {type(sigma).__name__}")
    if not (math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"expected a finite sigma >= 0 (8-bit units), got {sigma}")
    return float(sigma)


@runtime_checkable
class Method(Protocol):
    """A reconstruction method: raw image of ``pattern`` plus noise level in, RGB estimate out.

    Attributes:
        name: Short label for tables, e.g. ``"lmmse"`` or ``"malvar2004"``.
        pattern: The sensor pattern whose raw images the method reconstructs.
    """

    name: str
    pattern: Pattern

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        """Estimate the scene.

        Args:
            raw: Raw sensor image (noise included).
            sigma: The noise level in 8-bit units (methods may ignore it).

        Returns:
            RGB estimate, float, not clamped, same dtype as ``raw``.

        Shape:
            - raw: ``(N, 1, H, W)``.
            - output: ``(N, 3, H, W)``.
        """
        ...


# --------------------------------------------------------------------------------------------
# Classical demosaicking of the Bayer pattern


def _demosaic_functions() -> dict[str, Callable[..., np.ndarray]]:
    import colour_demosaicing as cd

    return {
        "bilinear": cd.demosaicing_CFA_Bayer_bilinear,
        "malvar2004": cd.demosaicing_CFA_Bayer_Malvar2004,
        "menon2007": cd.demosaicing_CFA_Bayer_Menon2007,
    }


class ClassicalDemosaic:
    """Classical demosaicking of the ``bayer`` pattern (RGGB) with ``colour-demosaicing``.

    ``bilinear`` is ``demosaicing_CFA_Bayer_bilinear``, ``malvar2004`` is
    ``demosaicing_CFA_Bayer_Malvar2004`` (Malvar, He & Cutler 2004) and ``menon2007`` is
    ``demosaicing_CFA_Bayer_Menon2007`` (Menon, Andriani & Calvagno 2007, with its refining
    step). These algorithms interpolate and do not denoise: ``sigma`` is ignored, so at
    ``sigma > 0`` they pass the noise (and its demosaicking artefacts) straight through.

    Args:
        method: One of ``bilinear``, ``malvar2004``, ``menon2007`` (case-insensitive).

    Raises:
        ValueError: Unknown method; the message lists the valid names.
    """

    METHODS = ("bilinear", "malvar2004", "menon2007")

    def __init__(self, method: str) -> None:
        key = str(method).strip().lower()
        if key not in self.METHODS:
            raise ValueError(
                f"expected a demosaicking method among {', '.join(self.METHODS)}, got {method!r}"
            )
        self.name = key
        self.pattern = get("bayer")
        self._function = _demosaic_functions()[key]

    def reconstruct(self, raw: torch.Tensor, sigma: float = 0.0) -> torch.Tensor:
        """Demosaic each image of the batch (``sigma`` is checked, then ignored).

        Shape:
            - raw: ``(N, 1, H, W)``, the RGGB mosaic (R at (0, 0)).
            - output: ``(N, 3, H, W)``, same dtype and device as ``raw``.
        """
        check_raw(raw)
        _check_sigma(sigma)
        cfa = raw.detach().cpu().double().numpy()
        # The package works in float64 on (H, W) arrays and returns (H, W, 3).
        out = np.stack([self._function(cfa[n, 0], "RGGB") for n in range(cfa.shape[0])])
        rgb = torch.from_numpy(np.ascontiguousarray(out.transpose(0, 3, 1, 2)))
        return rgb.to(device=raw.device, dtype=raw.dtype)

    def __repr__(self) -> str:
        return f"ClassicalDemosaic({self.name!r})"


# --------------------------------------------------------------------------------------------
# LMMSE: statistics, filters, reconstruction


class LMMSEFileError(ValueError):
    """A saved LMMSE statistics file is missing, damaged or inconsistent; the message says why."""


def _phase_slices(
    size: int, period: int, phase: int, radius: int, margin: int
) -> tuple[int, int]:
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
    _cache: dict[float, tuple[torch.Tensor, torch.Tensor]] = field(
        default_factory=dict, init=False, repr=False
    )

    def __post_init__(self) -> None:
        ph, pw = self.pattern.period
        p, d = ph * pw, (2 * self.radius + 1) ** 2
        expected = {
            "xx": (p, d + 1, d + 1), "xy": (p, d + 1, 3), "yy": (p, 3, 3), "counts": (p,),
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
            self.pattern, self.radius, self.xx + other.xx, self.xy + other.xy,
            self.yy + other.yy, self.counts + other.counts,
            {"pooled": [self.info, other.info]},
        )

    def _solve(self, sigma: float) -> torch.Tensor:
        """The ``(P, d + 1, 3)`` LMMSE solution (filters and bias) at ``sigma``, float64."""
        if bool((self.counts == 0).any()):
            raise ValueError("expected statistics with at least one sample per phase, got none")
        n = self.counts.to(torch.float64).view(-1, 1, 1)
        mxx = self.xx / n
        mxy = self.xy / n
        d = mxx.shape[-1] - 1
        trace = torch.diagonal(mxx[:, :d, :d], dim1=-2, dim2=-1).sum(-1)
        diag = (sigma / 255.0) ** 2 + _RIDGE * trace / d
        eye = torch.zeros(d + 1, dtype=torch.float64)
        eye[:d] = 1.0
        # White noise independent of the signal and zero-mean: it adds (sigma/255)^2 to the
        # variance of every raw value and nothing to any other moment (the bias entry included).
        mxx = mxx + diag.view(-1, 1, 1) * torch.diag(eye)
        return torch.linalg.solve(mxx, mxy)

    def filters(self, sigma: float) -> tuple[torch.Tensor, torch.Tensor]:
        """The LMMSE filters and biases for noise level ``sigma`` (cached per sigma).

        Filter ``[p, c, a, b]`` multiplies the raw value at offset ``(a - r, b - r)`` from a pixel
        of phase ``p = i * Pw + j``, to predict colour ``c`` of that pixel.

        Args:
            sigma: Noise standard deviation in 8-bit units (``0`` for noise-free raw images).

        Returns:
            ``(weights, bias)`` in float64.

        Shape:
            - weights: ``(Ph * Pw, 3, 2r + 1, 2r + 1)``.
            - bias: ``(Ph * Pw, 3)``.
        """
        sigma = _check_sigma(sigma)
        if sigma not in self._cache:
            w = self._solve(sigma)
            k = self.kernel_size
            weights = w[:, :-1, :].transpose(1, 2).reshape(-1, 3, k, k).contiguous()
            self._cache[sigma] = (weights, w[:, -1, :].contiguous())
        return self._cache[sigma]

    def expected_mse(self, sigma: float) -> float:
        """Mean squared error of the LMMSE filters on the training neighbourhoods themselves.

        ``E|y - W^T x|^2 = tr(E[y y^T] - E[x y^T]^T W)`` at the optimum ``W``, averaged over the 3
        colours and over all neighbourhoods, in [0, 1] units. A score that needs no test
        images; being in-sample it is slightly optimistic, and it ignores image borders.
        """
        sigma = _check_sigma(sigma)
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
        from safetensors.torch import save_file

        tensors_path, meta_path = _paired_paths(path)
        tensors_path.parent.mkdir(parents=True, exist_ok=True)
        save_file(
            {
                "xx": self.xx.contiguous(), "xy": self.xy.contiguous(),
                "yy": self.yy.contiguous(), "counts": self.counts.contiguous(),
            },
            str(tensors_path),
            metadata={"format": _FORMAT, "version": str(_VERSION)},
        )
        meta = {
            "format": _FORMAT,
            "version": _VERSION,
            "pattern": self.pattern.to_dict(),
            "radius": self.radius,
            "counts": [int(c) for c in self.counts],
            "tensors": tensors_path.name,
            "sha256": hashlib.sha256(tensors_path.read_bytes()).hexdigest(),
            "info": self.info,
        }
        meta_path.write_text(json.dumps(meta, indent=1) + "\n")
        return meta_path

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LMMSEStatistics:
        """Read statistics written by :meth:`save`.

        Raises:
            LMMSEFileError: A file is missing, unreadable or damaged, the tensor file's checksum
                differs from the one recorded, or the contents are inconsistent.
        """
        from safetensors import SafetensorError
        from safetensors.torch import load

        tensors_path, meta_path = _paired_paths(path)
        try:
            meta = json.loads(meta_path.read_text())
        except OSError as exc:
            raise LMMSEFileError(f"cannot read LMMSE statistics '{meta_path}': {exc}") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise LMMSEFileError(f"'{meta_path}' is not valid JSON (damaged?): {exc}") from None
        if not isinstance(meta, dict) or meta.get("format") != _FORMAT:
            raise LMMSEFileError(f"'{meta_path}' is not an LMMSE statistics file ({_FORMAT})")
        if meta.get("version") != _VERSION:
            raise LMMSEFileError(
                f"'{meta_path}': expected format version {_VERSION}, got {meta.get('version')!r}"
            )
        try:
            blob = tensors_path.read_bytes()
        except OSError as exc:
            raise LMMSEFileError(f"cannot read LMMSE tensors '{tensors_path}': {exc}") from None
        if hashlib.sha256(blob).hexdigest() != meta.get("sha256"):
            raise LMMSEFileError(
                f"'{tensors_path}' does not match the checksum recorded in '{meta_path}' "
                f"(damaged, or from another fit)"
            )
        try:
            tensors = load(blob)
            pattern = Pattern.from_dict(meta["pattern"], source=str(meta_path))
            stats = cls(
                pattern, int(meta["radius"]), tensors["xx"], tensors["xy"], tensors["yy"],
                tensors["counts"], dict(meta.get("info", {})),
            )
        except (SafetensorError, PatternError, KeyError, TypeError, ValueError) as exc:
            raise LMMSEFileError(f"damaged LMMSE statistics '{meta_path}': {exc}") from None
        if [int(c) for c in stats.counts] != meta.get("counts"):
            raise LMMSEFileError(f"'{meta_path}': counts differ from those in '{tensors_path}'")
        return stats


def _paired_paths(path: str | os.PathLike[str]) -> tuple[Path, Path]:
    path = Path(path)
    if path.suffix.lower() in (".safetensors", ".json"):
        path = path.with_suffix("")
    return path.with_name(path.name + ".safetensors"), path.with_name(path.name + ".json")


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
    pattern: Pattern | str,
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
        pattern: The pattern (name, file path or :class:`Pattern`).
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
    pattern = get(pattern)
    if isinstance(radius, bool) or not isinstance(radius, int) or radius < 0:
        raise ValueError(f"expected radius as an integer >= 0, got {radius!r}")
    if not isinstance(source, (torch.Tensor, PatchSampler)):
        if patches < 1:
            raise ValueError(f"expected patches >= 1, got {patches}")
        cache = source if isinstance(source, ImageCache) else ImageCache(
            source, min_size=patch_size, progress=progress
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
            "source": str(sampler.cache.paths[0].parent) if sampler.cache.paths else "",
            "images": len(sampler.cache), "patches": patches,
            "patch_size": sampler.patch_size, "seed": sampler.seed,
        }
    with torch.no_grad():
        for rgb in batches:
            _accumulate(stats, sensor(rgb), rgb, (ph, pw), radius, margins)
    return LMMSEStatistics(pattern, radius, *stats, info=info)


class LMMSE:
    """Linear MMSE reconstruction of any pattern, from precomputed :class:`LMMSEStatistics`.

    Every pixel's RGB is a linear function (plus bias) of the raw values in its
    ``(2r+1) x (2r+1)`` neighbourhood, with one filter per phase of the period, solved for the
    noise level passed to :meth:`reconstruct`. Outside the image the raw image is taken as 0.

    Args:
        statistics: The fitted statistics (see :func:`fit_lmmse`, :meth:`LMMSEStatistics.load`).
        name: Label for tables.
    """

    def __init__(self, statistics: LMMSEStatistics, name: str = "lmmse") -> None:
        self.statistics = statistics
        self.pattern = statistics.pattern
        self.name = name

    @classmethod
    def fit(
        cls, pattern: Pattern | str,
        source: torch.Tensor | PatchSampler | ImageCache | str | os.PathLike[str], **kwargs: Any,
    ) -> LMMSE:
        """``LMMSE(fit_lmmse(pattern, source, **kwargs))``."""
        return cls(fit_lmmse(pattern, source, **kwargs))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LMMSE:
        """Load statistics saved by :meth:`save` (see :meth:`LMMSEStatistics.load`)."""
        return cls(LMMSEStatistics.load(path))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Save the statistics (see :meth:`LMMSEStatistics.save`)."""
        return self.statistics.save(path)

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        """Apply the phase filters for ``sigma``: one convolution, then a per-pixel phase pick.

        Args:
            raw: Raw image of :attr:`pattern` (phase ``(0, 0)`` at the top-left pixel).
            sigma: Noise standard deviation in 8-bit units that the filters are solved for.

        Returns:
            RGB estimate, not clamped, in ``raw``'s dtype and device.

        Shape:
            - raw: ``(N, 1, H, W)``.
            - output: ``(N, 3, H, W)``.
        """
        check_raw(raw)
        weights, bias = self.statistics.filters(sigma)
        ph, pw = self.pattern.period
        r = self.statistics.radius
        n, _, h, w = raw.shape
        weights = weights.to(device=raw.device, dtype=raw.dtype)
        bias = bias.to(device=raw.device, dtype=raw.dtype)
        out = F.conv2d(raw, weights.reshape(-1, 1, 2 * r + 1, 2 * r + 1), padding=r)
        out = out.view(n, ph * pw, 3, h, w)
        rows = torch.arange(h, device=raw.device) % ph
        cols = torch.arange(w, device=raw.device) % pw
        phase = rows[:, None] * pw + cols[None, :]
        index = phase.view(1, 1, 1, h, w).expand(n, 1, 3, h, w)
        picked = out.gather(1, index).squeeze(1)
        return picked + bias[phase].permute(2, 0, 1).unsqueeze(0)

    def __repr__(self) -> str:
        return (
            f"LMMSE(pattern={self.pattern.name!r}, radius={self.statistics.radius}, "
            f"samples={int(self.statistics.counts.sum())})"
        )


# --------------------------------------------------------------------------------------------
# Evaluation and screening


TestImages = Sequence[tuple[str, torch.Tensor]] | str | os.PathLike[str]


def _test_images(images: TestImages) -> list[tuple[str, torch.Tensor]]:
    if isinstance(images, (str, os.PathLike)):
        return load_validation(images)
    out = list(images)
    if not out:
        raise ValueError("expected at least one test image, got none")
    for name, img in out:
        if not isinstance(img, torch.Tensor) or img.ndim != 3 or img.shape[0] != 3:
            raise ValueError(f"expected test image {name!r} as a (3, H, W) tensor")
    return out


def evaluate_method(
    method: Method,
    images: TestImages,
    sigmas: Iterable[float],
    *,
    psnr_crops: Sequence[int] = (),
) -> list[dict[str, Any]]:
    """Score a method on whole test images (SPEC section 7), one row per image and sigma.

    Each image goes through the method's sensor (float32), gets the evaluation noise of its
    name and sigma (:func:`~splitcam.noise.add_evaluation_noise`, the same for every method),
    is reconstructed (:func:`splitcam.evaluation.simulate_and_reconstruct`, the step
    ``splitcam evaluate`` uses), and is compared with PSNR, SSIM and CIEDE2000 without border
    crop.

    Args:
        method: The method to score.
        images: ``(name, image)`` pairs, images ``(3, H, W)`` in [0, 1], or a folder.
        sigmas: Noise levels in 8-bit units.
        psnr_crops: Extra PSNRs with these border crops, as ``psnr_crop<c>`` (published
            demosaicking figures often crop the border).

    Returns:
        Rows ``{"image", "sigma", "psnr", "ssim", "ciede2000", "psnr_crop<c>"..., "seconds"}``;
        ``seconds`` is the time of sensor, noise and reconstruction (not the metrics).
    """
    from .evaluation import simulate_and_reconstruct

    sensor = SplitterSensor(method.pattern)
    rows = []
    data = _test_images(images)
    for sigma in sigmas:
        sigma = _check_sigma(sigma)
        for name, img in data:
            start = time.perf_counter()
            out = simulate_and_reconstruct(method, sensor, name, img.float(), sigma)
            seconds = time.perf_counter() - start
            row: dict[str, Any] = {"image": name, "sigma": sigma, **compute_all(out, img)}
            for crop in psnr_crops:
                row[f"psnr_crop{crop}"] = psnr(out, img, crop=crop)
            row["seconds"] = seconds
            rows.append(row)
    return rows


def summarise(rows: Iterable[dict[str, Any]], keys: Sequence[str]) -> dict[str, float]:
    """Mean of each metric in ``keys`` over ``rows`` (infinite PSNRs left out, see
    :func:`~splitcam.metrics.mean_over_images`)."""
    rows = list(rows)
    return {k: mean_over_images(r[k] for r in rows).mean for k in keys}


@dataclass
class ScreenResult:
    """What :func:`screen_patterns` found.

    Attributes:
        rows: One dict per pattern and sigma: ``pattern``, ``sigma``, mean ``psnr``, ``ssim``,
            ``ciede2000`` over the test images, ``rank`` (1 = best PSNR at that sigma),
            ``expected_psnr`` (in-sample on the training patches, from the statistics alone),
            ``fit_seconds`` and ``eval_seconds``.
        ranking: Per sigma, the pattern names from best to worst mean PSNR.
        per_image: The per-image rows of :func:`evaluate_method`, with a ``pattern`` key.
        statistics: The fitted statistics per pattern name (save them to reuse the fits).
        decode_seconds: Time to decode the training images (shared by all patterns).
        total_seconds: Wall time of the whole screen.
    """

    rows: list[dict[str, Any]]
    ranking: dict[float, list[str]]
    per_image: list[dict[str, Any]]
    statistics: dict[str, LMMSEStatistics]
    decode_seconds: float
    total_seconds: float


def screen_patterns(
    pattern_names: Sequence[str | Pattern],
    train_dir: str | os.PathLike[str] | ImageCache,
    test_images: TestImages,
    sigmas: Sequence[float] = (0.0, 10.0),
    *,
    radius: int = DEFAULT_RADIUS,
    patches: int = DEFAULT_PATCHES,
    patch_size: int = DEFAULT_PATCH_SIZE,
    seed: int = 0,
    psnr_crops: Sequence[int] = (),
    progress: bool = False,
) -> ScreenResult:
    """Fit LMMSE for each pattern and rank the patterns by mean PSNR on the test images.

    Every pattern is fitted on the same training patches (one decoded cache, the same sampler
    seed) and scored on the same noisy test images, so the ranking compares the patterns, not
    the draws. Minutes for the whole library, against days of network training.

    Args:
        pattern_names: Built-in names, pattern file paths or :class:`Pattern` objects; names
            must be distinct.
        train_dir: Folder of training images (or an already decoded :class:`ImageCache`).
        test_images: ``(name, image)`` pairs or a folder (see :func:`evaluate_method`).
        sigmas: Noise levels in 8-bit units.
        radius, patches, patch_size, seed: See :func:`fit_lmmse`.
        psnr_crops: Extra border-cropped PSNRs (see :func:`evaluate_method`), averaged into the
            rows as ``psnr_crop<c>``.
        progress: Show progress bars.

    Returns:
        A :class:`ScreenResult`.
    """
    start = time.perf_counter()
    resolved = [get(p) for p in pattern_names]
    names = [p.name for p in resolved]
    if len(set(names)) != len(names):
        raise ValueError(f"expected distinct pattern names, got {names}")
    cache = train_dir if isinstance(train_dir, ImageCache) else ImageCache(
        train_dir, min_size=patch_size, progress=progress
    )
    decode_seconds = time.perf_counter() - start
    data = _test_images(test_images)
    crop_keys = [f"psnr_crop{c}" for c in psnr_crops]
    rows: list[dict[str, Any]] = []
    per_image: list[dict[str, Any]] = []
    statistics: dict[str, LMMSEStatistics] = {}
    for pattern in resolved:
        t0 = time.perf_counter()
        stats = fit_lmmse(
            pattern, cache, radius=radius, patches=patches, patch_size=patch_size, seed=seed,
            progress=progress,
        )
        method = LMMSE(stats)
        for sigma in sigmas:
            method.statistics.filters(sigma)
        fit_seconds = time.perf_counter() - t0
        statistics[pattern.name] = stats
        for sigma in sigmas:
            t1 = time.perf_counter()
            image_rows = evaluate_method(method, data, [sigma], psnr_crops=psnr_crops)
            eval_seconds = time.perf_counter() - t1
            per_image += [{"pattern": pattern.name, **r} for r in image_rows]
            mse = stats.expected_mse(sigma)
            rows.append({
                "pattern": pattern.name, "sigma": float(sigma),
                **summarise(image_rows, ("psnr", "ssim", "ciede2000", *crop_keys)),
                "expected_psnr": -10.0 * math.log10(mse) if mse > 0 else math.inf,
                "fit_seconds": fit_seconds, "eval_seconds": eval_seconds,
            })
    ranking = _rank(rows)
    return ScreenResult(
        rows, ranking, per_image, statistics, decode_seconds, time.perf_counter() - start
    )


def _rank(rows: list[dict[str, Any]]) -> dict[float, list[str]]:
    """Order the patterns per sigma by mean PSNR and write each row's ``rank``."""
    ranking: dict[float, list[str]] = {}
    for sigma in dict.fromkeys(r["sigma"] for r in rows):
        group = sorted((r for r in rows if r["sigma"] == sigma), key=lambda r: -r["psnr"])
        for place, row in enumerate(group, start=1):
            row["rank"] = place
        ranking[sigma] = [r["pattern"] for r in group]
    return ranking
