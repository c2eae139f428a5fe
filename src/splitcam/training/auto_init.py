"""``--init-from auto``: the best shipped network to start a new pattern's fine-tuning from,
found by trying each for a short while.

A user's own pattern has no network of its own, but it rarely lacks a good start: the network
for any pattern (``universal``) serves every pattern, and a shipped network of another pattern
with the same period already knows the period's geometry (router-zou started from the shipped A
ended 1.13 dB above the same 10 minutes from ``universal``, docs/results/universal/). Which is
best depends on the pattern, so :func:`choose_start` trains each candidate
(:func:`candidates`) for an equal share of the search time on the run's own settings, scores
each on the run's validation photos, keeps the best, and the run continues from that probe's
weights: the search is part of the budget, not added to it.
"""

from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import patterns
from ..recon.loading import load_model, model_names
from ..recon.registry import trained_domain
from .config import ConfigError, TrainConfig
from .setup import config_patterns

__all__ = ["SEARCH_SHARE", "Probe", "candidates", "choose_start"]

logger = logging.getLogger(__name__)

#: The share of the run's time limit the search takes, split evenly among the candidates.
SEARCH_SHARE = 0.3


@dataclass(frozen=True)
class Probe:
    """One candidate tried: its name, validation PSNR at its start and after its share of the
    search, the minutes it trained, and its run folder (what the run continues from)."""

    name: str
    start: float
    end: float
    minutes: float
    folder: Path


def candidates(pattern: patterns.Pattern, domain: str) -> list[str]:
    """The shipped networks a run of ``pattern`` in the light ``domain`` can start from: the
    network for any pattern of that domain, and every one-pattern network of the domain whose
    period is the pattern's (for a library pattern, its own among them)."""
    found = []
    for name in model_names():
        meta = load_model(name).meta
        config = meta.get("config") or {}
        if trained_domain(config) != domain:
            continue
        network = meta["network"]
        if network.get("arch") == "universal" and config["pattern"]["name"] == "random":
            found.insert(0, name)
        elif network.get("arch") == "physics" and tuple(network["period"]) == pattern.period:
            found.append(name)
    return found


def choose_start(
    config: TrainConfig, implied: Any, *, search_share: float = SEARCH_SHARE
) -> tuple[TrainConfig, list[Probe]]:
    """Try every candidate and return the run's settings, continuing from the best, with what
    was tried.

    Args:
        config: The run's settings, with ``run.init_from = "auto"`` and a time limit.
        implied: ``implied(candidate) -> {setting: value}``, the settings a start from that
            candidate implies (a network for any pattern sets ``--arch universal``).
        search_share: The share of the time limit the search takes.

    Raises:
        ConfigError: No time limit, a learned pattern, or no candidate for the pattern.
    """
    limit = config.run.time_limit
    if not limit:
        raise ConfigError(
            "--init-from auto shares a time limit among its candidates: give --time-limit"
        )
    if config.pattern.learn or config.pattern.name.strip().lower() == "random":
        raise ConfigError(
            "--init-from auto is for one fixed pattern (no --learn-pattern, not random)"
        )
    if not config.data.val_split and not config.data.val and config.data.val_split is not None:
        raise ConfigError("--init-from auto chooses by validation: leave --val-split above 0")
    pattern = config_patterns(config).first()
    names = candidates(pattern, config.data.domain)
    if not names:
        raise ConfigError(
            f"--init-from auto: no shipped network can start a pattern of period {pattern.period}"
        )
    share = limit * search_share / len(names)
    logger.info(
        f"--init-from auto: trying {', '.join(names)} for {share:.2f} min each "
        f"({search_share:.0%} of the {limit:g}-minute budget)"
    )
    from .trainer import train

    probes = []
    search = Path(config.run.out) / "init-search"
    for name in names:
        probe = config.override(
            {
                **implied(name),
                "run.init_from": name,
                "run.time_limit": share,
                "run.out": str(search / name),
                "run.val_every": 10**9,  # at its start and its end
            }
        )
        # A probe ends at its time limit by design: the trainer's advice to resume it with a
        # larger limit is not for the user, so its log is quiet for the probe.
        with _quiet(logging.getLogger(train.__module__)):
            train(probe, progress=False)
        scores = _val_rows(search / name) or [float("-inf")]
        probes.append(Probe(name, scores[0], scores[-1], share, search / name))
        logger.info(f"  {name}: validation {scores[0]:.2f} -> {scores[-1]:.2f} dB")
    best = max(probes, key=lambda p: p.end)
    logger.info(
        f"--init-from auto: continuing from {best.name} ({best.end:.2f} dB after its probe, the "
        f"best of {len(probes)}) for the {limit * (1 - search_share):.2f} minutes left"
    )
    chosen = config.override(
        {
            **implied(best.name),
            "run.init_from": str(best.folder),
            "run.time_limit": limit * (1 - search_share),
        }
    )
    return chosen, probes


def _val_rows(run: Path) -> list[float]:
    from .rundir import metrics_rows

    return [float(r["val_psnr"]) for r in metrics_rows(run) if "val_psnr" in r]


@contextlib.contextmanager
def _quiet(log: logging.Logger):
    """``log`` says only warnings and worse inside the block."""
    level = log.level
    log.setLevel(max(level, logging.WARNING))
    try:
        yield
    finally:
        log.setLevel(level)
