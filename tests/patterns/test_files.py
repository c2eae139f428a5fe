"""Pattern files (splitcam.patterns.files): TOML and JSON round trips and the files refused."""

from __future__ import annotations

import json

import pytest

from splitcam import patterns
from splitcam.patterns import PatternError


def _valid() -> dict:
    return patterns.get("D").to_dict()


@pytest.mark.parametrize("suffix", [".json", ".toml"])
@pytest.mark.parametrize("name", patterns.names())
def test_file_round_trip(tmp_path, name, suffix):
    p = patterns.get(name)
    path = patterns.save(p, tmp_path / f"p{suffix}")
    q = patterns.load(path)
    assert q.equals(p) and q.name == p.name and q.provenance == p.provenance
    assert q.description == p.description and q.reference == p.reference
    assert patterns.get(str(path)).equals(p)


def test_toml_written_by_hand(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(
        'name = "stripe"\nlayout = [[0, 1]]\n'
        "[[kernels]]\nR = [[0, 1, 0]]\nG = [[0, 1, 0]]\nB = [[0, 1, 0]]\n"
        "[[kernels]]\nR = [[1, 0, 0]]\nG = [[0, 1, 0]]\nB = [[0, 0.5, 0]]\n"
    )
    p = patterns.load(path)
    assert p.period == (1, 2) and p.num_splitters == 2 and p.absorbs_light
    assert p.kernels[1, 0, 0].tolist() == [1, 0, 0]


def test_file_errors(tmp_path):
    with pytest.raises(PatternError, match="not found"):
        patterns.load(tmp_path / "missing.json")
    with pytest.raises(PatternError, match="expected a .json or .toml file, got '.yaml'"):
        patterns.load(tmp_path / "p.yaml")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(PatternError, match="is not valid json"):
        patterns.load(bad)
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text("name = \n")
    with pytest.raises(PatternError, match="is not valid toml"):
        patterns.load(bad_toml)
    invalid = tmp_path / "invalid.json"
    data = _valid()
    data["layout"] = [[0, 9], [2, 3]]
    invalid.write_text(json.dumps(data))
    with pytest.raises(PatternError, match="invalid.json.*layout index 9"):
        patterns.get(str(invalid))
