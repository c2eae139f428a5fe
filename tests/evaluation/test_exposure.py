"""The exposure study (splitcam.evaluation.exposure): crossovers and the raw SNR check."""

from __future__ import annotations

import math

import pytest
import torch


def test_crossover_interpolates_in_log_exposure() -> None:
    from splitcam.evaluation.exposure import crossover

    ref = {1.0: 10.0, 10.0: 20.0, 100.0: 30.0}
    assert crossover({1.0: 12.0, 10.0: 20.0 + 1.0, 100.0: 29.0}, ref) == pytest.approx(10**1.5)
    assert crossover({1.0: 11.0, 10.0: 21.0, 100.0: 31.0}, ref) == math.inf
    assert crossover({1.0: 9.0, 10.0: 21.0, 100.0: 31.0}, ref) is None
    # lower is better (CIEDE2000): wins below N = 10
    assert crossover(
        {1.0: 1.0, 10.0: 2.0, 100.0: 3.0}, {1.0: 2.0, 10.0: 2.0, 100.0: 2.0}, higher_is_better=False
    ) == pytest.approx(10.0)


def test_raw_snr_follows_the_signal_gain() -> None:
    """On a flat grey scene a lossless splitter gathers k = 3 times the filter's signal; its raw
    SNR gain is near 10 log10 k shot-limited and 20 log10 k read-limited (not exactly: its
    pixels are not k times the filter's one by one)."""
    from splitcam.evaluation.exposure import raw_snr_check

    grey = [("grey", torch.full((3, 64, 64), 0.5))]
    snr = raw_snr_check(grey, patterns=["A", "D", "bayer"])
    for name in ("A", "D"):
        assert snr[name]["k"] == pytest.approx(3.0, rel=0.03)  # borders lose a little
        assert abs(snr[name]["shot_gain_db"] - snr[name]["shot_theory_db"]) < 0.6
        assert abs(snr[name]["read_gain_db"] - snr[name]["read_theory_db"]) < 0.6
    assert snr["bayer"]["k"] == 1.0 and snr["bayer"]["read_gain_db"] == 0.0
