"""The test-set registry (splitcam.data.registry): every file with its hashes, the parser, and
importing it without numpy or torch."""

from __future__ import annotations

import csv
import hashlib
import importlib.resources
import re
from pathlib import Path

import pytest
from conftest import fresh_modules

import splitcam.data.download as downloading
from splitcam.data import registry, testsets


def _git_blob(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def _entry(dataset: str, name: str) -> registry.DatasetFile:
    return next(f for f in registry.datasets()[dataset].files if f.name == name)


def _registry_rows() -> list[dict[str, str]]:
    """The rows of the shipped registry file, read without the module's parser."""
    text = importlib.resources.files("splitcam.data").joinpath("registry.tsv").read_text()
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    return list(csv.DictReader(lines, delimiter="\t"))


def test_registry_lists_every_file_with_well_formed_hashes() -> None:
    rows = _registry_rows()
    assert list(rows[0]) == [
        "dataset",
        "file",
        "source_path",
        "sha256",
        "git_blob",
        "pixels_sha256",
    ]
    kodak = [row for row in rows if row["dataset"] == "kodak24"]
    mcmaster = [row for row in rows if row["dataset"] == "mcmaster"]
    train = [row for row in rows if row["dataset"] == "train"]
    assert len(kodak) + len(mcmaster) + len(train) == len(rows)
    assert len(train) == 432 and all(r["file"].endswith(".jpg") for r in train)
    assert all(
        r["source_path"] == f"BSR/BSDS500/data/images/{split}/{r['file']}"
        for r in train
        for split in [r["source_path"].split("/")[-2]]
    )
    assert {r["source_path"].split("/")[-2] for r in train} == {"train", "test", "val"}
    assert all(row["pixels_sha256"] == "-" for row in train)
    assert [row["file"] for row in kodak] == [f"kodim{i:02d}.png" for i in range(1, 25)]
    assert [row["source_path"] for row in kodak] == [
        f"testsets/Set24/kodim{i:02d}.png" for i in range(1, 25)
    ]
    assert [row["file"] for row in mcmaster] == [f"{i:02d}.png" for i in range(1, 19)]
    assert [row["source_path"] for row in mcmaster] == [
        f"testsets/McMaster/{i}.tif" for i in range(1, 19)
    ]
    for row in rows:
        assert re.fullmatch(r"[0-9a-f]{64}", row["sha256"]), row
        assert re.fullmatch(r"[0-9a-f]{40}", row["git_blob"]), row
    assert all(row["pixels_sha256"] == "-" for row in kodak)
    assert all(re.fullmatch(r"[0-9a-f]{64}", row["pixels_sha256"]) for row in mcmaster)
    for column in ("sha256", "git_blob"):
        assert len({row[column] for row in rows}) == len(rows), column

    # The module serves exactly these rows, and keeps no hashes of its own.
    assert registry.dataset_names() == ("kodak24", "mcmaster", "train")
    loaded = [(d.name, f) for d in registry.datasets().values() for f in d.files]
    assert [
        (name, f.name, f.source_path, f.sha256, f.git_blob, f.pixels_sha256 or "-")
        for name, f in loaded
    ] == [tuple(row.values()) for row in rows]
    assert all(f.converted for f in registry.datasets()["mcmaster"].files)
    assert not any(f.converted for f in registry.datasets()["kodak24"].files)
    for module in (registry, downloading, testsets):
        source = Path(module.__file__).read_text()
        assert not re.search(r"[0-9a-f]{64}", source), module.__name__
        assert not any(row["git_blob"] in source for row in rows), module.__name__


def test_registry_matches_shared_data(shared_data: Path) -> None:
    for name in registry.dataset_names():
        folder = shared_data / name
        lines = (folder / "MANIFEST.sha256").read_text().splitlines()
        manifest = {file: digest for digest, file in (line.split(maxsplit=1) for line in lines)}
        with open(folder / "SOURCES.tsv", newline="") as fh:
            sources = {row["file"]: row for row in csv.DictReader(fh, delimiter="\t")}
        dataset = registry.datasets()[name]
        assert {f.name for f in dataset.files} == set(sources)
        assert {f.name for f in dataset.files} == set(manifest) - {
            "SOURCES.tsv",
            "DECODED_RGB.sha256",
        }
        ((repo, commit),) = {(row["source_repo"], row["source_commit"]) for row in sources.values()}
        assert dataset.base_url == f"https://raw.githubusercontent.com/{repo}/{commit}/"
        for entry in dataset.files:
            row = sources[entry.name]
            assert entry.sha256 == manifest[entry.name]
            assert entry.source_path == row["source_path"]
            assert entry.git_blob == (
                row.get("git_blob_sha1") or row["git_blob_sha1_of_source_tif"]
            )
            data = (folder / entry.name).read_bytes()
            assert hashlib.sha256(data).hexdigest() == entry.sha256
            if entry.converted:
                assert downloading._pixels_sha256(folder / entry.name) == entry.pixels_sha256
            else:
                # The SHA-256 pooch checks pins the same bytes as the published git blob id.
                assert _git_blob(data) == entry.git_blob


def test_registry_parser_rejects_malformed_tables() -> None:
    text = importlib.resources.files("splitcam.data").joinpath("registry.tsv").read_text()
    assert registry.parse_registry(text) == registry.datasets()
    kodim01 = _entry("kodak24", "kodim01.png")
    with pytest.raises(RuntimeError, match="malformed hash in row kodak24/kodim01.png"):
        registry.parse_registry(text.replace(kodim01.sha256, kodim01.sha256[:-1]))
    mcm03 = _entry("mcmaster", "03.png")
    with pytest.raises(RuntimeError, match="mcmaster/03.png is converted but has no pixel"):
        registry.parse_registry(text.replace(mcm03.pixels_sha256 or "?", "-"))
    with pytest.raises(RuntimeError, match="expected the columns"):
        registry.parse_registry(text.replace("pixels_sha256\n", "pixels\n"))
    kodak_only = "\n".join(line for line in text.splitlines() if not line.startswith("mcmaster"))
    with pytest.raises(RuntimeError, match="no files listed for mcmaster"):
        registry.parse_registry(kodak_only)


@pytest.mark.integration
def test_registry_and_download_import_neither_torch_nor_numpy() -> None:
    # The command line builds its parser from the registry: no numpy, no torch, and the
    # registry file is read on first use, not at import.
    loaded = fresh_modules(
        "import splitcam.data.registry as r\n"
        "assert r.datasets.cache_info().currsize == 0\n"
        "assert r.dataset_names() == ('kodak24', 'mcmaster', 'train')\n"
        "import splitcam.data.download"
    )
    assert {"splitcam.data.registry", "splitcam.data.download"} <= loaded
    assert not {"torch", "numpy", "pooch", "PIL"} & loaded


def test_the_training_photos_are_found_under_the_data_root(monkeypatch, tmp_path) -> None:
    """Scripts and studies read the training photos from $SPLITCAM_DATA/train, never from a
    folder beside the repository."""
    from splitcam.data import registry

    monkeypatch.setenv(registry.DATA_ENV, str(tmp_path))
    assert registry.training_folder() == tmp_path / "train"
    monkeypatch.delenv(registry.DATA_ENV)
    assert registry.training_folder() == Path(registry.DEFAULT_ROOT).expanduser() / "train"
    assert registry.training_folder(tmp_path / "x") == tmp_path / "x" / "train"


def test_data_by_the_name_of_a_downloaded_dataset(tmp_path, monkeypatch):
    """``--data train`` (a flag, a config file, a sweep or a recipe: every reader lists images
    through :func:`list_images`) finds the downloaded training photos under the data root."""
    from PIL import Image

    from splitcam.data.patches import list_images
    from splitcam.data.registry import dataset_folder

    monkeypatch.setenv("SPLITCAM_DATA", str(tmp_path / "root"))
    with pytest.raises(FileNotFoundError, match="splitcam data download train"):
        dataset_folder("train")
    (tmp_path / "root" / "train").mkdir(parents=True)
    assert dataset_folder("train") == tmp_path / "root" / "train"
    Image.new("RGB", (4, 4)).save(tmp_path / "root" / "train" / "a.png")
    assert list_images("train") == [tmp_path / "root" / "train" / "a.png"]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "train").mkdir()  # a folder of that name here is the folder meant
    assert dataset_folder("train") == Path("train")
    assert dataset_folder("photos") == Path("photos")


def test_a_portable_path_is_relative_to_the_data_root_or_the_working_folder(tmp_path, monkeypatch):
    from splitcam.data.registry import dataset_folder, portable_path

    root, work = tmp_path / "data", tmp_path / "work"
    (root / "train").mkdir(parents=True)
    (work / "runs" / "a").mkdir(parents=True)
    monkeypatch.setenv("SPLITCAM_DATA", str(root))
    monkeypatch.chdir(work)
    assert portable_path(root / "train") == "train"
    assert dataset_folder(portable_path(root / "train")) == root / "train"  # resolves again
    assert portable_path(str(root / "train" / "x.png")) == "train/x.png"
    assert portable_path(work / "runs" / "a") == "runs/a"
    assert portable_path(root) == "."
    assert portable_path(tmp_path / "other" / "photos") == "photos"  # outside both: its name
    assert portable_path("experiments/a.toml") == "experiments/a.toml"  # relative: as given
    assert portable_path("") == ""
