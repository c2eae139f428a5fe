"""Nothing a user owns is lost, across commands: outputs never replace inputs or each other, a
full disk damages nothing, flags without effect are refused."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import blocky_images
from PIL import Image

from splitcam.cli import main


def _unchanged(path, arr) -> bool:
    with Image.open(path) as im:
        return np.array_equal(np.asarray(im), arr)


@pytest.mark.parametrize(
    "argv",
    [
        [
            "reconstruct",
            "--method",
            "lmmse",
            "--pattern",
            "D",
            "--image",
            "{photo}",
            "--out",
            "{photo}",
        ],
        ["simulate", "{photo}", "--out", "{photo}"],
        ["simulate", "{photo}", "--out", "{dir}/raw.png", "--preview", "{photo}"],
    ],
)
def test_an_output_never_replaces_an_input(argv, photo, tmp_path, capsys):
    path, arr = photo
    argv = [a.format(photo=path, dir=tmp_path) for a in argv]
    assert main(argv) == 1
    assert "would be overwritten" in capsys.readouterr().err
    assert _unchanged(path, arr)


def test_two_outputs_are_two_files(photo, tmp_path, capsys):
    path, _ = photo
    raw = tmp_path / "raw.png"
    assert main(["simulate", str(path), "--out", str(raw), "--preview", str(raw)]) == 1
    assert "name the same file" in capsys.readouterr().err
    assert not raw.exists()
    # The same file by another path counts too.
    other = tmp_path / "sub" / ".." / "raw.png"
    (tmp_path / "sub").mkdir()
    assert main(["simulate", str(path), "--out", str(raw), "--preview", str(other)]) == 1


def _full_disk(monkeypatch, after: int = 10):
    """Every file write fails with ENOSPC after ``after`` bytes (a disk that fills mid-write)."""
    import builtins
    import errno
    import io as stdio

    real_open = builtins.open

    def fake_open(file, mode="r", *args, **kwargs):
        handle = real_open(file, mode, *args, **kwargs)
        if "w" in mode or "a" in mode:
            write = handle.write

            def limited(data, _write=write):
                if len(data) > after:
                    _write(data[:after])
                    raise OSError(errno.ENOSPC, "No space left on device")
                return _write(data)

            handle.write = limited
        return handle

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(stdio, "open", fake_open)  # what pathlib's write_bytes/write_text use


def test_a_full_disk_damages_nothing_and_names_the_file(photo, tmp_path, monkeypatch, capsys):
    from splitcam.io import stale_temporaries

    path, arr = photo
    out = tmp_path / "rec.png"
    args = ["reconstruct", "--method", "lmmse", "--pattern", "D", "--image", str(path)]
    assert main([*args, "--out", str(out), "--quiet"]) == 0
    before = out.read_bytes()
    _full_disk(monkeypatch)
    assert main([*args, "--sigma", "10", "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(out) in err[0] and "No space left" in err[0]
    assert out.read_bytes() == before  # the earlier output is intact
    assert not stale_temporaries(tmp_path)
    # A pattern file and a raw file likewise.
    from splitcam import patterns

    toml = tmp_path / "d.toml"
    monkeypatch.undo()
    patterns.save(patterns.get("D"), toml)
    text = toml.read_text()
    _full_disk(monkeypatch)
    with pytest.raises(OSError, match="d.toml"):
        patterns.save(patterns.get("A"), toml)
    assert toml.read_text() == text
    assert _unchanged(path, arr)


def test_training_on_a_full_disk_fails_in_one_line(tmp_path, monkeypatch, capsys):
    data = blocky_images(tmp_path / "img", 5)
    args = ["train", "--data", str(data), "--patch-size", "16", "--batch-size", "2"]
    args += ["--features", "4", "--blocks", "1", "--val-split", "1", "--steps", "4"]
    args += ["--threads", "1", "--out", str(tmp_path / "run"), "--quiet"]
    _full_disk(monkeypatch, after=5)
    assert main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left" in err[0] and str(tmp_path / "run") in err[0]


def test_flags_without_effect_are_refused(tmp_path, capsys):
    data = blocky_images(tmp_path / "img", 3)
    assert main(["train", "--data", str(data), "--photons", "10", "100", "--steps", "1"]) == 1
    assert "--photons: settings of the photon model; add --noise photon" in capsys.readouterr().err
    ev = ["evaluate", "--method", "lmmse", "--patterns", "D", "--datasets", str(data)]
    assert main([*ev, "--read-noise", "3", "--out", str(tmp_path / "e")]) == 1
    assert "no effect without --photons" in capsys.readouterr().err
    assert main(["study", "exposure", "--points", "0", "--datasets", str(data)]) == 1
    assert "--points must be at least 1" in capsys.readouterr().err
