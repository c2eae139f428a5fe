"""What a start implies (splitcam.training.starts): a network for any pattern implies its
architecture, the fine-tuning budget, rate and detail-chosen patches unless the run sets them; a
photon fine-tune keeps its network's exposures; a user's own pattern starts from universal; each
choice is announced in the log."""

from __future__ import annotations

import json
import logging

from splitcam.recon.loading import resolve_model
from splitcam.training.config import TrainConfig
from splitcam.training.starts import (
    FINE_TUNE_HARD,
    FINE_TUNE_LR,
    FINE_TUNE_MINUTES,
    fine_tuning,
    own_pattern_start,
    photon_range,
    start_settings,
)


def test_a_universal_start_implies_the_fine_tuning_defaults(tiny_universal, caplog) -> None:
    model, _ = tiny_universal
    with caplog.at_level(logging.INFO, logger="splitcam"):
        implied = fine_tuning(str(model), {})
    assert implied["run.time_limit"] == FINE_TUNE_MINUTES and implied["optim.lr"] == FINE_TUNE_LR
    assert implied["network.arch"] == "universal" and implied["network.features"] == 8
    assert f"for {FINE_TUNE_MINUTES:g} minutes" in caplog.text
    given = fine_tuning(str(model), {"run.time_limit": 1.0, "optim.lr": 1e-3})
    assert "run.time_limit" not in given and "optim.lr" not in given
    assert fine_tuning("D", {}) == {}  # a network of one pattern implies nothing
    assert start_settings("universal", {})["data.hard_patches"] == FINE_TUNE_HARD
    assert "data.hard_patches" not in start_settings("universal", {"data.hard_patches": 0.0})


def test_a_users_pattern_starts_from_universal_unless_the_run_says(caplog) -> None:
    with caplog.at_level(logging.INFO, logger="splitcam"):
        assert own_pattern_start({"pattern.name": "mine.toml"}) == {"run.init_from": "universal"}
    assert "no network of its own" in caplog.text
    assert own_pattern_start({"pattern.name": "router(eta=0.5)"}) == {"run.init_from": "universal"}
    for given in (
        {"pattern.name": "D"},  # a library pattern trains by its recipe
        {"pattern.name": "random"},
        {"pattern.name": "mine.toml", "network.arch": "physics"},
        {"pattern.name": "mine.toml", "run.init_from": "A"},
        {"pattern.name": "mine.toml", "pattern.learn": True},
    ):
        assert own_pattern_start(given) == {}, given


def test_a_photon_fine_tune_keeps_its_networks_exposures(caplog) -> None:
    header = json.loads(resolve_model("universal-photon").read_text())["config"]["noise"]
    assert header["photons"] != TrainConfig().noise.photons  # what the rule is for
    photon = {"noise.model": "photon"}
    with caplog.at_level(logging.INFO, logger="splitcam"):
        assert photon_range("universal-photon", photon) == {"noise.photons": header["photons"]}
    assert "the range universal-photon was trained on" in caplog.text
    assert photon_range("universal-photon", {**photon, "noise.photons": [5.0, 50.0]}) == {}
    assert photon_range("universal-photon", {}) == {}  # a Gaussian run
    assert photon_range("universal", photon) == {}  # trained on Gaussian noise
