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


def _synthetic_results() -> dict:
    """PSNR / CIEDE2000 curves over N = 1, 10, 100, 1000: the router beats bayer below
    N = 10^2.5 and rgbw below N = 10^1.5; quad loses to rgbw below N = 10^1.5 and wins above."""
    ns = (1.0, 10.0, 100.0, 1000.0)

    def curve(psnr):
        return {
            n: {"psnr": p, "ssim": 0.5, "ciede2000": 40.0 - p}
            for n, p in zip(ns, psnr, strict=True)
        }

    return {
        "bayer": curve([10.0, 20.0, 30.0, 40.0]),
        "rgbw": curve([12.0, 22.0, 32.0, 42.0]),
        "router": curve([13.0, 23.0, 31.0, 39.0]),
        "quad": curve([11.0, 21.0, 33.0, 43.0]),
    }


def test_crossover_against_rgbw_on_synthetic_curves() -> None:
    from splitcam.evaluation.exposure import crossover

    r = _synthetic_results()
    at = {k: {n: v["psnr"] for n, v in c.items()} for k, c in r.items()}
    assert crossover(at["router"], at["bayer"]) == pytest.approx(10**2.5)
    assert crossover(at["router"], at["rgbw"]) == pytest.approx(10**1.5)
    assert crossover(at["quad"], at["rgbw"]) is None


def test_write_study_states_crossovers_against_both_references(tmp_path) -> None:
    from splitcam.evaluation.exposure import write_study

    r = _synthetic_results()
    text = write_study(r, None, tmp_path / "two", references=("bayer", "rgbw")).read_text()
    assert "| pattern | vs bayer: PSNR | vs bayer: CIEDE2000 | vs rgbw: PSNR |" in text
    table = text.split("## Crossover")[1].splitlines()
    row = next(line for line in table if line.startswith("| router |"))
    assert row.count("N ≈ 316") == 2 and row.count("N ≈ 31.6") == 2
    quad = next(line for line in table if line.startswith("| quad |"))
    assert "never below; above N ≈ 31.6" in quad
    # a window: loses at the lowest exposure, wins between two crossings
    r["window"] = {n: {**v, "psnr": v["psnr"] + d} for (n, v), d in zip(
        r["rgbw"].items(), (-0.5, 1.0, 1.0, -1.0), strict=True)}  # fmt: skip
    text = write_study(r, None, tmp_path / "three", references=("rgbw",)).read_text()
    window = next(x for x in text.split("## Crossover")[1].splitlines() if "| window |" in x)
    assert "never below; between N ≈ 2.15 and 316" in window
    # the default: the Bayer filter only, as before
    text = write_study(r, None, tmp_path / "one").read_text()
    assert "beats the Bayer filter" in text and "vs rgbw" not in text
    assert "| bayer |" not in text.split("## Crossover")[1]


def test_write_study_compares_each_network_with_the_references_network(tmp_path) -> None:
    """Networks get a crossover table of their own: the router's network against the filter's
    network (not against the filter's LMMSE), labels as a model for any pattern names them."""
    from splitcam.evaluation.exposure import write_study

    r = _synthetic_results()
    # the networks: each LMMSE curve shifted; the router's network loses to rgbw's above N = 10
    shift = {"bayer": 2.0, "rgbw": 2.0, "router": 1.0}
    for name, d in shift.items():
        r[f"net-u-{name}"] = {
            n: {**v, "psnr": v["psnr"] + d, "ciede2000": v["ciede2000"] - d}
            for n, v in r[name].items()
        }
    networks = {f"net-u-{name}": name for name in shift}
    text = write_study(
        r, None, tmp_path, references=("bayer", "rgbw"), networks=networks
    ).read_text()
    lmmse, nets = text.split("## Crossover")[1:3]
    assert "(closed-form LMMSE)" in lmmse and "net-u-" not in lmmse
    assert "against the reference's network" in nets
    row = next(line for line in nets.splitlines() if line.startswith("| net-u-router |"))
    # router + 1 against rgbw + 2: wins by 0, 0, -2, -4 -> 1 - 1 = 0 at N = 1, loses above
    diff = [r["router"][n]["psnr"] + 1 - r["rgbw"][n]["psnr"] - 2 for n in (1, 10, 100, 1000)]
    assert diff == [0.0, 0.0, -2.0, -4.0] and row.split(" | ")[3] == "never"
    # against bayer's network: +2 -1 = +1 difference over LMMSE's crossover curve
    assert row.split(" | ")[1].startswith("N ≈ ")


def test_exposure_study_continues_an_interrupted_run(tmp_path) -> None:
    """With `out`, a second run reuses every score of the first (no reconstruction repeated)
    and gives the same numbers; a new exposure computes only the new rows."""
    from splitcam import patterns
    from splitcam.evaluation.exposure import exposure_study

    class Counted:
        name = "net-count-A"
        pattern = patterns.get("A")
        domain = "linear"

        def __init__(self) -> None:
            self.calls = 0

        def reconstruct(self, raw, level):
            self.calls += 1
            return raw.expand(-1, 3, -1, -1).clone()

    images = [("flat", torch.full((3, 20, 22), 0.4)), ("ramp", torch.rand(3, 20, 22))]
    first = Counted()
    a = exposure_study(images, patterns=["A"], photons=[10.0], methods=[first], out=tmp_path,
                       progress=False)  # fmt: skip
    again = Counted()
    b = exposure_study(images, patterns=["A"], photons=[10.0], methods=[again], out=tmp_path,
                       progress=False)  # fmt: skip
    assert first.calls == 2 and again.calls == 0 and a == b
    more = Counted()
    c = exposure_study(images, patterns=["A"], photons=[10.0, 100.0], methods=[more],
                       out=tmp_path, progress=False)  # fmt: skip
    assert more.calls == 2 and c["net-count-A"][10.0] == a["net-count-A"][10.0]
    assert c["A"][100.0]["psnr"] > c["A"][10.0]["psnr"]  # the LMMSE: more light, better
