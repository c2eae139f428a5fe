"""Verified downloads (splitcam.data.download).

Downloads are served by a local HTTP server on 127.0.0.1 (``serve`` in conftest) from the
shared data folder or from temporary folders laid out like the public sources, or copied from
local folders; nothing goes to the internet."""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import socket
from pathlib import Path

import numpy as np
import pytest
from mirror import Server
from PIL import Image

from splitcam.data import registry, testsets
from splitcam.data.download import ChecksumError, DownloadError, download


def _contents(folder: Path) -> list[str]:
    """Every name in a folder, hidden ones included: left-over downloads show up here."""
    return sorted(p.name for p in folder.iterdir())


def _write_png(path: Path, seed: int, size: tuple[int, int] = (5, 4)) -> np.ndarray:
    pixels = np.random.default_rng(seed).integers(0, 256, (*size, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(path)
    return pixels


def _git_blob(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def _entry(dataset: str, name: str) -> registry.DatasetFile:
    return next(f for f in registry.datasets()[dataset].files if f.name == name)


def test_download_from_http_mirror(shared_data: Path, serve, tmp_path: Path) -> None:
    server = serve(shared_data)
    wanted = ["kodim01.png", "kodim19.png", "07.png"]
    paths = download(
        ["kodak24", "mcmaster"], tmp_path, mirror=server.url + "/", progress=False, files=wanted
    )
    assert paths == [
        tmp_path / "kodak24" / "kodim01.png",
        tmp_path / "kodak24" / "kodim19.png",
        tmp_path / "mcmaster" / "07.png",
    ]
    for path in paths:
        assert path.read_bytes() == (shared_data / path.parent.name / path.name).read_bytes()
    assert sorted(server.log) == [
        "/kodak24/kodim01.png",
        "/kodak24/kodim19.png",
        "/mcmaster/07.png",
    ]
    assert _contents(tmp_path / "kodak24") == ["kodim01.png", "kodim19.png"]
    assert _contents(tmp_path / "mcmaster") == ["07.png"]
    names = [name for name, _ in testsets.resolve("kodak24", root=tmp_path)]
    assert names == ["kodim01", "kodim19"]


@pytest.mark.parametrize("how", ["env-folder", "file-url"])
def test_download_from_local_mirror(
    how: str, shared_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(registry.DATA_ENV, str(tmp_path))
    if how == "env-folder":
        monkeypatch.setenv(registry.MIRROR_ENV, str(shared_data))
        mirror = None
    else:
        mirror = shared_data.resolve().as_uri()
    (path,) = download("mcmaster", mirror=mirror, progress=False, files=["07.png"])
    assert path == tmp_path / "mcmaster" / "07.png"
    assert path.read_bytes() == (shared_data / "mcmaster" / "07.png").read_bytes()
    assert _contents(tmp_path / "mcmaster") == ["07.png"]


def _public_layout(tmp_path: Path, shared_data: Path) -> Path:
    """A folder laid out like the source repository of Kodak24, pointing at the shared copies."""
    site = tmp_path / "site"
    (site / "testsets").mkdir(parents=True)
    (site / "testsets" / "Set24").symlink_to(shared_data / "kodak24")
    return site


def test_download_from_public_source_layout(
    shared_data: Path, serve, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    server = serve(_public_layout(tmp_path, shared_data))
    monkeypatch.setitem(
        registry.datasets(),
        "kodak24",
        dataclasses.replace(registry.datasets()["kodak24"], base_url=server.url + "/"),
    )
    (path,) = download("kodak24", tmp_path / "data", progress=False, files=["kodim03.png"])
    assert path.read_bytes() == (shared_data / "kodak24" / "kodim03.png").read_bytes()
    assert server.log == ["/testsets/Set24/kodim03.png"]
    assert _contents(tmp_path / "data" / "kodak24") == ["kodim03.png"]


def _serve_mcmaster_tiff(
    tiff: Path, name: str, blob: str, serve, monkeypatch: pytest.MonkeyPatch
) -> Server:
    """Serve the folder above ``testsets/McMaster/`` as McMaster's source, with ``name``'s git
    blob id registered as ``blob``."""
    dataset = registry.datasets()["mcmaster"]
    files = tuple(
        dataclasses.replace(f, git_blob=blob) if f.name == name else f for f in dataset.files
    )
    server = serve(tiff.parents[2])
    monkeypatch.setitem(
        registry.datasets(),
        "mcmaster",
        dataclasses.replace(dataset, base_url=server.url + "/", files=files),
    )
    return server


def test_mcmaster_tiff_is_verified_and_converted(
    shared_data: Path, serve, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The published TIFF is not on this machine; a PackBits TIFF with the same pixels stands in,
    # so the real pixel hash is checked while the blob id is the stand-in's.
    tiff = tmp_path / "site" / "testsets" / "McMaster" / "2.tif"
    tiff.parent.mkdir(parents=True)
    reference = np.asarray(Image.open(shared_data / "mcmaster" / "02.png").convert("RGB"))
    Image.fromarray(reference).save(tiff, compression="packbits")
    server = _serve_mcmaster_tiff(tiff, "02.png", _git_blob(tiff.read_bytes()), serve, monkeypatch)
    out = tmp_path / "data"
    (path,) = download("mcmaster", out, progress=False, files=["02.png"])
    assert path == out / "mcmaster" / "02.png"
    assert server.log == ["/testsets/McMaster/2.tif"]
    assert np.array_equal(np.asarray(Image.open(path)), reference)
    assert _contents(out / "mcmaster") == ["02.png"]  # no TIFF, scratch folder or temporary

    # A PNG encoded differently still counts as present, by its pixels.
    Image.fromarray(reference).save(path, compress_level=1)
    server.log.clear()
    download("mcmaster", out, progress=False, files=["02.png"])
    assert server.log == []

    # Different bytes (a changed TIFF) are refused by the blob id before decoding.
    Image.fromarray(reference).save(tiff, compression="tiff_lzw")
    path.unlink()
    with pytest.raises(ChecksumError, match="mcmaster/02.png.*git blob id") as info:
        download("mcmaster", out, progress=False, files=["02.png"])
    assert _git_blob(tiff.read_bytes()) in str(info.value)
    assert _contents(out / "mcmaster") == []


def test_mcmaster_tiff_with_other_pixels_is_refused(
    serve, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Right bytes (the blob id is registered) that decode to other pixels than registered: the
    # pixel check is what stops them.
    tiff = tmp_path / "site" / "testsets" / "McMaster" / "5.tif"
    tiff.parent.mkdir(parents=True)
    _write_png(tmp_path / "other.png", 5, size=(8, 8))
    Image.open(tmp_path / "other.png").save(tiff, compression="packbits")
    _serve_mcmaster_tiff(tiff, "05.png", _git_blob(tiff.read_bytes()), serve, monkeypatch)
    out = tmp_path / "data"
    with pytest.raises(DownloadError, match="mcmaster/05.png.*pixel SHA-256") as info:
        download("mcmaster", out, progress=False, files=["05.png"])
    assert not isinstance(info.value, ChecksumError)
    assert _contents(out / "mcmaster") == []


@pytest.mark.parametrize("how", ["http", "folder"])
def test_tampered_file_is_refused_and_deleted(
    how: str, shared_data: Path, serve, tmp_path: Path
) -> None:
    site = tmp_path / "site" / "kodak24"
    site.mkdir(parents=True)
    data = bytearray((shared_data / "kodak24" / "kodim05.png").read_bytes())
    data[1000] ^= 0xFF
    (site / "kodim05.png").write_bytes(bytes(data))
    mirror = serve(tmp_path / "site").url if how == "http" else str(tmp_path / "site")
    out = tmp_path / "data"
    with pytest.raises(ChecksumError) as info:
        download("kodak24", out, mirror=mirror, progress=False, files=["kodim05.png"])
    message = str(info.value)
    assert "kodak24/kodim05.png" in message
    assert _entry("kodak24", "kodim05.png").sha256 in message
    assert hashlib.sha256(bytes(data)).hexdigest() in message
    assert _contents(out / "kodak24") == []


def test_present_files_are_skipped_and_bad_ones_replaced(
    shared_data: Path, serve, tmp_path: Path
) -> None:
    server = serve(shared_data)
    wanted = ["kodim07.png", "kodim08.png"]
    download("kodak24", tmp_path, mirror=server.url, progress=False, files=wanted)
    assert len(server.log) == 2
    server.log.clear()
    download("kodak24", tmp_path, mirror=server.url, progress=False, files=wanted)
    assert server.log == []

    (tmp_path / "kodak24" / "kodim08.png").write_bytes(b"not the image")
    paths = download("kodak24", tmp_path, mirror=server.url, progress=False, files=wanted)
    assert server.log == ["/kodak24/kodim08.png"]
    assert paths[1].read_bytes() == (shared_data / "kodak24" / "kodim08.png").read_bytes()
    assert _contents(tmp_path / "kodak24") == wanted


def test_broken_connection_leaves_nothing_and_retry_starts_over(
    shared_data: Path, serve, tmp_path: Path
) -> None:
    server = serve(shared_data)
    server.cut_once.add("/kodak24/kodim02.png")
    out = tmp_path / "data"
    with pytest.raises(DownloadError, match="kodak24/kodim02.png"):
        download("kodak24", out, mirror=server.url, progress=False, files=["kodim02.png"])
    assert _contents(out / "kodak24") == []

    (path,) = download("kodak24", out, mirror=server.url, progress=False, files=["kodim02.png"])
    assert path.read_bytes() == (shared_data / "kodak24" / "kodim02.png").read_bytes()
    assert server.log == ["/kodak24/kodim02.png"] * 2


def test_progress_bars_without_pooch_log(
    shared_data: Path, serve, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    import pooch

    server = serve(shared_data)
    logger = pooch.get_logger()
    # As after an earlier pooch download: the logger has cached that INFO messages go out.
    assert logger.isEnabledFor(logging.INFO)
    (path,) = download("kodak24", tmp_path, mirror=server.url, progress=True, files=["kodim09.png"])
    assert path.read_bytes() == (shared_data / "kodak24" / "kodim09.png").read_bytes()
    err = capfd.readouterr().err
    assert "download" in err and "kodak24/kodim09.png" in err
    assert "Downloading data from" not in err
    assert logger.filters == []


def test_network_error_leaves_no_final_file(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    # Nothing listens on the port any more: the connection is refused.
    with pytest.raises(DownloadError, match="kodak24/kodim01.png") as info:
        download(
            "kodak24",
            tmp_path,
            mirror=f"http://127.0.0.1:{port}",
            progress=False,
            timeout=5,
            files=["kodim01.png"],
        )
    assert not isinstance(info.value, ChecksumError)
    assert _contents(tmp_path / "kodak24") == []


def test_http_error_is_reported(serve, tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    server = serve(tmp_path / "empty")
    with pytest.raises(DownloadError, match="kodak24/kodim01.png .*HTTP 404"):
        download("kodak24", tmp_path, mirror=server.url, progress=False, files=["kodim01.png"])


def test_missing_file_in_local_mirror_is_reported(tmp_path: Path) -> None:
    (tmp_path / "mirror").mkdir()
    with pytest.raises(DownloadError, match="kodak24/kodim01.png"):
        download(
            "kodak24",
            tmp_path / "data",
            mirror=str(tmp_path / "mirror"),
            progress=False,
            files=["kodim01.png"],
        )
    assert _contents(tmp_path / "data" / "kodak24") == []


def test_download_rejects_unknown_names(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown dataset.*kodak24, mcmaster"):
        download(["kodak"], tmp_path)
    with pytest.raises(ValueError, match="01.png"):
        download("kodak24", tmp_path, files=["01.png"])
    with pytest.raises(ValueError, match="neither a URL"):
        download("kodak24", tmp_path, mirror=str(tmp_path / "missing"))
    with pytest.raises(ValueError, match="unsupported scheme 'ftp://'"):
        download("kodak24", tmp_path, mirror="ftp://127.0.0.1/data")


def test_training_photos_download_from_their_public_source(
    shared_data: Path, serve, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`splitcam data download train`: the 432 BSDS500 photos, pinned to a commit of their
    source repository and verified file by file; a photo the mirror serves wrong is refused."""
    dataset = registry.datasets()["train"]
    assert len(dataset.files) == 432
    assert "c4f9ac8c43397cbacbf2e2ba1505efafa769435d" in dataset.base_url
    site = tmp_path / "site"
    for split in ("train", "test", "val"):
        (site / "BSR" / "BSDS500" / "data" / "images" / split).mkdir(parents=True)
    picked = ["100075.jpg", "97033.jpg"]
    for name in picked:
        entry = _entry("train", name)
        (site / entry.source_path).symlink_to(shared_data / "train" / name)
    server = serve(site)
    monkeypatch.setitem(
        registry.datasets(), "train", dataclasses.replace(dataset, base_url=server.url + "/")
    )
    paths = download("train", tmp_path / "data", progress=False, files=picked)
    for path in paths:
        assert path.read_bytes() == (shared_data / "train" / path.name).read_bytes()
    assert _contents(tmp_path / "data" / "train") == sorted(picked)
    assert registry.training_folder(tmp_path / "data") == tmp_path / "data" / "train"
    # A mirror that serves another photo under a name: refused, nothing left behind.
    wrong = _entry("train", "100080.jpg")
    (site / wrong.source_path).symlink_to(shared_data / "train" / "100075.jpg")
    with pytest.raises(ChecksumError):
        download("train", tmp_path / "data", progress=False, files=["100080.jpg"])
    assert _contents(tmp_path / "data" / "train") == sorted(picked)
