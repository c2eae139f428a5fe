"""studies/fullwave/stack_scan.py: a variant names changes to a design run's stack, and a
stopped scan continues without solving a variant twice."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import load_script

STUDY = Path(__file__).resolve().parents[2] / "studies" / "fullwave" / "stack_scan.py"
BASE = {"stack": [1.0, 0.699, 2.8, "Si3N4", "vacuum", "SiO2"], "terms": 357}


def _study():
    return load_script(STUDY, "stack_scan_study")


def test_a_variant_changes_only_what_it_names():
    study = _study()
    changes = study.parse_variant("pillar=2.4, thickness=0.51")
    assert changes == {"pillar": 2.4, "thickness": 0.51}
    assert study.settings_of(BASE, changes) == {
        "stack": [1.0, 0.51, 2.8, 2.4, "vacuum", "SiO2"],
        "terms": 357,
    }
    assert BASE["stack"][1] == 0.699  # the base is not changed in place
    assert study.parse_variant("pillar=Si3N4") == {"pillar": "Si3N4"}
    assert study.parse_variant("") == {}
    assert study._label(study.parse_variant("depth=2.0,pillar=2.6")) == "depth=2,pillar=2.6"


@pytest.mark.parametrize("text", ["thickness", "height=0.5", "depth=deep"])
def test_a_variant_that_names_nothing_of_the_stack_is_refused(text):
    with pytest.raises(ValueError, match="variant part"):
        _study().parse_variant(text)


def test_every_part_s_rows_are_read_once_and_tabled_against_the_leaderboard_stack(
    tmp_path, monkeypatch
):
    study = _study()
    monkeypatch.setattr(study, "OUT", tmp_path)

    def row(variant, psnr30):
        psnr = {f"{n:g}": psnr30 + n / 1000 for n in study.EXPOSURES}
        eff = {"blue": 0.5, "green": 0.5, "red": 0.4}
        return json.dumps({"variant": variant, "psnr": psnr, "efficiency": eff, "reflection": 0.03})

    (tmp_path / "scan-1of2.jsonl").write_text(row("", 20.0) + "\n" + row("depth=2", 20.5) + "\n")
    (tmp_path / "scan-2of2.jsonl").write_text(row("depth=2", 99.0) + "\n" + '{"variant": "de')
    found = study.rows()
    assert sorted(r["variant"] for r in found) == ["", "depth=2"]
    text = study.table(found)
    assert "| depth=2 |" in text and "20.53 (+0.50)" in text
    assert text.splitlines()[2].startswith("| leaderboard")
