"""What a run's start implies when its settings leave it open: the training policy behind
``splitcam train --init-from`` and a user's own pattern.

- A start from a network for any pattern (``universal``) implies its architecture, a short
  fine-tuning budget, a lower rate and patches chosen by detail (:func:`fine_tuning`,
  :func:`start_settings`; each of ``--init-from auto``'s candidates too).
- A photon-model run from a network trained with the photon model keeps that network's range
  of exposures (:func:`photon_range`).
- A user's own pattern starts from ``universal`` (:func:`own_pattern_start`).

Each takes the dotted settings a run's flags and configuration file give (what either sets is
kept) and returns the settings implied, announcing each choice in the log.
"""

from __future__ import annotations

import logging

from .. import patterns

__all__ = [
    "FINE_TUNE_HARD",
    "FINE_TUNE_LR",
    "FINE_TUNE_MINUTES",
    "fine_tuning",
    "own_pattern_start",
    "photon_range",
    "start_settings",
]

logger = logging.getLogger(__name__)

#: Default budget (minutes) and peak learning rate of fine-tuning a network for any pattern to
#: one pattern (docs/results/universal/README.md: 3e-4 against 1e-3 side by side), and its
#: patches chosen by detail (docs/results/universal/levers.md: against uniform patches, against
#: adapters and against teachers, side by side).
FINE_TUNE_MINUTES = 10.0
FINE_TUNE_LR = 3e-4
FINE_TUNE_HARD = 0.5


def fine_tuning(init_from: str, given: dict) -> dict:
    """Settings implied by ``--init-from`` a network for any pattern (``universal``) when
    ``--arch`` is left out: its architecture, unless ``--steps`` or ``--time-limit`` is given a
    budget of :data:`FINE_TUNE_MINUTES`, and unless ``--lr`` is given :data:`FINE_TUNE_LR`.

    ``given`` holds the dotted keys set by flags and by the ``--config`` file: what either sets
    is kept (experiments/gpu/universal.toml sets its own rate and time limit)."""
    from .init_from import source_network

    if (source_network(init_from) or {}).get("arch") != "universal":
        return {}
    implied = start_settings(init_from, given)
    if "optim.steps" not in given and "run.time_limit" not in given:
        implied["run.time_limit"] = FINE_TUNE_MINUTES
        logger.info(f"fine-tuning {init_from} for {FINE_TUNE_MINUTES:g} minutes (--time-limit)")
    return implied


def start_settings(source: str, given: dict) -> dict:
    """What a fine-tuning from ``source`` implies (for ``--init-from universal`` and each of
    ``--init-from auto``'s candidates): its network's architecture and size, and
    :data:`FINE_TUNE_LR` unless a rate is given."""
    from .init_from import source_network

    network = source_network(source) or {}
    implied = {
        "network.arch": network.get("arch", "physics"),
        "network.features": network.get("features", 64),
        "network.blocks": network.get("blocks", 10),
    }
    if "optim.lr" not in given:
        implied["optim.lr"] = FINE_TUNE_LR
    if "data.hard_patches" not in given:
        implied["data.hard_patches"] = FINE_TUNE_HARD
    return implied


def photon_range(source: str, given: dict) -> dict:
    """A photon-model run from a network trained with the photon model keeps that network's
    range of exposures unless ``--photons`` is given: a narrower range forgets the exposures
    left out (a fine-tune of ``universal-photon``, trained from 1, on the default 10 to 10^4 lost
    1.6-4.1 dB at N = 1; docs/results/exposure/measured/fine-tuned/)."""
    from .init_from import source_header

    if given.get("noise.model") != "photon" or "noise.photons" in given:
        return {}
    noise = (source_header(source).get("config") or {}).get("noise") or {}
    if noise.get("model") != "photon" or not noise.get("photons"):
        return {}
    lo, hi = (float(v) for v in noise["photons"])
    logger.info(f"photons {lo:g} to {hi:g}, the range {source} was trained on (--photons)")
    return {"noise.photons": [lo, hi]}


def own_pattern_start(given: dict) -> dict:
    """A user's pattern (a file or a router, not a library name) has no network of its own:
    unless the run says how to start (``--init-from``, ``--arch``, ``--learn-pattern``), it
    fine-tunes the network for any pattern, ``universal``."""
    name = str(given.get("pattern.name", ""))
    if not name or name.strip().lower() in {n.lower() for n in patterns.names()} | {"random"}:
        return {}
    if any(k in given for k in ("run.init_from", "network.arch")) or given.get("pattern.learn"):
        return {}
    logger.info(
        f"{name}: no network of its own; fine-tuning universal (--init-from universal; "
        "--arch physics trains one from scratch)"
    )
    return {"run.init_from": "universal"}
