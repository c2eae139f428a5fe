"""The break-even map of routers against a filter array (splitcam.evaluation.breakeven)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from splitcam import patterns

PHOTONS = [3.0, 300.0]


@pytest.fixture(scope="module")
def tiny() -> list:
    """One small smooth colour image (fast)."""
    y, x = torch.meshgrid(torch.linspace(0, 1, 16), torch.linspace(0, 1, 16), indexing="ij")
    return [("ramp", torch.stack([0.2 + 0.6 * x, 0.3 + 0.4 * y, 0.8 - 0.5 * x * y]))]


def test_verdict_on_synthetic_curves() -> None:
    from splitcam.evaluation.breakeven import verdict

    n = [1.0, 10.0, 100.0, 1000.0]
    assert verdict(n, [0.0, 0.0, 0.0, 0.0])["verdict"] == "tie"
    assert verdict(n, [1.0, 0.5, 0.2, 0.1]) == {
        "verdict": "always",
        "break_even": None,
        "crossings": [],
    }
    assert verdict(n, [-1.0, -0.5, 0.0, -0.1])["verdict"] == "never"
    below = verdict(n, [2.0, 1.0, -1.0, -2.0])
    assert below["verdict"] == "below" and below["break_even"] == pytest.approx(10**1.5)
    above = verdict(n, [-2.0, -1.0, 1.0, 2.0])
    assert above["verdict"] == "above" and above["crossings"][0][1] == "up"
    mixed = verdict(n, [1.0, -1.0, 1.0, -1.0])
    assert mixed["verdict"] == "mixed" and mixed["break_even"] == pytest.approx(10**2.5)
    # a small wobble inside the tolerance is no crossing
    assert verdict(n, [0.01, -0.01, 0.5, 0.4], tol=0.05)["verdict"] == "always"


def test_a_router_with_rgbw_light_and_kernels_ties_rgbw(tiny) -> None:
    from splitcam import patterns
    from splitcam.evaluation.breakeven import break_even

    result = break_even(
        tiny,
        etas=[0.5, 1.0],
        chis=[0.0],
        photons=PHOTONS,
        candidate=lambda e, x: patterns.get("rgbw"),
    )
    assert [c["verdict"] for c in result["cells"]] == ["tie", "tie"]
    assert all(d == 0.0 for c in result["cells"] for d in c["difference"])
    assert result["reference"] == "rgbw" and result["photons"] == PHOTONS


def test_a_router_better_everywhere_reports_always_and_infeasible_cells(tiny) -> None:
    """router(1, 0) = A gathers more light with the same kernels' shape than the dim
    router(0.3, 0): better at every exposure; eta + chi > 1 is never simulated."""
    from splitcam import patterns
    from splitcam.evaluation.breakeven import break_even

    result = break_even(
        tiny,
        etas=[1.0],
        chis=[0.0, 0.2],
        photons=PHOTONS,
        reference=patterns.router(0.3, 0.0),
    )
    better, impossible = result["cells"]
    assert better["verdict"] == "always" and min(better["difference"]) > 0
    assert impossible["verdict"] == "infeasible" and impossible["difference"] is None
    # the opposite way round, lower-is-better metric: never better
    worse = break_even(
        tiny,
        etas=[0.3],
        chis=[0.0],
        photons=PHOTONS,
        reference=patterns.get("A"),
        metric="ciede2000",
    )["cells"][0]
    assert worse["verdict"] == "never"


def test_router_one_zero_is_a_and_never_creates_light() -> None:
    from splitcam import patterns

    a = patterns.get("A")
    assert np.array_equal(patterns.router(1.0, 0.0).kernels, a.kernels)
    for eta in np.linspace(0.3, 1.0, 4):
        for chi in np.linspace(0.0, 0.35, 4):
            if eta + chi > 1:
                with pytest.raises(patterns.PatternError):
                    patterns.router(eta, chi)
                continue
            k = patterns.router(eta, chi).kernels  # (splitter, colour, kh, kw)
            assert k.min() >= 0
            # every splitter sends on eta + chi of each colour's light: lost, never created
            assert np.allclose(k.sum(axis=(2, 3)), eta + chi)
            assert np.all(k.sum(axis=(2, 3)) <= 1 + 1e-12)


def test_presets_are_read_from_the_library() -> None:
    from splitcam import patterns
    from splitcam.evaluation.breakeven import preset_points

    points = preset_points()
    for name, (eta, chi) in points.items():
        meta = patterns.get(name).metadata
        assert eta == pytest.approx(np.mean(meta["eta"]))
        assert chi == pytest.approx(np.mean(meta["chi"]))
        assert 0 < eta < 1 and 0 < chi < 1 and eta + chi <= 1


def test_write_break_even(tmp_path, tiny) -> None:
    import json

    from splitcam.evaluation.breakeven import break_even, write_break_even

    result = break_even(tiny, etas=[0.5, 1.0], chis=[0.0, 0.6], photons=PHOTONS)
    path = write_break_even(result, tmp_path, note="note")
    text = path.read_text()
    assert "| 0.5 |" in text and "router-zou" in text
    assert (tmp_path / "breakeven.png").stat().st_size > 1000
    data = json.loads((tmp_path / "breakeven.json").read_text())
    assert len(data["cells"]) == 4 and "router-best" in data["presets"]


def test_cell_text() -> None:
    from splitcam.viz.breakeven import cell_text

    window = {"verdict": "mixed", "crossings": [[1.4, "down"], [5.1, "up"], [68.0, "down"]]}
    assert cell_text({**window, "break_even": 68.0}) == "5.1–68"
    assert cell_text({"verdict": "below", "break_even": 1234.0}) == "<1200"  # not 1.2e3
    assert cell_text({"verdict": "below", "break_even": 23456.0}) == "<2.3e4"
    assert cell_text({"verdict": "above", "break_even": 40.0}) == ">40"
    assert cell_text({"verdict": "infeasible", "break_even": None}) == ""


def test_the_map_with_a_method_reconstructs_every_sensor_with_it(tiny) -> None:
    """`method` replaces the LMMSE for the reference and every router: the LMMSE passed as a
    method (under another name) gives the default map exactly; a method that ignores the raw
    image makes every router tie."""
    from splitcam.evaluation.breakeven import break_even
    from splitcam.recon.closed_form import closed_form_lmmse

    grid = {"etas": [0.5, 1.0], "chis": [0.0, 0.25], "photons": PHOTONS}
    default = break_even(tiny, **grid)
    same = break_even(
        tiny, **grid, method=lambda p: closed_form_lmmse(p, domain="linear", name=f"x-{p.name}")
    )
    assert same["method"] == "x" and default["method"] == "closed-form LMMSE"
    assert [c["difference"] for c in same["cells"]] == [c["difference"] for c in default["cells"]]

    class Grey:
        domain = "linear"

        def __init__(self, pattern) -> None:
            self.pattern, self.name = pattern, f"grey-{pattern.name}"

        def reconstruct(self, raw, level):
            return torch.full((raw.shape[0], 3, *raw.shape[-2:]), 0.5)

    blind = break_even(tiny, **grid, method=Grey)
    feasible = [c for c in blind["cells"] if c["verdict"] != "infeasible"]
    assert feasible and all(c["verdict"] == "tie" for c in feasible)


def test_the_map_against_another_reference_equals_computing_it_again(tiny) -> None:
    """``against`` reconstructs only the new reference; the map must be the one a full pass
    against that reference computes (an independent computation of every router's curve)."""
    from splitcam.evaluation.breakeven import against, break_even

    grid = {"etas": [0.5, 0.9], "chis": [0.0, 0.2], "photons": PHOTONS, "tol": 0.01}
    first = break_even(tiny, reference=patterns.get("rgbw"), **grid)
    direct = break_even(tiny, reference=patterns.get("bayer-d5100"), **grid)
    rebased = against(first, patterns.get("bayer-d5100"), tiny)
    assert rebased["reference"] == "bayer-d5100"
    assert rebased["reference_curve"] == pytest.approx(direct["reference_curve"], abs=1e-9)
    for mine, theirs in zip(rebased["cells"], direct["cells"], strict=True):
        assert (mine["eta"], mine["chi"], mine["verdict"]) == (
            theirs["eta"],
            theirs["chi"],
            theirs["verdict"],
        )
        if theirs["difference"] is None:
            assert mine["difference"] is None
        else:
            assert mine["difference"] == pytest.approx(theirs["difference"], abs=1e-9)
            # the per-image differences, and so the intervals over images, too
            assert np.allclose(mine["difference_images"], theirs["difference_images"], atol=1e-9)
            assert (mine["interval"] is None) == (theirs["interval"] is None)
            if theirs["interval"] is not None:
                assert mine["interval"] == pytest.approx(theirs["interval"], rel=1e-6)
    # One image: every resample is that image, so the interval is the crossing itself.
    below = [c for m in (first, direct) for c in m["cells"] if c["verdict"] == "below"]
    assert below
    for c in below:
        assert c["interval"] == pytest.approx([c["break_even"]] * 2)
    # back against the first reference: the first map again
    again = against(rebased, patterns.get("rgbw"), tiny)
    assert [c["verdict"] for c in again["cells"]] == [c["verdict"] for c in first["cells"]]


def test_several_references_each_get_a_map(tmp_path, tiny, monkeypatch) -> None:
    from splitcam.cli import main

    folder = tmp_path / "photos"
    folder.mkdir()
    from PIL import Image

    Image.fromarray((tiny[0][1].permute(1, 2, 0).numpy() * 255).astype(np.uint8)).save(
        folder / "ramp.png"
    )
    code = main(
        [
            "study",
            "breakeven",
            "--datasets",
            str(folder),
            "--eta",
            "0.6",
            "1",
            "--chi",
            "0",
            "--photons",
            "3",
            "300",
            "--reference",
            "rgbw,rgbw-d5100",
            "--quiet",
            "--out",
            str(tmp_path / "map"),
        ]
    )
    assert code == 0
    for name in ("rgbw", "rgbw-d5100"):
        data = json.loads((tmp_path / "map" / name / "breakeven.json").read_text())
        assert data["reference"] == name and (tmp_path / "map" / name / "breakeven.png").is_file()
