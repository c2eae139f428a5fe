"""Finding and loading test sets and the bundled images (splitcam.data.testsets)."""

from __future__ import annotations

import socket
import urllib.parse
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from splitcam.data import registry, testsets


def _write_png(path: Path, seed: int, size: tuple[int, int] = (5, 4)) -> np.ndarray:
    pixels = np.random.default_rng(seed).integers(0, 256, (*size, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(path)
    return pixels


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
