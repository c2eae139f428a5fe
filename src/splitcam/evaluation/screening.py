"""Screening: score reconstruction methods on whole images, and rank many patterns by their
LMMSE in minutes, before spending hours training networks."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import torch

from ..data.patches import ImageCache, load_validation
from ..patterns import Pattern, check_pattern
from ..physics.sensor import SplitterSensor
from ..recon.base import Reconstructor, check_sigma
from ..recon.lmmse import (
    DEFAULT_PATCH_SIZE,
    DEFAULT_PATCHES,
    DEFAULT_RADIUS,
    LMMSE,
    LMMSEStatistics,
    fit_lmmse,
)
from .metrics import mean_over_images, psnr
from .protocol import score, simulate_and_reconstruct

__all__ = ["ScreenResult", "evaluate_method", "screen_patterns"]


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
    method: Reconstructor,
    images: TestImages,
    sigmas: Iterable[float],
    *,
    psnr_crops: Sequence[int] = (),
) -> list[dict[str, Any]]:
    """Score a method on whole test images (model.md §7), one row per image and sigma.

    The protocol's own steps (:func:`~splitcam.evaluation.protocol.simulate_and_reconstruct`
    and :func:`~splitcam.evaluation.protocol.score`, as ``splitcam evaluate``), with the time of
    the simulation and reconstruction of each image added.

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
    sensor = SplitterSensor(method.pattern)
    rows = []
    data = _test_images(images)
    for sigma in sigmas:
        sigma = check_sigma(sigma)
        for name, img in data:
            start = time.perf_counter()
            out = simulate_and_reconstruct(method, sensor, name, img.float(), sigma)
            seconds = time.perf_counter() - start
            row: dict[str, Any] = {"image": name, "sigma": sigma, **score(out, img)}
            for crop in psnr_crops:
                row[f"psnr_crop{crop}"] = psnr(out, img, crop=crop)
            row["seconds"] = seconds
            rows.append(row)
    return rows


def _means(rows: Iterable[dict[str, Any]], keys: Sequence[str]) -> dict[str, float]:
    """Mean of each metric in ``keys`` over ``rows`` (infinite PSNRs left out, see
    :func:`~splitcam.evaluation.metrics.mean_over_images`)."""
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
    patterns: Sequence[Pattern],
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
        patterns: The patterns, of distinct names.
        train_dir: Folder of training images (or an already decoded :class:`ImageCache`).
        test_images: ``(name, image)`` pairs or a folder (see :func:`evaluate_method`).
        sigmas: Noise levels in 8-bit units.
        radius: See :func:`fit_lmmse`.
        patches: See :func:`fit_lmmse`.
        patch_size: See :func:`fit_lmmse`.
        seed: See :func:`fit_lmmse`.
        psnr_crops: Extra border-cropped PSNRs (see :func:`evaluate_method`), averaged into the
            rows as ``psnr_crop<c>``.
        progress: Show progress bars.

    Returns:
        A :class:`ScreenResult`.
    """
    start = time.perf_counter()
    resolved = [check_pattern(p) for p in patterns]
    names = [p.name for p in resolved]
    if len(set(names)) != len(names):
        raise ValueError(f"expected distinct pattern names, got {names}")
    cache = (
        train_dir
        if isinstance(train_dir, ImageCache)
        else ImageCache(train_dir, min_size=patch_size, progress=progress)
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
            pattern,
            cache,
            radius=radius,
            patches=patches,
            patch_size=patch_size,
            seed=seed,
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
            rows.append(
                {
                    "pattern": pattern.name,
                    "sigma": float(sigma),
                    **_means(image_rows, ("psnr", "ssim", "ciede2000", *crop_keys)),
                    "expected_psnr": -10.0 * math.log10(mse) if mse > 0 else math.inf,
                    "fit_seconds": fit_seconds,
                    "eval_seconds": eval_seconds,
                }
            )
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
