"""What a run trains and validates on: the training images, the held-out validation split, the
noise levels and patterns validated, and the validation score itself."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import torch

from .. import patterns
from ..data.patches import ImageCache, list_images
from ..data.testsets import centre_crop
from ..evaluation.protocol import mean_psnr
from ..io.domains import SRGB
from ..physics.noise import Exposure, level_label
from ..physics.system import ImagingSystem
from ..recon.base import NetworkReconstructor
from .config import ConfigError, TrainConfig

logger = logging.getLogger(__name__)


def val_split(config: TrainConfig) -> int:
    """How many images (the last, sorted by name) the training folder holds out: the set
    ``data.val_split``, none with a ``data.val`` folder, else ``min(32, max(1, n // 10))`` of
    ``n >= 2`` images (so validation curves come by default)."""
    data = config.data
    if data.val or not data.train:
        return 0
    if data.val_split is not None:
        return data.val_split
    n = len(list_images(data.train))
    return min(32, max(1, n // 10)) if n >= 2 else 0


def _short_side(path: Path) -> int:
    """An image file's smaller side, from its header; 0 for an unreadable file, so it is never
    chosen for validation (it once was, as the only validation image, and the run stopped with
    "all 1 were skipped" beside good photos): training skips it, naming it, and goes on."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return min(im.size)
    except OSError:
        return 0


def held_out(config: TrainConfig) -> list[Path]:
    """The training folder's validation images: the last ``val_split`` (sorted by name) of those
    that fit the validation crop (or, in a folder of smaller images, that are as large as its
    largest), so a tiny image sorting last is never the whole validation set.

    Raises:
        ConfigError: The split would leave no training image.
    """
    data = config.data
    split = val_split(config)
    if not split:
        return []
    files = list_images(data.train)
    sides = {f: _short_side(f) for f in files}
    need = max(1, min(data.val_crop or 1, max(sides.values())))
    chosen = [f for f in files if sides[f] >= need][-split:]
    if len(chosen) >= len(files):
        raise ConfigError(
            f"data.val_split {split} leaves no training images (the folder has {len(files)})"
        )
    return chosen


def train_source(config: TrainConfig) -> Any:
    """The training images: the ``data.train`` folder, or its files but the held-out ones.

    Raises:
        ConfigError: No training folder, or the split would leave no training image.
    """
    if not config.data.train:
        raise ConfigError("no training data: give --data DIR (or data.train in the config)")
    held = set(held_out(config))
    if held:
        return [f for f in list_images(config.data.train) if f not in held]
    return config.data.train


def val_images(config: TrainConfig) -> list[tuple[str, torch.Tensor]]:
    """Validation images: the held-out split or the --val folder, at ``data.val_scale`` of
    their size (:func:`~splitcam.data.patches.downscale`), centre-cropped."""
    data = config.data
    if data.val:
        source: Any = data.val
    elif val_split(config) and data.train:
        source = held_out(config)
    else:
        return []
    cache = ImageCache(
        source,
        min_size=1,
        max_images=data.val_max_images,
        progress=False,
        scales=(data.val_scale,),
    )
    images = []
    for i, name in enumerate(cache.names):
        img = cache.image(i)
        if data.val_crop:
            img = centre_crop(img, data.val_crop, multiple=1)
        images.append((name, img.contiguous()))
    return images


def say_held_out(config: TrainConfig, images: list[tuple[str, torch.Tensor]]) -> None:
    """Log which training images a run holds out for validation (nothing with a --val folder)."""
    if not images or config.data.val:
        return
    names = [name for name, _ in images]
    shown = ", ".join(names[:4]) + (", ..." if len(names) > 4 else "")
    crop = f" (of those at least {config.data.val_crop} px)" if config.data.val_crop else ""
    logger.info(
        f"validation: {len(names)} of the last {val_split(config)} images of "
        f"{config.data.train}{crop}, held out of training: {shown}"
    )


def val_levels(config: TrainConfig) -> list[float] | list[Exposure]:
    """The noise levels validated (:func:`~splitcam.training.noise.validation_levels`):
    ``data.val_sigmas``, or the photon model's exposures."""
    from .noise import validation_levels

    return validation_levels(config)


def validate(
    system: ImagingSystem,
    images: list[tuple[str, torch.Tensor]],
    sigmas: list[float] | list[Exposure],
    val_patterns: list[patterns.Pattern] | None = None,
    *,
    domain: str = SRGB,
    precision: str = "fp32",
) -> dict[str, float]:
    """Mean PSNR per noise level (a sigma, or a photon-model exposure: ``val_psnr_N<photons>``)
    on the validation images, by the evaluation protocol itself
    (:func:`splitcam.evaluation.protocol.mean_psnr`): the pattern as a run's checkpoint records
    it, the same simulation, noise, reconstruction, rounding and averaging as ``splitcam
    evaluate``, so the logged value is what ``evaluate`` reports for this step.

    ``domain`` is the run's light domain (model.md §13): in ``linear`` the images are decoded
    to radiance before the sensor and the network's estimate is encoded back to 8-bit sRGB
    before it is scored against them, as ``evaluate --domain linear`` does.

    With ``val_patterns`` (a run over many patterns) each of them is scored
    (``val_psnr_<pattern>_<level>``) and the plain keys hold the means over the patterns.

    ``precision`` is the run's own (``fp32``, or ``bf16`` for a run in bfloat16 + channels-last):
    the network is scored as it trains. Validation leaves the training state as it found it:
    the weights' memory layout (:func:`~splitcam.recon.tiling.reconstruct` restores it), the
    global generator and the autocast weight cache, so a resumed run equals an uninterrupted
    one.
    """
    was_training = system.training
    system.eval()
    targets = val_patterns or [system.sensor.to_pattern()]
    per_pattern = {}
    rng = torch.get_rng_state()
    try:
        for pattern in targets:
            method = NetworkReconstructor(
                system.network, pattern, "validation", domain=domain, precision=precision
            )
            per_pattern[pattern.name] = mean_psnr(method, images, sigmas, domain=domain)
    finally:
        torch.set_rng_state(rng)
        torch.clear_autocast_cache()
        system.train(was_training)

    means = {s: sum(m[s] for m in per_pattern.values()) / len(per_pattern) for s in sigmas}
    out = {f"val_psnr_{level_label(s)}": value for s, value in means.items()}
    if val_patterns:
        for name, scores in per_pattern.items():
            out.update({f"val_psnr_{name}_{level_label(s)}": v for s, v in scores.items()})
    out["val_psnr"] = sum(means.values()) / len(means)
    return out
