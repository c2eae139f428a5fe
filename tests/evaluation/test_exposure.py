"""The exposure study (splitcam.evaluation.exposure): crossovers and the raw SNR check."""

from __future__ import annotations

import math

import pytest
import torch

from splitcam import patterns


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
    snr = raw_snr_check(grey, patterns=[patterns.get(n) for n in ("A", "D", "bayer")])
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


def _scored(per: dict, names: list[str]) -> dict:
    """An exposure study's result from per-image PSNRs ``{N: values}`` (CIEDE2000 taken as
    40 − PSNR, SSIM 0.5): the means and the per-image scores, as exposure_study returns them."""
    import numpy as np

    out = {}
    for n, v in per.items():
        v = np.asarray(v, dtype=float)
        out[n] = {
            "psnr": float(v.mean()),
            "ssim": 0.5,
            "ciede2000": float((40 - v).mean()),
            "per_image": {
                "psnr": v.tolist(),
                "ssim": [0.5] * len(v),
                "ciede2000": (40 - v).tolist(),
            },
            "images": names,
        }
    return out


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
    assert row.count("N ≈ 320 ") == 2 and row.count("N ≈ 32 ") == 2
    quad = next(line for line in table if line.startswith("| quad |"))
    assert "never below; above N ≈ 32" in quad
    # a window: loses at the lowest exposure, wins between two crossings
    r["window"] = {n: {**v, "psnr": v["psnr"] + d} for (n, v), d in zip(
        r["rgbw"].items(), (-0.5, 1.0, 1.0, -1.0), strict=True)}  # fmt: skip
    text = write_study(r, None, tmp_path / "three", references=("rgbw",)).read_text()
    window = next(x for x in text.split("## Crossover")[1].splitlines() if "| window |" in x)
    assert "never below; between N ≈ 2.2 and 320" in window
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
    a_only = [patterns.get("A")]
    a = exposure_study(images, patterns=a_only, photons=[10.0], methods=[first], out=tmp_path,
                       progress=False)  # fmt: skip
    again = Counted()
    b = exposure_study(images, patterns=a_only, photons=[10.0], methods=[again], out=tmp_path,
                       progress=False)  # fmt: skip
    assert first.calls == 2 and again.calls == 0 and a == b
    more = Counted()
    c = exposure_study(images, patterns=a_only, photons=[10.0, 100.0], methods=[more],
                       out=tmp_path, progress=False)  # fmt: skip
    assert more.calls == 2 and c["net-count-A"][10.0] == a["net-count-A"][10.0]
    assert c["A"][100.0]["psnr"] > c["A"][10.0]["psnr"]  # the LMMSE: more light, better


def test_two_significant_figures_are_written_plainly() -> None:
    from splitcam.evaluation.exposure import two_figures

    assert [two_figures(v) for v in (242.0, 72.9, 1931.0, 3.16, 12345.0, 0.0456)] == [
        "240",
        "73",
        "1900",
        "3.2",
        "12000",
        "0.046",
    ]


def test_the_crossover_interval_is_the_bootstrap_of_the_images_shifts() -> None:
    """Difference curves linear in log exposure, one shift per image: the mean curve crosses at
    log10 N = 2 + mean(shift) / slope, so each resample's crossover follows from its mean shift
    alone. The interval must be the percentiles of those, computed here independently, with
    the same resamples."""
    import numpy as np

    from splitcam.evaluation.exposure import crossover_interval

    photons = [1.0, 10.0, 100.0, 1000.0, 10000.0]
    logs = np.log10(photons)
    shifts = np.array([-0.6, -0.2, 0.1, 0.3, 0.5, 0.9, -0.4, 0.2])
    slope = 2.0  # dB per decade
    candidate = 30.0 + slope * (2.0 - logs)[None, :] + shifts[:, None]  # wins below ~100
    reference = np.full_like(candidate, 30.0)
    out = crossover_interval(candidate, reference, photons, draws=500, seed=7)
    assert out["crossover"] == pytest.approx(10 ** (2 + shifts.mean() / slope))
    picks = np.random.default_rng(7).integers(0, len(shifts), size=(500, len(shifts)))
    expected = 10 ** (2 + shifts[picks].mean(1) / slope)
    lo, hi = np.quantile(expected, [0.05, 0.95], method="inverted_cdf")
    assert out["low"] == pytest.approx(lo) and out["high"] == pytest.approx(hi)
    assert out["low"] < out["crossover"] < out["high"]
    assert out["never"] == 0.0 and out["everywhere"] == 0.0
    # Lower is better (CIEDE2000): the same answer from negated scores.
    flipped = crossover_interval(
        -candidate, -reference, photons, higher_is_better=False, draws=500, seed=7
    )
    assert flipped["low"] == pytest.approx(lo) and flipped["high"] == pytest.approx(hi)
    # Identical images: no spread.
    same = crossover_interval(candidate[:1].repeat(5, 0), reference[:5], photons)
    assert same["low"] == same["high"] == pytest.approx(same["crossover"])
    with pytest.raises(ValueError, match="per-image scores"):
        crossover_interval(candidate, reference[:, :3], photons)


def test_an_interval_that_reaches_past_the_exposures_studied_says_so() -> None:
    """Half the images always favour the candidate by far, half never: resamples that never
    win or win everywhere give the ends ``<1`` and ``>10000``, and their shares are kept."""
    import numpy as np

    from splitcam.evaluation.exposure import crossover_interval, interval_text

    photons = [1.0, 100.0, 10000.0]
    good = np.full((4, 3), 10.0)
    bad = np.full((4, 3), -10.0)
    out = crossover_interval(np.vstack([good, bad]), np.zeros((8, 3)), photons, draws=400)
    assert 0.02 < out["never"] < 0.98 and 0.02 < out["everywhere"] < 0.98
    assert out["never"] + out["everywhere"] == pytest.approx(1.0)  # no resample crosses
    assert interval_text(out, photons) == "[<1, >10000]"


def test_a_study_writes_intervals_per_scene_set(tmp_path) -> None:
    """A study of two scene sets writes each crossover with its interval, pooled and per set,
    into exposure.md and exposure.json; the pooled crossover lies within its interval."""
    import json

    import numpy as np

    from splitcam.evaluation.exposure import write_study

    photons = [1.0, 10.0, 100.0, 1000.0]
    names = [f"kodak24/k{i}" for i in range(5)] + [f"mcmaster/m{i}" for i in range(4)]
    rng = np.random.default_rng(0)

    def result(offset, slope):
        return _scored(
            {n: offset + slope * math.log10(n) + rng.normal(0, 0.3, len(names)) for n in photons},
            names,
        )

    results = {"rgbw": result(10.0, 6.0), "router": result(13.0, 4.0)}
    text = write_study(results, None, tmp_path, references=("rgbw",)).read_text()
    assert "kodak24 only" in text and "mcmaster only" in text
    crossing = text.split("## Crossover")[1]
    row = next(ln for ln in crossing.splitlines() if ln.startswith("| router |"))
    assert row.count("[") == 2  # PSNR and CIEDE2000, each with its interval
    data = json.loads((tmp_path / "exposure.json").read_text())
    pooled = [c for c in data["crossovers"] if c["scene_set"] == "all" and c["metric"] == "psnr"]
    assert len(pooled) == 1 and pooled[0]["low"] <= pooled[0]["crossover"] <= pooled[0]["high"]
    assert pooled[0]["crossover"] == pytest.approx(10**1.5, rel=0.2)
    assert {c["scene_set"] for c in data["crossovers"]} == {"all", "kodak24", "mcmaster"}
    assert {c["images"] for c in data["crossovers"]} == {9, 5, 4}


def test_difference_curves_band_the_mean_and_the_chart_draws_them(tmp_path) -> None:
    """The band holds the mean difference at every exposure and closes when every image is
    the same; the crossover is the interval of :func:`crossover_interval`; CIEDE2000 is taken
    reference − candidate (positive: the candidate is better)."""
    import numpy as np

    from splitcam.evaluation.exposure import crossover_interval, difference_curves
    from splitcam.viz.charts import difference_chart

    photons = [1.0, 10.0, 100.0, 1000.0]
    names = [f"s/i{i}" for i in range(6)]
    rng = np.random.default_rng(1)

    def result(values):
        return _scored(dict(zip(photons, values.T, strict=True)), names)

    ref = 10 + 6 * np.log10(photons)[None, :] + rng.normal(0, 0.2, (6, 4))
    router = 12 + 5 * np.log10(photons)[None, :] + rng.normal(0, 0.4, (6, 4))
    flat = np.tile(router[:1], (6, 1))
    results = {
        "rgbw": result(ref),
        "router": result(router),
        "flat": result(flat),
        "flat-ref": result(np.tile(ref[:1], (6, 1))),
    }
    curves = difference_curves(results, [("router", "rgbw"), ("flat", "flat-ref")])
    c = curves[0]
    mean = np.array(c["mean"])
    assert np.allclose(mean, (router - ref).mean(0))
    assert np.all(np.array(c["low"]) <= mean) and np.all(mean <= np.array(c["high"]))
    assert c["crossover"] == crossover_interval(router, ref, photons)
    same = curves[1]
    assert same["low"] == pytest.approx(same["mean"]) and same["high"] == pytest.approx(
        same["mean"]
    )
    ciede = difference_curves(results, [("router", "rgbw")], metric="ciede2000")[0]
    assert np.allclose(ciede["mean"], mean)  # 40 − v: the same difference, the same sign
    path = difference_chart(curves, tmp_path / "d.png", title="test")
    assert path.stat().st_size > 10_000
    with pytest.raises(ValueError, match="per-image scores"):
        difference_curves({"a": {1.0: {"psnr": 1.0}}, "b": {1.0: {"psnr": 1.0}}}, [("a", "b")])


def test_the_crossovers_are_stated_in_lux_for_a_camera(tmp_path) -> None:
    """With a camera, each pooled crossover and its interval are also written in scene lux:
    N divided by the camera's photo-electrons per lux."""
    import json

    import numpy as np

    from splitcam.evaluation.exposure import two_figures, write_study
    from splitcam.physics.radiometry import Camera

    photons = [1.0, 10.0, 100.0, 1000.0]
    names = [f"s/i{i}" for i in range(6)]
    rng = np.random.default_rng(5)

    def result(offset, slope):
        return _scored(
            {n: offset + slope * math.log10(n) + rng.normal(0, 0.3, 6) for n in photons}, names
        )

    camera = Camera(pitch_um=0.8, f_number=1.4, exposure_s=1 / 60, illuminant="A")
    results = {"rgbw": result(10.0, 6.0), "router": result(13.0, 4.0)}
    text = write_study(results, None, tmp_path, references=("rgbw",), camera=camera).read_text()
    assert "## The crossovers in lux (pitch 0.8 µm, f/1.4, 1/60 s, A, white scene" in text
    data = json.loads((tmp_path / "exposure.json").read_text())
    pooled = next(
        c for c in data["crossovers"] if c["scene_set"] == "all" and c["metric"] == "psnr"
    )
    assert pooled["lux"][0] == pytest.approx(pooled["crossover"] / camera.electrons_per_lux)
    assert f"{two_figures(pooled['lux'][0])} lux [" in text
    assert data["camera"]["electrons_per_lux"] == pytest.approx(camera.electrons_per_lux)


def test_a_candidate_that_always_wins_gets_a_share_not_an_interval(tmp_path) -> None:
    from splitcam.evaluation.exposure import write_study

    photons = [1.0, 10.0, 100.0]
    names = ["s/a", "s/b", "s/c"]

    def result(v):
        return _scored({n: [v] * 3 for n in photons}, names)

    text = write_study(
        {"rgbw": result(10.0), "A": result(12.0)}, None, tmp_path, references=("rgbw",)
    ).read_text()
    row = next(ln for ln in text.split("## Crossover")[1].splitlines() if ln.startswith("| A |"))
    assert row.count("every exposure studied (in 100% of resamples)") == 2 and "[" not in row
