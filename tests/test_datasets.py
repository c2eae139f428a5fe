"""Tests for splitcam.data.testsets: test sets, the bundled images, verified downloads.

Downloads are served by a local HTTP server on 127.0.0.1 from the shared data folder (or from
temporary folders laid out like the public sources); nothing goes to the internet.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import http.server
import re
import socket
import threading
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from splitcam.data import testsets as datasets
from splitcam.data.testsets import ChecksumError, DownloadError


class _Handler(http.server.BaseHTTPRequestHandler):
    """Serves files below ``root``; optionally honours ``Range: bytes=N-`` and cuts files short.

    Python's SimpleHTTPRequestHandler ignores Range headers, so this one is written out. Settings
    live on a per-server subclass (see :class:`_Server`).
    """

    root: Path
    supports_range: bool
    cut_once: set[str]
    log: list[tuple[str, str | None]]

    def do_GET(self) -> None:
        path = self.path.split("?", 1)[0]
        self.log.append((path, self.headers.get("Range")))
        target = (self.root / path.lstrip("/")).resolve()
        if not target.is_file():
            self.send_error(404)
            return
        data = target.read_bytes()
        start, status = 0, 200
        match = re.fullmatch(r"bytes=(\d+)-", self.headers.get("Range") or "")
        if match and self.supports_range:
            start, status = int(match.group(1)), 206
            if start >= len(data):
                self.send_response(416)
                self.send_header("Content-Range", f"bytes */{len(data)}")
                self.send_header("Content-Length", "0")
                self.end_headers()
                return
        body = data[start:]
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        if status == 206:
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        self.end_headers()
        if path in self.cut_once:
            # Announce the full length, send half, hang up: a connection lost mid-download.
            self.cut_once.discard(path)
            self.wfile.write(body[: len(body) // 2])
            self.close_connection = True
            return
        self.wfile.write(body)

    def log_message(self, fmt: str, *args: object) -> None:
        pass


class _Server:
    """A threaded HTTP server on 127.0.0.1 serving one folder."""

    def __init__(self, root: Path, *, supports_range: bool = True) -> None:
        self.log: list[tuple[str, str | None]] = []
        self.cut_once: set[str] = set()
        handler = type(
            "Handler", (_Handler,),
            {"root": root.resolve(), "supports_range": supports_range, "cut_once": self.cut_once,
             "log": self.log},
        )
        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, args=(0.05,), daemon=True)
        self.thread.start()

    def requests_for(self, suffix: str) -> list[str | None]:
        """Range headers of the requests whose path ends with ``suffix``."""
        return [rng for path, rng in self.log if path.endswith(suffix)]

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join()


@pytest.fixture
def serve() -> Iterator:
    servers: list[_Server] = []

    def start(root: Path, *, supports_range: bool = True) -> _Server:
        servers.append(_Server(root, supports_range=supports_range))
        return servers[-1]

    yield start
    for server in servers:
        server.close()


@pytest.fixture(autouse=True)
def _no_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """A user's SPLITCAM_DATA or SPLITCAM_MIRROR must not change what the tests see."""
    monkeypatch.delenv(datasets.DATA_ENV, raising=False)
    monkeypatch.delenv(datasets.MIRROR_ENV, raising=False)


def _leftovers(folder: Path) -> list[str]:
    """Partial and temporary files in a dataset folder."""
    return sorted(p.name for p in folder.iterdir() if p.name.endswith((".part", ".tmp")))


def _write_png(path: Path, seed: int, size: tuple[int, int] = (5, 4)) -> np.ndarray:
    pixels = np.random.default_rng(seed).integers(0, 256, (*size, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(path)
    return pixels


def _tiff_blob(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


# ---------------------------------------------------------------------------------------------
# The embedded table


def test_table_matches_shared_manifests(shared_data: Path) -> None:
    for name in datasets.DATASET_NAMES:
        folder = shared_data / name
        lines = (folder / "MANIFEST.sha256").read_text().splitlines()
        manifest = {file: digest for digest, file in (line.split(maxsplit=1) for line in lines)}
        with open(folder / "SOURCES.tsv", newline="") as fh:
            sources = {row["file"]: row for row in csv.DictReader(fh, delimiter="\t")}
        dataset = datasets._DATASETS[name]
        assert {f.name for f in dataset.files} == set(sources)
        commits = {row["source_commit"] for row in sources.values()}
        repos = {row["source_repo"] for row in sources.values()}
        assert dataset.base_url == f"https://raw.githubusercontent.com/{repos.pop()}/{commits.pop()}/"
        for entry in dataset.files:
            row = sources[entry.name]
            assert entry.sha256 == manifest[entry.name]
            assert entry.source_path == row["source_path"]
            blob = row.get("git_blob_sha1") or row["git_blob_sha1_of_source_tif"]
            assert entry.git_blob == blob
            if entry.pixels_sha256 is not None:
                assert datasets._pixels_sha256(folder / entry.name) == entry.pixels_sha256
    assert all(f.pixels_sha256 and f.converted for f in datasets._MCMASTER.files)
    assert not any(f.converted for f in datasets._KODAK24.files)


# ---------------------------------------------------------------------------------------------
# Downloads


def test_download_from_mirror_equals_source(shared_data: Path, serve, tmp_path: Path) -> None:
    server = serve(shared_data)
    wanted = ["kodim01.png", "kodim19.png"]
    paths = datasets.download(
        ["kodak24"], tmp_path, mirror=server.url + "/", progress=False, files=wanted
    )
    assert paths == [tmp_path / "kodak24" / name for name in wanted]
    for path in paths:
        assert path.read_bytes() == (shared_data / "kodak24" / path.name).read_bytes()
    assert _leftovers(tmp_path / "kodak24") == []
    names = [name for name, _ in datasets.resolve("kodak24", root=tmp_path)]
    assert names == ["kodim01", "kodim19"]


def test_download_mirror_from_env_and_local_folder(
    shared_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(datasets.MIRROR_ENV, str(shared_data))
    monkeypatch.setenv(datasets.DATA_ENV, str(tmp_path))
    (path,) = datasets.download("mcmaster", progress=False, files=["07.png"])
    assert path == tmp_path / "mcmaster" / "07.png"
    assert path.read_bytes() == (shared_data / "mcmaster" / "07.png").read_bytes()


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
        datasets._DATASETS, "kodak24",
        dataclasses.replace(datasets._KODAK24, base_url=server.url + "/"),
    )
    (path,) = datasets.download("kodak24", tmp_path / "data", progress=False,
                                files=["kodim03.png"])
    assert path.read_bytes() == (shared_data / "kodak24" / "kodim03.png").read_bytes()
    assert server.requests_for("/testsets/Set24/kodim03.png") == [None]


def test_mcmaster_tiff_is_verified_and_converted(
    shared_data: Path, serve, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The published TIFF is not on this machine; a PackBits TIFF with the same pixels stands in,
    # so the real pixel hash is checked while the blob id is the stand-in's.
    source = tmp_path / "site" / "testsets" / "McMaster"
    source.mkdir(parents=True)
    reference = np.asarray(Image.open(shared_data / "mcmaster" / "02.png").convert("RGB"))
    Image.fromarray(reference).save(source / "2.tif", compression="packbits")
    tiff = (source / "2.tif").read_bytes()
    entry = next(f for f in datasets._MCMASTER.files if f.name == "02.png")
    files = tuple(
        dataclasses.replace(f, git_blob=_tiff_blob(tiff)) if f is entry else f
        for f in datasets._MCMASTER.files
    )
    server = serve(tmp_path / "site")
    monkeypatch.setitem(
        datasets._DATASETS, "mcmaster",
        dataclasses.replace(datasets._MCMASTER, base_url=server.url + "/", files=files),
    )
    out = tmp_path / "data"
    (path,) = datasets.download("mcmaster", out, progress=False, files=["02.png"])
    assert path == out / "mcmaster" / "02.png"
    assert np.array_equal(np.asarray(Image.open(path)), reference)
    assert _leftovers(out / "mcmaster") == []
    # A PNG encoded differently still counts as present, by its pixels.
    Image.fromarray(reference).save(path, compress_level=1)
    server.log.clear()
    datasets.download("mcmaster", out, progress=False, files=["02.png"])
    assert server.log == []

    # Different bytes (a changed TIFF) are refused by the blob id before decoding.
    Image.fromarray(reference).save(source / "2.tif", compression="tiff_lzw")
    path.unlink()
    with pytest.raises(ChecksumError, match="git blob id"):
        datasets.download("mcmaster", out, progress=False, files=["02.png"])
    assert list((out / "mcmaster").iterdir()) == []


def test_checksum_mismatch_leaves_nothing(shared_data: Path, serve, tmp_path: Path) -> None:
    site = tmp_path / "site" / "kodak24"
    site.mkdir(parents=True)
    data = bytearray((shared_data / "kodak24" / "kodim05.png").read_bytes())
    data[1000] ^= 0xFF
    (site / "kodim05.png").write_bytes(bytes(data))
    server = serve(tmp_path / "site")
    out = tmp_path / "data"
    with pytest.raises(ChecksumError) as info:
        datasets.download("kodak24", out, mirror=server.url, progress=False,
                          files=["kodim05.png"])
    message = str(info.value)
    entry = next(f for f in datasets._KODAK24.files if f.name == "kodim05.png")
    assert "kodak24/kodim05.png" in message
    assert entry.sha256 in message
    assert hashlib.sha256(bytes(data)).hexdigest() in message
    assert list((out / "kodak24").iterdir()) == []


def test_interrupted_download_resumes_with_range(shared_data: Path, serve, tmp_path: Path) -> None:
    server = serve(shared_data, supports_range=True)
    server.cut_once.add("/kodak24/kodim02.png")
    out = tmp_path / "data"
    original = (shared_data / "kodak24" / "kodim02.png").read_bytes()
    with pytest.raises(DownloadError, match="run the command again to resume"):
        datasets.download("kodak24", out, mirror=server.url, progress=False,
                          files=["kodim02.png"])
    part = out / "kodak24" / "kodim02.png.part"
    assert not (out / "kodak24" / "kodim02.png").exists()
    assert part.stat().st_size == len(original) // 2

    (path,) = datasets.download("kodak24", out, mirror=server.url, progress=False,
                                files=["kodim02.png"])
    assert path.read_bytes() == original
    assert server.requests_for("kodim02.png") == [None, f"bytes={len(original) // 2}-"]
    assert _leftovers(out / "kodak24") == []


def test_truncated_part_restarts_without_range_support(
    shared_data: Path, serve, tmp_path: Path
) -> None:
    server = serve(shared_data, supports_range=False)
    folder = tmp_path / "kodak24"
    folder.mkdir()
    original = (shared_data / "kodak24" / "kodim04.png").read_bytes()
    # A wrong prefix proves the restart: appending to it would fail the checksum.
    (folder / "kodim04.png.part").write_bytes(b"x" * 1000)
    (path,) = datasets.download("kodak24", tmp_path, mirror=server.url, progress=False,
                                files=["kodim04.png"])
    assert path.read_bytes() == original
    assert server.requests_for("kodim04.png") == ["bytes=1000-"]


def test_overlong_part_restarts_after_416(shared_data: Path, serve, tmp_path: Path) -> None:
    server = serve(shared_data, supports_range=True)
    folder = tmp_path / "kodak24"
    folder.mkdir()
    original = (shared_data / "kodak24" / "kodim06.png").read_bytes()
    (folder / "kodim06.png.part").write_bytes(original + b"junk")
    (path,) = datasets.download("kodak24", tmp_path, mirror=server.url, progress=False,
                                files=["kodim06.png"])
    assert path.read_bytes() == original
    assert server.requests_for("kodim06.png") == [f"bytes={len(original) + 4}-", None]


def test_present_files_are_skipped_and_bad_ones_replaced(
    shared_data: Path, serve, tmp_path: Path
) -> None:
    server = serve(shared_data)
    wanted = ["kodim07.png", "kodim08.png"]
    datasets.download("kodak24", tmp_path, mirror=server.url, progress=False, files=wanted)
    assert len(server.log) == 2
    server.log.clear()
    datasets.download("kodak24", tmp_path, mirror=server.url, progress=False, files=wanted)
    assert server.log == []

    (tmp_path / "kodak24" / "kodim08.png").write_bytes(b"not the image")
    paths = datasets.download("kodak24", tmp_path, mirror=server.url, progress=False,
                              files=wanted)
    assert [path for path, _ in server.log] == ["/kodak24/kodim08.png"]
    assert paths[1].read_bytes() == (shared_data / "kodak24" / "kodim08.png").read_bytes()


def test_network_error_leaves_no_final_file(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    # Nothing listens on the port any more: the connection is refused.
    with pytest.raises(DownloadError, match="kodak24/kodim01.png"):
        datasets.download("kodak24", tmp_path, mirror=f"http://127.0.0.1:{port}",
                          progress=False, timeout=5, files=["kodim01.png"])
    assert not (tmp_path / "kodak24" / "kodim01.png").exists()


def test_http_error_is_reported(serve, tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    server = serve(tmp_path / "empty")
    with pytest.raises(DownloadError, match="HTTP 404"):
        datasets.download("kodak24", tmp_path, mirror=server.url, progress=False,
                          files=["kodim01.png"])


def test_download_rejects_unknown_names(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown dataset.*kodak24, mcmaster"):
        datasets.download(["kodak"], tmp_path)
    with pytest.raises(ValueError, match="01.png"):
        datasets.download("kodak24", tmp_path, files=["01.png"])
    with pytest.raises(ValueError, match="neither a URL"):
        datasets.download("kodak24", tmp_path, mirror=str(tmp_path / "missing"))


def test_cli_download_and_list(
    shared_data: Path, serve, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    server = serve(shared_data)
    parser = argparse.ArgumentParser(prog="splitcam")
    datasets.add_cli(parser.add_subparsers(dest="command", required=True))
    # Pre-populate all but one file so the command downloads one and verifies the rest.
    folder = tmp_path / "mcmaster"
    folder.mkdir()
    for entry in datasets._MCMASTER.files[1:]:
        (folder / entry.name).symlink_to(shared_data / "mcmaster" / entry.name)
    args = parser.parse_args(
        ["data", "download", "mcmaster", "--to", str(tmp_path), "--mirror", server.url, "--quiet"]
    )
    assert args.handler(args) == 0
    assert server.requests_for(".png") == [None]
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
    assert datasets.resolve("kodak24", root=tmp_path) == expected
    monkeypatch.setenv(datasets.DATA_ENV, str(tmp_path))
    assert datasets.resolve("kodak24") == expected
    assert datasets.data_root() == tmp_path
    monkeypatch.delenv(datasets.DATA_ENV)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert datasets.data_root() == tmp_path / "home" / ".cache" / "splitcam" / "datasets"


def test_resolve_missing_dataset_says_how_to_get_it(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as info:
        datasets.resolve("mcmaster", root=tmp_path)
    message = str(info.value)
    assert "splitcam data download mcmaster --to DIR" in message
    assert datasets.DATA_ENV in message
    assert str(tmp_path) in message
    with pytest.raises(FileNotFoundError, match="neither a folder nor a dataset"):
        datasets.resolve("no_such_set", root=tmp_path)


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
    expected = [("a", folder / "a.JPG"), ("b", folder / "b.png"), ("c", folder / "c.tiff"),
                ("d", folder / "d.bmp")]
    assert datasets.resolve(str(folder)) == expected
    assert datasets.resolve(folder) == expected
    monkeypatch.chdir(tmp_path)
    # A plain word that is no dataset under the root but a folder here is that folder.
    assert datasets.resolve("mine", root=tmp_path / "root") == [
        (name, Path("mine") / path.name) for name, path in expected
    ]
    assert datasets.resolve("./mine") == [(n, Path("mine") / p.name) for n, p in expected]


def test_resolve_folder_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="does not exist"):
        datasets.resolve(tmp_path / "missing")
    with pytest.raises(FileNotFoundError, match="no image files"):
        datasets.resolve(tmp_path)
    _write_png(tmp_path / "x.png", 0)
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(tmp_path / "x.jpg")
    with pytest.raises(ValueError, match="x.jpg, x.png"):
        datasets.resolve(tmp_path)


def test_load_images(tmp_path: Path) -> None:
    pixels = _write_png(tmp_path / "img.png", 3, size=(6, 7))
    ((name, image),) = datasets.load_images(tmp_path)
    assert name == "img"
    assert image.shape == (3, 6, 7)
    assert str(image.dtype) == "torch.float32"
    np.testing.assert_allclose(image.permute(1, 2, 0).numpy() * 255, pixels, atol=1e-4)


def test_default_images_need_no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("default_images() tried to download")

    monkeypatch.setattr(urllib.request, "urlopen", refuse)
    monkeypatch.setattr(socket.socket, "connect", refuse)
    images = datasets.default_images()
    assert len(images) >= 4
    names = [name for name, _ in images]
    assert {"skimage/astronaut", "skimage/chelsea", "skimage/coffee", "skimage/rocket"} <= set(
        names
    )
    assert names == [n for n in datasets.DEFAULT_IMAGE_NAMES if n in names]
    for name, image in images:
        assert image.ndim == 3 and image.shape[0] == 3, name
        assert str(image.dtype) == "torch.float32", name
        assert 0.0 <= float(image.min()) and float(image.max()) <= 1.0, name
        # Colour, not greyscale stored as RGB.
        assert float((image[0] - image[1]).abs().max()) > 0.1, name
    assert datasets.load_images(None)[0][0] == names[0]


def test_default_images_match_skimage_loaders() -> None:
    import skimage.data

    ((name, image),) = datasets.default_images(["astronaut"])
    assert name == "skimage/astronaut"
    expected = skimage.data.astronaut().astype(np.float32) / 255
    np.testing.assert_array_equal(image.permute(1, 2, 0).numpy(), expected)
    with pytest.raises(ValueError, match="skimage/astronaut"):
        datasets.default_images(["camera"])
