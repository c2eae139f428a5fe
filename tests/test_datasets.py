"""Tests of the test sets: the registry (splitcam.data.registry), verified downloads
(splitcam.data.download), and finding and loading test sets and the bundled images
(splitcam.data.testsets).

Downloads are served by a local HTTP server on 127.0.0.1 from the shared data folder (or from
temporary folders laid out like the public sources), or copied from local folders; nothing goes
to the internet.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import http.server
import importlib.resources
import logging
import re
import socket
import subprocess
import sys
import threading
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import splitcam.data.download as downloading
from splitcam.data import registry, testsets
from splitcam.data.download import ChecksumError, DownloadError, download


class _Handler(http.server.BaseHTTPRequestHandler):
    """Serves the files below ``root``, logs the paths asked for, and can cut a file short.

    Settings live on a per-server subclass (see :class:`_Server`).
    """

    root: Path
    cut_once: set[str]
    log: list[str]

    def do_GET(self) -> None:
        path = urllib.parse.unquote(self.path.split("?", 1)[0])
        self.log.append(path)
        target = self.root / path.lstrip("/")
        if not target.is_file():
            self.send_error(404)
            return
        data = target.read_bytes()
        self.send_response(200)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        if path in self.cut_once:
            # Announce the full length, send half, hang up: a connection lost mid-download.
            self.cut_once.discard(path)
            self.wfile.write(data[: len(data) // 2])
            self.close_connection = True
            return
        self.wfile.write(data)

    def log_message(self, fmt: str, *args: object) -> None:
        pass


class _Server:
    """A threaded HTTP server on 127.0.0.1 serving one folder."""

    def __init__(self, root: Path) -> None:
        self.log: list[str] = []
        self.cut_once: set[str] = set()
        handler = type(
            "Handler",
            (_Handler,),
            {"root": root.resolve(), "cut_once": self.cut_once, "log": self.log},
        )
        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, args=(0.05,), daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join()


@pytest.fixture
def serve() -> Iterator:
    servers: list[_Server] = []

    def start(root: Path) -> _Server:
        servers.append(_Server(root))
        return servers[-1]

    yield start
    for server in servers:
        server.close()


@pytest.fixture(autouse=True)
def _no_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """A user's SPLITCAM_DATA or SPLITCAM_MIRROR must not change what the tests see."""
    monkeypatch.delenv(registry.DATA_ENV, raising=False)
    monkeypatch.delenv(registry.MIRROR_ENV, raising=False)


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


def _registry_rows() -> list[dict[str, str]]:
    """The rows of the shipped registry file, read without the module's parser."""
    text = importlib.resources.files("splitcam.data").joinpath("registry.tsv").read_text()
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    return list(csv.DictReader(lines, delimiter="\t"))


# ---------------------------------------------------------------------------------------------
# The registry


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
    assert len(kodak) + len(mcmaster) == len(rows)
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
    assert registry.dataset_names() == ("kodak24", "mcmaster")
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
        assert {f.name for f in dataset.files} == set(manifest) - {"SOURCES.tsv"}
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


# ---------------------------------------------------------------------------------------------
# Downloads


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
) -> _Server:
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


# ---------------------------------------------------------------------------------------------
# Finding and loading test sets


def test_resolve_dataset_names(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "kodak24").mkdir()
    _write_png(tmp_path / "kodak24" / "kodim02.png", 0)
    _write_png(tmp_path / "kodak24" / "kodim01.png", 1)
    expected = [(f"kodim0{i}", tmp_path / "kodak24" / f"kodim0{i}.png") for i in (1, 2)]
    assert testsets.resolve("kodak24", root=tmp_path) == expected
    monkeypatch.setenv(registry.DATA_ENV, str(tmp_path))
    assert testsets.resolve("kodak24") == expected
    assert registry.data_root() == tmp_path
    monkeypatch.delenv(registry.DATA_ENV)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert registry.data_root() == tmp_path / "home" / ".cache" / "splitcam" / "datasets"


def test_resolve_missing_dataset_says_how_to_get_it(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as info:
        testsets.resolve("mcmaster", root=tmp_path)
    message = str(info.value)
    assert "splitcam data download mcmaster --to DIR" in message
    assert registry.DATA_ENV in message
    assert str(tmp_path) in message
    with pytest.raises(FileNotFoundError, match="neither a folder nor a dataset"):
        testsets.resolve("no_such_set", root=tmp_path)


def test_resolve_folders(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "mine"
    folder.mkdir()
    _write_png(folder / "b.png", 0)
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(folder / "a.JPG")
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(folder / "c.tiff")
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(folder / "d.bmp")
    (folder / "notes.txt").write_text("not an image")
    _write_png(folder / ".hidden.png", 1)
    (folder / "sub").mkdir()
    _write_png(folder / "sub" / "e.png", 2)
    expected = [
        ("a", folder / "a.JPG"),
        ("b", folder / "b.png"),
        ("c", folder / "c.tiff"),
        ("d", folder / "d.bmp"),
    ]
    assert testsets.resolve(str(folder)) == expected
    assert testsets.resolve(folder) == expected
    monkeypatch.chdir(tmp_path)
    # A plain word that is no dataset under the root but a folder here is that folder.
    assert testsets.resolve("mine", root=tmp_path / "root") == [
        (name, Path("mine") / path.name) for name, path in expected
    ]
    assert testsets.resolve("./mine") == [(n, Path("mine") / p.name) for n, p in expected]


def test_resolve_folder_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="does not exist"):
        testsets.resolve(tmp_path / "missing")
    with pytest.raises(FileNotFoundError, match="no image files"):
        testsets.resolve(tmp_path)
    _write_png(tmp_path / "x.png", 0)
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(tmp_path / "x.jpg")
    with pytest.raises(ValueError, match="x.jpg, x.png"):
        testsets.resolve(tmp_path)


def test_load_images(tmp_path: Path) -> None:
    pixels = _write_png(tmp_path / "img.png", 3, size=(6, 7))
    ((name, image),) = testsets.load_images(tmp_path)
    assert name == "img"
    assert image.shape == (3, 6, 7)
    assert str(image.dtype) == "torch.float32"
    np.testing.assert_allclose(image.permute(1, 2, 0).numpy() * 255, pixels, atol=1e-4)


def test_default_images_need_no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("default_images() tried to download")

    monkeypatch.setattr(urllib.request, "urlopen", refuse)
    monkeypatch.setattr(socket.socket, "connect", refuse)
    images = testsets.default_images()
    assert len(images) >= 4
    names = [name for name, _ in images]
    assert {"skimage/astronaut", "skimage/chelsea", "skimage/coffee", "skimage/rocket"} <= set(
        names
    )
    assert names == [n for n in testsets.DEFAULT_IMAGE_NAMES if n in names]
    for name, image in images:
        assert image.ndim == 3 and image.shape[0] == 3, name
        assert str(image.dtype) == "torch.float32", name
        assert 0.0 <= float(image.min()) and float(image.max()) <= 1.0, name
        # Colour, not greyscale stored as RGB.
        assert float((image[0] - image[1]).abs().max()) > 0.1, name
    assert testsets.load_images(None)[0][0] == names[0]


def test_default_images_match_skimage_loaders() -> None:
    import skimage.data

    ((name, image),) = testsets.default_images(["astronaut"])
    assert name == "skimage/astronaut"
    expected = skimage.data.astronaut().astype(np.float32) / 255
    np.testing.assert_array_equal(image.permute(1, 2, 0).numpy(), expected)
    with pytest.raises(ValueError, match="skimage/astronaut"):
        testsets.default_images(["camera"])


def test_load_datasets(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for folder, seed in (("first", 0), ("second", 10)):
        (tmp_path / folder).mkdir()
        for i in range(3):
            _write_png(tmp_path / folder / f"img{i}.png", seed + i, size=(7, 9))
    spec = f"{tmp_path / 'first'}, {tmp_path / 'second'}/"
    whole = testsets.load_datasets(spec)
    assert [name for name, _ in whole] == ["first", "second"]
    assert [[n for n, _ in images] for _, images in whole] == [["img0", "img1", "img2"]] * 2
    assert all(image.shape == (3, 7, 9) for _, images in whole for _, image in images)

    cropped = testsets.load_datasets(spec, max_images=2, max_size=4)
    assert [name for name, _ in cropped] == ["first-4px", "second-4px"]
    for (_, images), (_, full) in zip(cropped, whole, strict=True):
        assert [n for n, _ in images] == ["img0", "img1"]
        for (_, image), (_, original) in zip(images, full[:2], strict=True):
            assert image.shape == (3, 4, 4)
            assert image.equal(testsets.centre_crop(original, 4))

    # No spec, or "default": the bundled images as the one test set "skimage".
    bundled = [("skimage/a", whole[0][1][0][1]), ("skimage/b", whole[0][1][1][1])]
    monkeypatch.setattr(testsets, "default_images", lambda: bundled)
    for default in (None, "", "default"):
        assert testsets.load_datasets(default) == [("skimage", bundled)]
    ((name, images),) = testsets.load_datasets(None, max_images=1, max_size=6)
    assert name == "skimage-6px" and [n for n, _ in images] == ["skimage/a"]

    for size in (1, 0, -3):
        with pytest.raises(ValueError, match=f"max_size must be at least 2 pixels, got {size}"):
            testsets.load_datasets(spec, max_size=size)
    with pytest.raises(FileNotFoundError, match="neither a folder nor a dataset"):
        testsets.load_datasets("no_such_set")


# ---------------------------------------------------------------------------------------------
# What importing costs


def _fresh_modules(code: str) -> set[str]:
    """The modules a fresh interpreter has loaded after running ``code``."""
    script = f"import sys\n{code}\nprint(' '.join(sys.modules))"
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    return set(result.stdout.split())


def test_registry_and_download_import_neither_torch_nor_numpy() -> None:
    # The command line builds its parser from the registry: no numpy, no torch, and the
    # registry file is read on first use, not at import.
    loaded = _fresh_modules(
        "import splitcam.data.registry as r\n"
        "assert r.datasets.cache_info().currsize == 0\n"
        "assert r.dataset_names() == ('kodak24', 'mcmaster')\n"
        "import splitcam.data.download"
    )
    assert {"splitcam.data.registry", "splitcam.data.download"} <= loaded
    assert not {"torch", "numpy", "pooch", "PIL"} & loaded


def test_data_package_imports_its_names_on_first_use() -> None:
    import splitcam.data as data
    from splitcam.data import images, patches, raw

    assert "torch" not in _fresh_modules("import splitcam.data")
    assert data.read_image is images.read_image
    assert data.write_raw is raw.write_raw
    assert data.ImageCache is patches.ImageCache
    assert data.load_images is testsets.load_images
    assert set(data.__all__) <= set(dir(data))
    assert {"registry", "download", "testsets", "images", "raw"} <= set(dir(data))
    assert data.registry is registry
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        data.nothing  # noqa: B018
