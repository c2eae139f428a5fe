"""Looking patterns up by name (splitcam.patterns.get, splitcam.patterns.names)."""

from __future__ import annotations

import pytest

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
