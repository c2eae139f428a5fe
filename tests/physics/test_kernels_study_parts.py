"""studies/fullwave/kernels.py shares its solving between processes (``--part K/N``): each part
solves its own wavelengths into its own file, and the whole run takes their lines in."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import load_script

STUDY = Path(__file__).resolve().parents[2] / "studies" / "fullwave" / "kernels.py"


def _study():
    return load_script(STUDY, "kernels_study")


def test_the_parts_solves_are_taken_in_once_after_a_line_cut_short(tmp_path):
    study = _study()
    rows = [json.dumps({"wavelength": w, "n": i}) for i, w in enumerate((410, 430, 450, 470))]
    (tmp_path / "solves.jsonl").write_text(rows[0] + "\n" + '{"wavelength": 4')  # cut short
    (tmp_path / "solves-1of2.jsonl").write_text(rows[1] + "\n" + rows[0] + "\n")
    (tmp_path / "solves-2of2.jsonl").write_text(rows[2] + "\n" + rows[3] + "\n")
    study._take_parts(tmp_path)
    lines = (tmp_path / "solves.jsonl").read_text().splitlines()
    assert lines == [rows[0], '{"wavelength": 4', rows[1], rows[2], rows[3]]
    assert not list(tmp_path.glob("solves-*"))  # taken in: a second run adds nothing
    study._take_parts(tmp_path)
    assert (tmp_path / "solves.jsonl").read_text().splitlines() == lines


def test_a_part_splits_the_wavelengths_and_a_bad_one_is_refused(tmp_path, monkeypatch):
    study = _study()
    asked = []
    monkeypatch.setattr(
        study,
        "pixel_kernels",
        lambda design, lams, **kw: asked.append((list(lams), kw["cache"].name)),
    )
    for part in ("1/3", "2/3", "3/3"):
        monkeypatch.setattr(
            "sys.argv", ["kernels.py", "--designs", "best", "--part", part, "--out", str(tmp_path)]
        )
        study.main()
    solved = sorted(w for lams, _ in asked for w in lams)
    assert solved == study.WAVELENGTHS  # each wavelength by one part
    assert [name for _, name in asked] == [f"solves-{k}of3.jsonl" for k in (1, 2, 3)]
    assert not (tmp_path / "kernels.md").exists()  # a part writes nothing else
    for bad in ("0/2", "3/2", "half"):
        monkeypatch.setattr("sys.argv", ["kernels.py", "--part", bad, "--out", str(tmp_path)])
        with pytest.raises(SystemExit, match="K/N"):
            study.main()
