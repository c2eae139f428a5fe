"""``splitcam data``: download a test set from a local mirror and list what is present."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from splitcam.data import registry


def test_cli_download_and_list(
    shared_data: Path, serve, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    server = serve(shared_data)
    from splitcam.cli import build_parser

    parser = build_parser()
    # Pre-populate all but one file so the command downloads one and verifies the rest.
    folder = tmp_path / "mcmaster"
    folder.mkdir()
    for entry in registry.datasets()["mcmaster"].files[1:]:
        (folder / entry.name).symlink_to(shared_data / "mcmaster" / entry.name)
    args = parser.parse_args(
        ["data", "download", "mcmaster", "--to", str(tmp_path), "--mirror", server.url, "--quiet"]
    )
    assert args.handler(args) == 0
    assert server.log == ["/mcmaster/01.png"]
    assert (folder / "01.png").read_bytes() == (shared_data / "mcmaster" / "01.png").read_bytes()
    assert f"mcmaster: 18 images in {folder}" in capsys.readouterr().out

    args = parser.parse_args(["data", "list", "--root", str(tmp_path)])
    assert args.handler(args) == 0
    out = capsys.readouterr().out
    assert re.search(r"mcmaster\s+complete", out)
    assert re.search(r"kodak24\s+not downloaded", out)


def test_data_list_checks_content_not_only_names(tmp_path, capsys) -> None:
    """A dataset with a damaged file is not 'complete' (it once was: only names were counted)."""
    from splitcam.data.download import dataset_state

    files = registry.datasets()["mcmaster"].files
    folder = tmp_path / "mcmaster"
    folder.mkdir()
    assert dataset_state(folder, files) == "not downloaded"
    for entry in files[:3]:
        (folder / entry.name).write_bytes(b"not the image")
    assert dataset_state(folder, files) == f"3/{len(files)} files, 3 damaged"
