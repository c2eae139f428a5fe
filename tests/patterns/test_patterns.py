"""Looking patterns up by name (splitcam.patterns.get, splitcam.patterns.names)."""

from __future__ import annotations

import pytest
import torch

from splitcam import patterns
from splitcam.patterns import PatternError


def test_registry_names_and_case_insensitive_lookup():
    assert patterns.names() == [
        "A",
        "B",
        "C",
        "D",
        "E",
        "bayer",
        "rgbw",
        "quad",
        "xtrans",
        "router-zou",
        "router-best",
        "router-best-fullwave",
        "router-best-fullwave-f2",
        "router-best-n30-fullwave-f2",
        "router-best-n300-fullwave-f2",
        "router-zou-fullwave",
        "router-zou-fullwave-f2",
        "bayer-d5100",
        "rgbw-d5100",
        "bayer-sdmerrill",
        "rgbw-sdmerrill",
    ]
    assert patterns.get("d").name == "D"
    assert patterns.get("BAYER").name == "bayer"
    with pytest.raises(PatternError, match="unknown pattern 'F'; valid names: A, B, C, D, E, bay"):
        patterns.get("F")


def test_get_reads_through_its_tables_and_a_new_parser_is_one_entry(monkeypatch):
    """Built-in names come from NAMES, other text from PARSERS in order; a syntax added to the
    table is read by get and named in its error message."""
    assert set(patterns.NAMES) == {n.lower() for n in patterns.names()}
    assert patterns.get("router(eta=0.5;chi=0)").equals(patterns.router(0.5, 0.0))

    def grey(text: str):
        if not text.startswith("grey:"):
            return None
        return patterns.router(float(text.removeprefix("grey:")), 0.0, name="grey")

    monkeypatch.setitem(patterns.PARSERS, "grey:ETA", grey)
    assert patterns.get("grey:0.7").equals(patterns.router(0.7, 0.0))
    assert patterns.get("D").name == "D"  # names still come first
    with pytest.raises(PatternError, match=r"or grey:ETA\)$"):
        patterns.get("nothing")


def test_builtin_reads_library_names_only():
    assert patterns.builtin("Bayer").equals(patterns.get("bayer"))
    with pytest.raises(PatternError, match="unknown pattern 'router\\(eta=0.5\\)'"):
        patterns.builtin("router(eta=0.5)")


def test_library_functions_take_patterns_and_say_how_to_read_a_name(tmp_path):
    """Names are read once, where a user hands them over: a function below that is given a
    name refuses it with a TypeError naming patterns.get; constructors still read names."""
    from splitcam.design import design_pattern
    from splitcam.evaluation.exposure import exposure_study
    from splitcam.physics.sensor import SplitterSensor, pattern_pixel_kernels
    from splitcam.recon.closed_form import ClosedFormFilters, closed_form_lmmse
    from splitcam.recon.lmmse import LMMSE, fit_lmmse

    images = [("grey", torch.full((3, 12, 12), 0.5))]
    calls = [
        lambda: design_pattern("D", steps=1),
        lambda: closed_form_lmmse("D"),
        lambda: pattern_pixel_kernels("D"),
        lambda: fit_lmmse("D", images[0][1][None]),
        lambda: exposure_study(images, patterns=["D"], photons=[10.0], progress=False),
    ]
    for call in calls:
        with pytest.raises(TypeError, match=r"splitcam.patterns.get\('D'\)"):
            call()
    d = patterns.get("D")
    assert SplitterSensor("D").to_pattern().equals(d)
    assert ClosedFormFilters("D").pattern.equals(d)
    assert LMMSE.fit("D", images[0][1][None].double(), radius=1).pattern.equals(d)
    path = patterns.save(d, tmp_path / "mine.toml")
    assert closed_form_lmmse(patterns.get(path)).pattern.equals(d)
