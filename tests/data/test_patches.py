"""Tests of splitcam.data.patches: folder listing, the decode-once cache and the patch sampler."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import SHARED_DATA
from PIL import Image

from splitcam.data.images import read_image, write_image
from splitcam.data.patches import (
    ImageCache,
    PatchSampler,
    downscale,
    list_images,
    load_validation,
)

TRAIN = SHARED_DATA / "train"


def _save8(path: Path, arr: np.ndarray) -> None:
    Image.fromarray(arr).save(path)


def _rgb8(height: int, width: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


@pytest.fixture
def mixed_folder(tmp_path: Path) -> Path:
    """Three good 8-bit images, a 16-bit PNG, an RGBA PNG and three files to be skipped."""
    folder = tmp_path / "mixed"
    folder.mkdir()
    _save8(folder / "a_good.png", _rgb8(40, 48, 1))
    _save8(folder / "b_good.JPG", _rgb8(48, 40, 2))
    _save8(folder / "c_good.bmp", _rgb8(36, 36, 3))
    levels = np.zeros((40, 40, 3), np.uint16)
    levels[0, 0] = (65535, 32768, 0)
    levels[1:] = np.random.default_rng(4).integers(0, 65536, (39, 40, 3), dtype=np.uint16)
    write_image(folder / "d_deep.png", levels / 65535.0, bits=16)
    rgba = np.dstack([_rgb8(40, 40, 5), np.zeros((40, 40), np.uint8)])
    Image.fromarray(rgba, "RGBA").save(folder / "e_alpha.png")
    Image.fromarray(_rgb8(40, 40, 6)[..., 0], "L").save(folder / "x_grey.png")
    (folder / "y_corrupt.jpg").write_bytes(
        np.random.default_rng(7).integers(0, 256, 3000, dtype=np.uint8).tobytes()
    )
    _save8(folder / "z_small.png", _rgb8(20, 100, 8))
    (folder / "notes.txt").write_text("not an image, not listed\n")
    _save8(folder / ".hidden.png", _rgb8(40, 40, 9))
    return folder


def _cache(source: Path | list[Path], **kwargs: object) -> ImageCache:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ImageCache(source, **kwargs)  # type: ignore[arg-type]


def test_list_images_sorted_filtered(mixed_folder: Path) -> None:
    names = [p.name for p in list_images(mixed_folder)]
    assert names == [
        "a_good.png",
        "b_good.JPG",
        "c_good.bmp",
        "d_deep.png",
        "e_alpha.png",
        "x_grey.png",
        "y_corrupt.jpg",
        "z_small.png",
    ]


def test_list_images_missing_and_empty(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="does not exist") as exc:
        list_images(tmp_path / "nowhere")
    assert "nowhere" in str(exc.value)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "readme.txt").write_text("x")
    with pytest.raises(FileNotFoundError, match=r"no image files \(\.png .*\.bmp\)") as exc:
        list_images(empty)
    assert str(empty) in str(exc.value)


def test_cache_skips_bad_files_with_one_warning(mixed_folder: Path) -> None:
    with pytest.warns(UserWarning) as record:
        cache = ImageCache(mixed_folder, min_size=32, progress=False)
    assert len(record) == 1
    message = str(record[0].message)
    assert "skipped 3 of 8 images" in message
    assert "x_grey.png (greyscale" in message
    assert "y_corrupt.jpg (not an image file)" in message
    assert "z_small.png (100x20 is smaller than 32x32)" in message
    assert cache.names == ["a_good", "b_good", "c_good", "d_deep", "e_alpha"]
    assert [p.name for p, _ in cache.skipped] == ["x_grey.png", "y_corrupt.jpg", "z_small.png"]


def test_cache_storage_and_values(mixed_folder: Path) -> None:
    cache = _cache(mixed_folder, min_size=32, progress=False)
    # One 16-bit source makes the whole cache uint16, with 8-bit sources scaled exactly by 257.
    assert cache.dtype == np.uint16 and cache.max_value == 65535
    for arr in cache.arrays:
        assert arr.flags.c_contiguous and arr.shape[0] == 3
    assert cache.sizes.tolist() == [[40, 48], [48, 40], [36, 36], [40, 40], [40, 40]]
    deep = cache.image(cache.names.index("d_deep"))
    assert deep.dtype == torch.float32 and deep.shape == (3, 40, 40)
    assert deep[0, 0, 0] == 1.0
    assert deep[1, 0, 0] == np.float32(32768 / 65535)
    assert deep[2, 0, 0] == 0.0
    for i, path in enumerate(cache.paths):
        expected = torch.from_numpy(read_image(path)).permute(2, 0, 1)
        assert torch.equal(cache.image(i), expected), path.name
    alpha = cache.image(cache.names.index("e_alpha"))
    assert torch.equal(alpha, torch.from_numpy(_rgb8(40, 40, 5) / np.float32(255)).permute(2, 0, 1))


def test_cache_uint8_when_all_sources_8_bit(tmp_path: Path) -> None:
    for i in range(3):
        _save8(tmp_path / f"{i}.png", _rgb8(20, 24, i))
    cache = ImageCache(tmp_path, min_size=16, progress=True)
    assert cache.dtype == np.uint8 and cache.max_value == 255
    assert cache.nbytes == 3 * 3 * 20 * 24
    assert len(_cache(tmp_path, min_size=16, max_images=2)) == 2


def test_cache_nothing_usable(tmp_path: Path) -> None:
    Image.fromarray(_rgb8(40, 40, 0)[..., 0], "L").save(tmp_path / "grey.png")
    (tmp_path / "bad.jpg").write_bytes(b"\x00" * 100)
    with pytest.raises(ValueError, match="no usable images"):
        _cache(tmp_path)


def test_downscale_is_pillows_antialiased_bicubic() -> None:
    # An independent resampler: Pillow's own bicubic (antialiased when reducing) on 8-bit RGB.
    image = _rgb8(45, 61, 11)
    smooth = np.asarray(Image.fromarray(image).resize((61, 45), Image.Resampling.BOX))
    for arr in (image, smooth):
        ours = downscale(np.ascontiguousarray(arr.transpose(2, 0, 1)), 0.5)
        pillow = np.asarray(Image.fromarray(arr).resize((30, 22), Image.Resampling.BICUBIC))
        assert ours.dtype == np.uint8 and ours.shape == (3, 22, 30) and ours.flags.c_contiguous
        assert np.abs(ours.transpose(1, 2, 0).astype(int) - pillow).max() <= 1


def test_downscale_keeps_flat_images_flat_and_16_bit_range() -> None:
    flat = np.full((3, 33, 20), 65535, np.uint16)
    small = downscale(flat, 0.3)
    assert small.dtype == np.uint16 and small.shape == (3, 10, 6)
    assert (small == 65535).all()  # no overshoot past the integer range
    # A sharp step: bicubic overshoots past both ends of the range there, which must be clipped,
    # not wrapped round by the integer cast (the columns would then stop rising).
    step = np.zeros((3, 16, 40), np.uint16)
    step[..., 20:] = 65535
    rows = downscale(step, 0.5).astype(int)
    assert rows.min() == 0 and rows.max() == 65535
    assert (np.diff(rows, axis=-1) >= 0).all()
    image = _rgb8(8, 8, 3).transpose(2, 0, 1)
    assert downscale(image, 1.0) is image
    for bad in (0.0, 1.5, -0.5):
        with pytest.raises(ValueError, match="factor"):
            downscale(image, bad)


def test_cache_keeps_each_image_at_each_scale(tmp_path: Path) -> None:
    _save8(tmp_path / "big.png", _rgb8(80, 100, 0))
    _save8(tmp_path / "small.png", _rgb8(40, 60, 1))
    # small.png at half size (20x30) is below min_size: left out without a warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cache = ImageCache(tmp_path, min_size=32, scales=(1.0, 0.5), progress=False)
    assert cache.names == ["big", "big@0.5", "small"]
    assert cache.sizes.tolist() == [[80, 100], [40, 50], [40, 60]]
    assert cache.paths == [tmp_path / "big.png"] * 2 + [tmp_path / "small.png"]
    assert (len(cache), cache.files) == (3, 2)
    expected = downscale(cache.arrays[0], 0.5)
    assert np.array_equal(cache.arrays[1], expected)
    # max_images counts files, not copies.
    first = _cache(tmp_path, min_size=32, scales=(1.0, 0.5), max_images=1)
    assert first.names == ["big", "big@0.5"]
    # At half size only, small.png has no copy left: skipped, and said so.
    with pytest.warns(UserWarning, match=r"small\.png \(smaller than 32x32 at every scale\)"):
        halves = ImageCache(tmp_path, min_size=32, scales=(0.5,), progress=False)
    assert halves.names == ["big@0.5"]
    for bad in ((), (1.0, 1.0), (0.0,), (2.0,)):
        with pytest.raises(ValueError, match="scales"):
            ImageCache(tmp_path, scales=bad)


def _coordinate_image(height: int, width: int, offset: int) -> np.ndarray:
    """A 16-bit image whose pixels tell where they are: R = row, G = column, B = image id."""
    rows, cols = np.mgrid[0:height, 0:width]
    return np.stack([rows, cols, np.full_like(rows, offset)], axis=-1).astype(np.uint16)


def _all_orientations(window: np.ndarray) -> list[np.ndarray]:
    """The 8 dihedral transforms of a (C, P, P) window, built independently with np.rot90."""
    out = []
    for mirrored in (window, window[:, :, ::-1]):
        out.extend(np.rot90(mirrored, k, axes=(1, 2)) for k in range(4))
    return out


@pytest.fixture
def coordinate_cache(tmp_path: Path) -> tuple[ImageCache, dict[int, np.ndarray]]:
    images = {7: _coordinate_image(21, 30, 7), 9: _coordinate_image(34, 19, 9)}
    for key, img in images.items():
        write_image(tmp_path / f"coords{key}.png", img / 65535.0, bits=16)
    return ImageCache(tmp_path, min_size=16, progress=False), images


def test_patches_are_dihedral_windows(coordinate_cache) -> None:
    cache, images = coordinate_cache
    size = 16
    sampler = PatchSampler(cache, patch_size=size, seed=3)
    seen_orientations: set[int] = set()
    corners: dict[int, list[tuple[int, int]]] = {7: [], 9: []}
    for _ in range(25):
        batch = sampler.sample(40)
        assert batch.shape == (40, 3, size, size) and batch.dtype == torch.float32
        assert float(batch.min()) >= 0.0 and float(batch.max()) <= 1.0
        levels = np.rint(batch.numpy() * 65535).astype(np.int64)
        for patch in levels:
            key = int(patch[2, 0, 0])
            top, left = int(patch[0].min()), int(patch[1].min())
            window = images[key].transpose(2, 0, 1)[:, top : top + size, left : left + size]
            assert window.shape == (3, size, size)
            matches = [
                k for k, t in enumerate(_all_orientations(window)) if np.array_equal(t, patch)
            ]
            assert len(matches) == 1
            seen_orientations.add(matches[0])
            corners[key].append((top, left))
    assert seen_orientations == set(range(8))
    for key, found in corners.items():
        tops, lefts = zip(*found, strict=True)
        height, width = images[key].shape[:2]
        # The windows reach both borders of every image, never beyond.
        assert min(tops) == 0 and max(tops) == height - size
        assert min(lefts) == 0 and max(lefts) == width - size


def test_no_augment_gives_plain_windows(coordinate_cache) -> None:
    cache, images = coordinate_cache
    sampler = PatchSampler(cache, patch_size=16, seed=4, augment=False)
    levels = np.rint(sampler.sample(30).numpy() * 65535).astype(np.int64)
    for patch in levels:
        top, left = int(patch[0, 0, 0]), int(patch[1, 0, 0])
        window = images[int(patch[2, 0, 0])].transpose(2, 0, 1)[:, top : top + 16, left : left + 16]
        assert np.array_equal(patch, window)


def test_seed_and_rank_determinism(coordinate_cache) -> None:
    cache, _ = coordinate_cache
    first = [PatchSampler(cache, patch_size=16, seed=5).sample(8) for _ in range(2)]
    assert torch.equal(first[0], first[1])
    a = PatchSampler(cache, patch_size=16, seed=5)
    b = PatchSampler(cache, patch_size=16, seed=5)
    for _ in range(3):
        assert torch.equal(a.sample(8), b.sample(8))
    other_seed = PatchSampler(cache, patch_size=16, seed=6).sample(8)
    assert not torch.equal(other_seed, first[0])
    ranks = [PatchSampler(cache, patch_size=16, seed=5, rank=r, world_size=3) for r in range(3)]
    batches = [s.sample(8) for s in ranks]
    assert torch.equal(batches[0], first[0])
    assert not torch.equal(batches[0], batches[1])
    assert not torch.equal(batches[1], batches[2])


def test_state_dict_resumes_identical_sequence(coordinate_cache, tmp_path: Path) -> None:
    cache, _ = coordinate_cache
    uninterrupted = PatchSampler(cache, patch_size=16, seed=11)
    reference = [uninterrupted.sample(6) for _ in range(5)]

    before = PatchSampler(cache, patch_size=16, seed=11)
    for _ in range(2):
        before.sample(6)
    state = before.state_dict()
    assert state["generator_state"].dtype == torch.uint8
    torch.save(state, tmp_path / "sampler.pt")

    resumed = PatchSampler(cache, patch_size=16, seed=999)
    resumed.load_state_dict(torch.load(tmp_path / "sampler.pt", weights_only=True))
    for expected in reference[2:]:
        assert torch.equal(resumed.sample(6), expected)

    bare = PatchSampler(cache, patch_size=16, seed=0)
    bare.load_state_dict(state["generator_state"])
    assert torch.equal(bare.sample(6), reference[2])

    wrong_rank = PatchSampler(cache, patch_size=16, seed=11, rank=1, world_size=2)
    with pytest.raises(ValueError, match="rank=0"):
        wrong_rank.load_state_dict(state)


def test_sampler_argument_errors(coordinate_cache) -> None:
    cache, _ = coordinate_cache
    with pytest.raises(ValueError, match="smallest image side 19"):
        PatchSampler(cache, patch_size=20)
    with pytest.raises(ValueError, match="rank"):
        PatchSampler(cache, patch_size=16, rank=2, world_size=2)
    with pytest.raises(ValueError, match="batch_size"):
        PatchSampler(cache, patch_size=16).sample(0)


def test_load_validation(mixed_folder: Path) -> None:
    with pytest.warns(UserWarning, match="skipped 2 of"):
        pairs = load_validation(mixed_folder)
    names = [name for name, _ in pairs]
    assert names == ["a_good", "b_good", "c_good", "d_deep", "e_alpha", "z_small"]
    for name, image in pairs:
        expected = read_image(next(mixed_folder.glob(f"{name}.*")))
        assert image.dtype == torch.float32
        assert torch.equal(image, torch.from_numpy(expected).permute(2, 0, 1))
    assert len(_validation_quiet(mixed_folder, 2)) == 2


def _validation_quiet(folder: Path, max_images: int) -> list[tuple[str, torch.Tensor]]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_validation(folder, max_images=max_images)


@pytest.mark.skipif(not TRAIN.is_dir(), reason="shared training images not available")
def test_real_training_images() -> None:
    cache = ImageCache(TRAIN, max_images=3, progress=False)
    assert cache.dtype == np.uint8 and len(cache) == 3
    batch = PatchSampler(cache, seed=0).sample(80)
    assert batch.shape == (80, 3, 64, 64) and batch.dtype == torch.float32
    assert 0.0 <= float(batch.min()) and float(batch.max()) <= 1.0
    assert float(batch.std()) > 0.01


def test_partial_periods_cut_batches_part_way_through_a_period(coordinate_cache) -> None:
    cache, images = coordinate_cache
    plain = PatchSampler(cache, patch_size=16, seed=7, augment=False)
    cut = PatchSampler(cache, patch_size=16, seed=7, augment=False, partial=0.5, period=(2, 3))
    shapes = set()
    for _ in range(60):
        batch = cut.sample(4)
        h, w = batch.shape[-2:]
        shapes.add((h, w))
        # Rows end part-way through a period of 2, columns of 3 (1 or 2 cut from the 5 whole
        # periods of 3 in 16), or not at all.
        assert h in (16, 15) and w in (15, 14, 13)
        # What is left is the top-left of a plain window of that image.
        levels = np.rint(batch.numpy() * 65535).astype(np.int64)
        for patch in levels:
            top, left = int(patch[0, 0, 0]), int(patch[1, 0, 0])
            image = images[int(patch[2, 0, 0])].transpose(2, 0, 1)
            assert np.array_equal(patch, image[:, top : top + h, left : left + w])
    # Every combination turns up, whole batches included.
    assert shapes == {(a, b) for a in (16, 15) for b in (15, 14, 13)}
    # partial=0 draws nothing extra: the plain sequence is unchanged.
    again = PatchSampler(cache, patch_size=16, seed=7, augment=False, partial=0.0, period=(2, 2))
    assert torch.equal(again.sample(4), plain.sample(4))
    # ... and a period that does not divide the patch gives whole periods only: the same
    # windows, less the column that would end part-way through a period of 3.
    whole = PatchSampler(cache, patch_size=16, seed=7, augment=False, partial=0.0, period=(1, 3))
    reference = PatchSampler(cache, patch_size=16, seed=7, augment=False)
    for _ in range(3):
        assert torch.equal(whole.sample(4), reference.sample(4)[..., :15])
    with pytest.raises(ValueError, match="partial"):
        PatchSampler(cache, patch_size=16, partial=1.5)
    with pytest.raises(ValueError, match="period"):
        PatchSampler(cache, patch_size=16, period=(2, 16))


# --- images held on the device: the same patches, built by one gather ---------------------------

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _eight_bit_cache(tmp_path: Path) -> ImageCache:
    """8-bit photos of odd sizes in both orientations, each also at half size."""
    for i, (h, w) in enumerate([(37, 53), (53, 37), (40, 41)]):
        _save8(tmp_path / f"p{i}.png", _rgb8(h, w, 20 + i))
    return ImageCache(tmp_path, min_size=16, progress=False, scales=(1.0, 0.5))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("augment", [True, False])
def test_device_images_give_the_host_patches(coordinate_cache, tmp_path, device, augment) -> None:
    """One seed, the same patches whether the images sit on a device or not (the CPU stands in
    for the device here): 16-bit and 8-bit images, half-size copies, every orientation, patches
    ending part-way through a period."""
    for cache in (coordinate_cache[0], _eight_bit_cache(tmp_path)):
        settings = {"patch_size": 16, "seed": 13, "augment": augment, "partial": 0.5}
        host = PatchSampler(cache, **settings, period=(2, 3))
        held = PatchSampler(cache, **settings, period=(2, 3), device=device)
        assert held.images.nbytes == cache.nbytes and host.images is None
        assert held.device.type == device and host.device.type == "cpu"
        for _ in range(30):
            a, b = host.sample(24), held.sample(24)
            assert b.device.type == device and b.dtype == torch.float32
            assert a.shape == b.shape and torch.equal(a, b.cpu())
        assert torch.equal(host.generator.get_state(), held.generator.get_state())


def _orientation(patch: np.ndarray, images: dict[int, np.ndarray], size: int) -> tuple:
    """(image id, top, left, dihedral transforms) of a coordinate patch, found by search: a cut
    patch (part-way through a period) may have lost the window's first rows or columns."""
    key = int(patch[2, 0, 0])
    image = images[key].transpose(2, 0, 1)
    h, w = patch.shape[1:]
    lost = size - min(h, w)  # rows or columns, whichever way the window was turned
    for top in range(max(0, int(patch[0].min()) - lost), int(patch[0].min()) + 1):
        for left in range(max(0, int(patch[1].min()) - lost), int(patch[1].min()) + 1):
            window = image[:, top : top + size, left : left + size]
            if window.shape[1:] != (size, size):
                continue
            found = [
                k
                for k, t in enumerate(_all_orientations(window))
                if np.array_equal(t[:, :h, :w], patch)
            ]
            if found:
                return key, top, left, found
    raise AssertionError("patch not found in its image")


def test_device_sampling_rates(coordinate_cache) -> None:
    """On the device path, position classes within a period, the 8 orientations and partial
    periods occur at the rates the host path draws them with: classes in proportion to the
    windows starting in them, orientations 1/8 each, a cut in rows (columns) half the time."""
    cache, images = coordinate_cache
    size, period, batches, per_batch = 16, (2, 3), 150, 20
    sampler = PatchSampler(
        cache, patch_size=size, seed=21, partial=0.5, period=period, device="cpu"
    )
    classes: dict[tuple[int, int, int], int] = {}
    orientations = np.zeros(8)
    cut_rows = cut_cols = 0
    for _ in range(batches):
        batch = sampler.sample(per_batch)
        h, w = batch.shape[-2:]
        cut_rows += h < size
        cut_cols += w < size - size % period[1]
        levels = np.rint(batch.numpy() * 65535).astype(np.int64)
        for patch in levels[:5]:  # the orientation search is slow; 5 per batch is enough
            key, top, left, found = _orientation(patch, images, size)
            orientations[found[0]] += 1 / len(found)
            cls = (key, top % period[0], left % period[1])
            classes[cls] = classes.get(cls, 0) + 1
    n = batches * 5
    # Orientations: chi-square against 1/8 each (7 degrees of freedom; 99.9 %: 24.3).
    expected = n / 8
    assert ((orientations - expected) ** 2 / expected).sum() < 24.3
    # Position classes: each image is drawn half the time, and within it a class in proportion
    # to the window positions in it.
    chi = 0.0
    for key, img in images.items():
        rows, cols = img.shape[0] - size + 1, img.shape[1] - size + 1
        for r in range(period[0]):
            for c in range(period[1]):
                share = len(range(r, rows, period[0])) * len(range(c, cols, period[1]))
                expected = n * 0.5 * share / (rows * cols)
                chi += (classes.get((key, r, c), 0) - expected) ** 2 / expected
    assert chi < 32.9  # 11 degrees of freedom, 99.95 %
    # Partial periods: a binomial(150, 0.5) each, within 4 standard deviations.
    for hits in (cut_rows, cut_cols):
        assert abs(hits - batches / 2) < 4 * (batches / 4) ** 0.5


def test_device_images_of_16_bit_samples_above_32767(tmp_path: Path) -> None:
    """16-bit samples travel as int16 bits: values above 32767 must come back unsigned."""
    img = np.full((20, 20, 3), 65000, np.uint16)
    img[..., 1] = 40000
    write_image(tmp_path / "bright.png", img / 65535.0, bits=16)
    cache = ImageCache(tmp_path, min_size=16, progress=False)
    patch = PatchSampler(cache, patch_size=16, device="cpu").sample(2)
    assert torch.allclose(patch[:, 0], torch.tensor(65000 / 65535))
    assert torch.allclose(patch[:, 1], torch.tensor(40000 / 65535))


def test_hard_patches_follow_the_stated_probabilities(tmp_path: Path) -> None:
    """A flat image (no gradient energy) and a noisy one: one patch picked among four
    candidates, each candidate from either image with probability 1/2. With weight h on detail,
    a batch of one comes from the noisy image with probability
    sum_k C(4, k) / 16 * (k (1 - h) / 4 + h) over k >= 1 noisy candidates."""
    _save8(tmp_path / "a_flat.png", np.full((32, 32, 3), 128, np.uint8))
    _save8(tmp_path / "b_noise.png", _rgb8(32, 32, 5))
    cache = ImageCache(tmp_path, min_size=16, progress=False)
    from math import comb

    for h in (0.0, 0.5, 1.0):
        expect = sum(comb(4, k) / 16 * (k * (1 - h) / 4 + h) for k in range(1, 5))
        sampler = PatchSampler(cache, patch_size=16, seed=1, hard=h)
        noisy = [float(sampler.sample(1).std()) > 0 for _ in range(3000)]
        assert abs(np.mean(noisy) - expect) < 0.03, (h, np.mean(noisy), expect)
    # Off, it draws exactly what it drew before the option existed.
    plain, off = (
        PatchSampler(cache, patch_size=16, seed=2),
        PatchSampler(cache, patch_size=16, seed=2),
    )
    off.hard = 0.0
    assert torch.equal(plain.sample(4), off.sample(4))
    with pytest.raises(ValueError, match="hard"):
        PatchSampler(cache, patch_size=16, hard=1.5)


def test_hard_patches_resume_their_sequence(coordinate_cache) -> None:
    """Chosen by detail, the batches still depend only on the generator's state."""
    cache, _ = coordinate_cache
    first = PatchSampler(cache, patch_size=8, seed=3, hard=0.7)
    first.sample(5)
    state = first.state_dict()
    expect = first.sample(5)
    second = PatchSampler(cache, patch_size=8, seed=3, hard=0.7)
    second.load_state_dict(state)
    assert torch.equal(second.sample(5), expect)
