"""The noise a run trains under: one table, :data:`TRAINING_NOISE`, keyed by the
configuration's ``noise.model``.

Each entry says how a configuration becomes the level sampler of training (drawn by the one
:class:`~splitcam.physics.noise.TrainingNoise`, which makes a batch noisy through the levels'
own :meth:`~splitcam.physics.noise.NoiseModel.apply_batch`), the levels validation scores, and
what to check of the settings before a run starts. A new noise model for training is its
:class:`~splitcam.physics.noise.NoiseModel` (in its own module, the user's included) plus one
entry here: nothing else in training branches on the noise model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch

from ..physics.noise import Exposure, LogUniformExposure, TrainingNoise, UniformSigma

if TYPE_CHECKING:
    from .config import TrainConfig

__all__ = ["TRAINING_NOISE", "NoiseType", "build_noise", "validation_levels"]


def _no_check(config: TrainConfig) -> None:
    del config


@dataclass(frozen=True)
class NoiseType:
    """One noise model as training uses it."""

    #: ``config -> (n, generator) -> [level] * n``: the levels of a step.
    sampler: Callable[[TrainConfig], Callable[[int, torch.Generator], list]]
    #: ``config -> levels``: what validation scores (``val_psnr_<label>``).
    validation: Callable[[TrainConfig], list[Any]]
    #: ``config -> None``, raising ValueError for settings the model refuses.
    check: Callable[[TrainConfig], None] = _no_check


def _photon_sampler(config: TrainConfig) -> LogUniformExposure:
    """The photon model's level sampler (it checks the sensor settings and the range)."""
    return LogUniformExposure(*config.noise.photons, config.noise.sensor())


def _photon_levels(config: TrainConfig) -> list[Exposure]:
    return [Exposure(n, **config.noise.sensor()) for n in config.noise.val_photons]


def _photon_check(config: TrainConfig) -> None:
    """The photon model's settings: its validation levels and its sampler are built (each
    refuses what it cannot take)."""
    _photon_levels(config)
    _photon_sampler(config)


TRAINING_NOISE: dict[str, NoiseType] = {
    # The paper's: sigma ~ U[optim.sigma_min, optim.sigma_max]; validated at data.val_sigmas.
    "gaussian": NoiseType(
        sampler=lambda c: UniformSigma(c.optim.sigma_min, c.optim.sigma_max),
        validation=lambda c: list(c.data.val_sigmas),
    ),
    # The photon model (model.md §11) at exposures drawn log-uniformly from noise.photons.
    "photon": NoiseType(
        sampler=_photon_sampler,
        validation=_photon_levels,
        check=_photon_check,
    ),
}


def build_noise(
    config: TrainConfig, seed: int, device: torch.device | None = None
) -> TrainingNoise:
    """The training noise of a configuration, seeded, drawn on ``device`` (default the CPU)."""
    return TrainingNoise(
        TRAINING_NOISE[config.noise.model].sampler(config),
        per_sample=config.optim.per_sample_sigma,
        seed=seed,
        device=device,
    )


def validation_levels(config: TrainConfig) -> list[Any]:
    """The noise levels a run is validated at."""
    return TRAINING_NOISE[config.noise.model].validation(config)
