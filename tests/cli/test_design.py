"""``splitcam design``: the pattern file and figure it writes, and the outputs it refuses."""

from __future__ import annotations

import numpy as np
import pytest

from splitcam import patterns
from splitcam.cli import main
from splitcam.design import closed_form_psnr, design_pattern


def _assert_valid(pattern: patterns.Pattern, start: patterns.Pattern) -> None:
    """A light-conserving splitter of the start's layout and kernel size."""
    assert np.array_equal(pattern.layout, start.layout)
    assert pattern.kernels.shape == start.kernels.shape
    assert np.all(pattern.kernels >= 0)
    np.testing.assert_allclose(pattern.kernels.sum(axis=(2, 3)), 1.0, rtol=0, atol=1e-12)
    assert not pattern.absorbs_light


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_cli_writes_a_pattern_file_that_round_trips_and_a_figure(tmp_path, capsys, suffix) -> None:
    from PIL import Image

    out = tmp_path / "sub" / f"designed{suffix}"
    args = ["--pattern", "D", "--init", "random", "--seed", "2", "--sigmas", "0", "10"]
    assert main(["design", *args, "--steps", "20", "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    loaded = patterns.get(out)
    _assert_valid(loaded, patterns.get("D"))
    assert loaded.name == "D-designed" and loaded.provenance == "designed"
    assert loaded.metadata["init"] == "random" and loaded.metadata["sigmas"] == [0.0, 10.0]
    # The file holds exactly what the library designs with the same settings.
    result = design_pattern(patterns.get("D"), init="random", seed=2, sigmas=[0, 10], steps=20)
    assert loaded.equals(result.pattern)  # bit-exact
    # The printed table is the closed-form PSNR before/after per sigma.
    rows = {
        line.split("|")[1].strip(): line.split("|")[2:5]
        for line in text.splitlines()
        if line.startswith("| ") and "sigma" not in line
    }
    assert set(rows) == {"0", "10"}
    for s in (0.0, 10.0):
        start_db, designed_db, gain = (float(v) for v in rows[f"{s:g}"])
        assert start_db == pytest.approx(result.psnr_before[s], abs=0.006)
        assert designed_db == pytest.approx(float(closed_form_psnr(loaded, [s])[0]), abs=0.006)
        assert gain == pytest.approx(designed_db - start_db, abs=0.011)
    # The figure: the start and the designed pattern side by side, so about twice as wide as
    # one drawing, and the two halves differ.
    image = np.asarray(Image.open(out.with_suffix(".png")).convert("RGB"))
    assert image.shape[1] > 1.8 * image.shape[0]
    width = (image.shape[1] - 24) // 2  # two drawings of the same size, a 24-pixel gap
    left, right = image[:, :width], image[:, -width:]
    assert (left < 250).any(axis=-1).mean() > 0.05 and (right < 250).any(axis=-1).mean() > 0.05
    assert (left != right).any(axis=-1).mean() > 0.01


def test_cli_refuses_an_output_that_is_not_a_pattern_file(tmp_path, capsys) -> None:
    assert main(["design", "--out", str(tmp_path / "x.png"), "--steps", "1", "--quiet"]) == 1
    assert ".toml or .json" in capsys.readouterr().err
    assert main(["design", "--pattern", "bayer", "--out", str(tmp_path / "b.toml"), "--quiet"]) == 1
    assert "absorbs light" in capsys.readouterr().err
    assert not (tmp_path / "b.toml").exists()


def test_design_to_a_read_only_folder_is_refused_before_designing(tmp_path, capsys, monkeypatch):
    import os

    from splitcam import design

    if os.geteuid() == 0:
        # root writes anywhere: a file where the folder should be stands in for no permission
        blocked = tmp_path / "blocked"
        blocked.write_text("")
        out = blocked / "d.toml"
    else:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        out = locked / "d.toml"
    monkeypatch.setattr(design, "design_pattern", lambda *a, **k: pytest.fail("designed first"))
    assert main(["design", "--pattern", "D", "--out", str(out), "--quiet"]) == 1
    assert "cannot write there" in capsys.readouterr().err
