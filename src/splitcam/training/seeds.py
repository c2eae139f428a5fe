"""Every random stream of a training run, derived from ``run.seed``.

Each stream has its own seed so that changing one part of a run (another pattern mix, more
ranks) leaves the others' draws as they were, and a resumed run repeats the uninterrupted one
(the generators' states are checkpointed; these seeds only start them).
"""

from __future__ import annotations

from .config import TrainConfig

#: Spacing of the per-rank and per-step seeds (primes, so the streams do not line up).
_STEP = 7919
_SAMPLER_RANK = 1_000_003
_NOISE_RANK = 2_000_003


def global_seed(config: TrainConfig) -> int:
    """Torch's global generator (network initialisation)."""
    return config.run.seed


def pattern_seed(config: TrainConfig) -> int:
    """A learned pattern's initialisation, its closed-form design, a metasurface's profile."""
    return config.run.seed + 17


def mix_seed(config: TrainConfig) -> int:
    """Which pattern each step of a ``--pattern random`` run draws."""
    return config.run.seed + 31


def sampler_seed(config: TrainConfig, start_step: int) -> int:
    """The training patches (a run continued from another's weights must not replay its first
    patches; :class:`~splitcam.data.patches.PatchSampler` adds the rank)."""
    return config.run.seed + start_step


def mining_seed(config: TrainConfig) -> int:
    """The windows scored when mining by colour error (``data.colour_mined``): a stream of
    their own, so the training patches are the same with and without mining's draws."""
    return config.run.seed + 7_919


def noise_seed(config: TrainConfig, start_step: int, rank: int) -> int:
    """The simulated sensor noise of one rank."""
    return (config.run.seed + start_step) * _STEP + 1 + 104729 * rank


def reseeded(sampler_seed: int, rank: int, step: int) -> tuple[int, int]:
    """``(patch seed, noise seed)`` of a rank that a checkpoint holds no generator state for (a
    run resumed with more processes than it had): a function of the step, so not a replay."""
    return (
        sampler_seed + _SAMPLER_RANK * rank + _STEP * step,
        sampler_seed + _NOISE_RANK * rank + _STEP * step,
    )
