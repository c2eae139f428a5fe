"""``splitcam patterns``: the table, ``show`` and ``export``, shipped models' learned patterns
included."""

from __future__ import annotations

import numpy as np
from PIL import Image

from splitcam import patterns
from splitcam.cli import main


def test_patterns_table_lists_every_pattern(capsys):
    assert main(["patterns"]) == 0
    out = capsys.readouterr().out
    for name in patterns.names():
        assert f"| {name} " in out
    assert "yes, 4-pixel unit" in out and "0.25/0.50/0.25" in out
    # Names without an action list those (it was an argparse error).
    assert main(["patterns", "D", "bayer-d5100"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert [r.split("|")[1].strip() for r in rows[1:]] == ["D", "bayer-d5100"]
    assert main(["patterns", "list", "E"]) == 0 and "| E " in capsys.readouterr().out


def test_patterns_show_and_export(tmp_path, capsys):
    png = tmp_path / "d.png"
    assert main(["patterns", "show", "D", "--out", str(png)]) == 0
    with Image.open(png) as im:
        assert im.size[0] > 300 and im.size[1] > 200
    toml = tmp_path / "d.toml"
    assert main(["patterns", "export", "d", "--out", str(toml)]) == 0
    assert patterns.load(toml).equals(patterns.get("D"))
    assert main(["patterns", "show", str(toml), "--out", str(tmp_path / "e.png")]) == 0


def test_exporting_again_never_undoes_a_users_edits(tmp_path, capsys):
    """An exported pattern file is there to be edited: exporting over it again is refused in
    one line (the edits kept) unless --force; over the same pattern it is a no-op."""
    toml = tmp_path / "mine.toml"
    assert main(["patterns", "export", "D", "--out", str(toml)]) == 0
    assert main(["patterns", "export", "D", "--out", str(toml)]) == 0
    assert "already holds this pattern" in capsys.readouterr().out
    edited = toml.read_text().replace('name = "D"', 'name = "mine"')
    assert edited != toml.read_text()
    toml.write_text(edited)
    assert main(["patterns", "export", "B", "--out", str(toml)]) == 1
    assert "--force replaces it" in capsys.readouterr().err
    assert toml.read_text() == edited
    assert main(["patterns", "export", "B", "--out", str(toml), "--force"]) == 0
    assert patterns.load(toml).equals(patterns.get("B"))


def test_patterns_show_a_shipped_models_learned_pattern(tmp_path):
    from splitcam import patterns
    from splitcam.recon.loading import load_model

    out = tmp_path / "a.png"
    assert main(["patterns", "show", "A-opt", "--out", str(out)]) == 0
    assert out.stat().st_size > 1000
    assert main(["patterns", "export", "A-opt", "--out", str(tmp_path / "a.toml")]) == 0
    learned = load_model("A-opt").pattern
    assert np.allclose(patterns.load(tmp_path / "a.toml").kernels, learned.kernels)
