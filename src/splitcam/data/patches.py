"""Training and validation data: image folders, a decode-once cache and a random patch sampler.

Training draws random square patches, each in one of the 8 orientations of the dihedral group
(4 rotations, each with or without a mirror flip). Decoding a JPEG costs milliseconds while a
training step needs ~80 patches, so :class:`ImageCache` decodes every image once and keeps the
integer samples in memory; :class:`PatchSampler` then only copies strided views and converts.

On an accelerator the same images are copied once into device memory (:class:`DeviceImages`,
still as integers) and a batch is cut out of them by one gather on the device, so training draws
its data with no host copy and no loop over patches.

Randomness comes only from the sampler's own :class:`torch.Generator` on the CPU: the same seed
gives the same batches wherever the images are held, and :meth:`PatchSampler.state_dict` lets a
resumed run draw the batches an uninterrupted run would have drawn.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .colour import ColourMix
from .images import IMAGE_SUFFIXES, ImageReadError, decode_image
from .registry import dataset_folder
from .scales import valid_scales

__all__ = [
    "DeviceImages",
    "ImageCache",
    "MinedWindows",
    "PatchSampler",
    "dihedral",
    "downscale",
    "list_images",
    "load_validation",
]

#: Candidates drawn per patch when patches are chosen by detail (``PatchSampler(hard=)``).
HARD_POOL = 4

# Ranks seed their generators at seed + _RANK_STRIDE * rank: a prime far above any seed sweep.
_RANK_STRIDE = 1_000_003
# Below this many files decoding is quick and a progress bar is only noise.
_PROGRESS_MIN_IMAGES = 32


def list_images(folder: str | os.PathLike[str]) -> list[Path]:
    """The image files of a folder, sorted by name.

    Files whose suffix is one of ``.png .jpg .jpeg .tif .tiff .bmp`` (any case) count; sub-folders
    are not searched and hidden files (names starting with ``.``) are ignored.

    Args:
        folder: The folder to list, or the name of a downloaded dataset
            (:func:`~splitcam.data.registry.dataset_folder`: ``train`` is the training photos).

    Returns:
        Paths of the image files, sorted.

    Raises:
        FileNotFoundError: The folder does not exist, is not a folder, or holds no image files.
    """
    folder = dataset_folder(folder)
    accepted = " ".join(IMAGE_SUFFIXES)
    if not folder.exists():
        raise FileNotFoundError(f"image folder '{folder}' does not exist")
    if not folder.is_dir():
        raise FileNotFoundError(f"'{folder}' is not a folder (expected a folder of images)")
    paths = sorted(
        p
        for p in folder.iterdir()
        if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".") and p.is_file()
    )
    if not paths:
        raise FileNotFoundError(f"no image files ({accepted}) in folder '{folder}'")
    return paths


def _resolve_paths(source: str | os.PathLike[str] | Iterable[str | os.PathLike[str]]) -> list[Path]:
    if isinstance(source, (str, os.PathLike)):
        return list_images(source)
    paths = [Path(p) for p in source]
    if not paths:
        raise ValueError("no image files given")
    return paths


def _warn_skipped(skipped: Sequence[tuple[Path, str]], total: int, where: str) -> None:
    """One warning for all skipped files, so a bad folder does not flood the log."""
    if not skipped:
        return
    details = "; ".join(f"{p.name} ({reason})" for p, reason in skipped)
    warnings.warn(
        f"skipped {len(skipped)} of {total} images in {where}: {details}", UserWarning, stacklevel=3
    )


def _describe(paths: Sequence[Path], source: Any) -> str:
    if isinstance(source, (str, os.PathLike)):
        return f"'{source}'"
    parents = {p.parent for p in paths}
    return f"'{parents.pop()}'" if len(parents) == 1 else "the given files"


def _check_cache_args(
    min_size: int, max_images: int | None, scales: Sequence[float]
) -> tuple[float, ...]:
    """:class:`ImageCache`'s arguments checked; its scales as a tuple of floats."""
    if min_size < 1:
        raise ValueError(f"min_size must be positive, got {min_size}")
    if max_images is not None and max_images < 1:
        raise ValueError(f"max_images must be positive or None, got {max_images}")
    if not valid_scales(scales):
        raise ValueError(f"scales must be distinct factors in (0, 1], got {list(scales)}")
    return tuple(float(f) for f in scales)


def _copies(
    image: np.ndarray, scales: tuple[float, ...], min_size: int
) -> list[tuple[float, np.ndarray]]:
    """``(factor, image at that size)`` for each of ``scales`` at which both sides are still at
    least ``min_size``."""
    copies = [(factor, downscale(image, factor)) for factor in scales]
    return [(factor, copy) for factor, copy in copies if min(copy.shape[1:]) >= min_size]


class ImageCache:
    """Every usable image of a folder, decoded once and kept in memory as integers.

    Images are stored channel-first and contiguous as uint8 when every source is 8-bit. If any
    source is 16-bit, all are stored as uint16 and 8-bit sources are multiplied by 257: since
    65535 = 255 * 257 this is exact, and ``v * 257 / 65535`` and ``v / 255`` round to the same
    float32. Integers take a quarter (uint8) or half (uint16) of the memory of float32; the
    432 BSDS500 training images take 200 MB as uint8.

    Images that are greyscale, corrupt, unreadable or smaller than ``min_size`` in either
    dimension are skipped with one warning naming every skipped file and the reason.

    Args:
        source: A folder (see :func:`list_images`) or a list of image files.
        min_size: Smallest accepted height and width, normally the patch size.
        max_images: Keep at most this many usable files (the first ones in sorted order).
        progress: Show a tqdm progress bar while decoding (only for 32 images or more).
        scales: Keep each image at each of these sizes (factors in ``(0, 1]``, see
            :func:`downscale`), each copy one more image to draw patches from; a copy smaller
            than ``min_size`` is left out silently, a file with no copy left is skipped.
            ``(1.0,)``: the images as they are.

    Attributes:
        arrays: The images, each a C-contiguous ``(3, H, W)`` uint8 or uint16 numpy array.
        names: File name stems, parallel to ``arrays`` (``stem@0.5`` for a copy at half size).
        paths: Source files, parallel to ``arrays`` (a file once per scale it was kept at).
        skipped: ``(path, reason)`` for every file that was skipped.
        max_value: 255 for uint8 storage, 65535 for uint16.

    Raises:
        FileNotFoundError: See :func:`list_images`.
        ValueError: No usable image is left, or bad arguments.
    """

    def __init__(
        self,
        source: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
        *,
        min_size: int = 64,
        max_images: int | None = None,
        progress: bool = True,
        scales: Sequence[float] = (1.0,),
    ) -> None:
        scales = _check_cache_args(min_size, max_images, scales)
        candidates = _resolve_paths(source)
        where = _describe(candidates, source)
        arrays: list[np.ndarray] = []
        paths: list[Path] = []
        names: list[str] = []
        skipped: list[tuple[Path, str]] = []
        kept = 0
        iterator: Iterable[Path] = candidates
        if progress and len(candidates) >= _PROGRESS_MIN_IMAGES:
            from tqdm.auto import tqdm

            iterator = tqdm(candidates, desc="decoding images", unit="img", leave=False)
        for path in iterator:
            if max_images is not None and kept >= max_images:
                break
            try:
                arr = decode_image(path)
            except ImageReadError as exc:
                skipped.append((path, exc.reason))
                continue
            height, width = arr.shape[:2]
            if height < min_size or width < min_size:
                skipped.append((path, f"{width}x{height} is smaller than {min_size}x{min_size}"))
                continue
            # Channel-first right away, so only one image at a time exists in both layouts.
            copies = _copies(np.ascontiguousarray(arr.transpose(2, 0, 1)), scales, min_size)
            if not copies:
                skipped.append((path, f"smaller than {min_size}x{min_size} at every scale"))
                continue
            kept += 1
            for factor, copy in copies:
                arrays.append(copy)
                paths.append(path)
                names.append(path.stem if factor == 1 else f"{path.stem}@{factor:g}")
        if hasattr(iterator, "close"):
            iterator.close()
        _warn_skipped(skipped, kept + len(skipped), where)
        if not arrays:
            raise ValueError(f"no usable images in {where}: all {len(skipped)} were skipped")

        wide = any(a.dtype == np.uint16 for a in arrays)
        self.max_value: int = 65535 if wide else 255
        if wide:
            for i, arr in enumerate(arrays):
                if arr.dtype == np.uint8:
                    arrays[i] = arr.astype(np.uint16) * np.uint16(257)
        self.arrays: list[np.ndarray] = arrays
        self.paths: list[Path] = paths
        self.names: list[str] = names
        self.files: int = kept
        """Number of files the images came from (``len(self)`` counts each copy at each scale)."""
        self.skipped: list[tuple[Path, str]] = skipped
        self.sizes = torch.tensor([a.shape[1:] for a in self.arrays], dtype=torch.int64)
        """``(N, 2)`` int64 tensor of (height, width) per image."""

    def __len__(self) -> int:
        return len(self.arrays)

    @property
    def dtype(self) -> np.dtype:
        """Storage dtype, uint8 or uint16."""
        return self.arrays[0].dtype

    @property
    def nbytes(self) -> int:
        """Memory taken by the cached pixels, in bytes."""
        return sum(a.nbytes for a in self.arrays)

    def image(self, index: int) -> torch.Tensor:
        """One cached image as float32 values in [0, 1] (the values :func:`read_image` gives).

        Shape:
            Output: ``(3, H, W)``.
        """
        values = np.divide(self.arrays[index], np.float32(self.max_value), dtype=np.float32)
        return torch.from_numpy(values)


def downscale(image: np.ndarray, factor: float) -> np.ndarray:
    """An integer image made smaller by ``factor``, antialiased, in its own dtype.

    Resampled with torch's antialiased bicubic filter (Pillow's, for 8-bit images; Pillow itself
    does not resample 16-bit colour), rounded and clipped back to the integer range, so 8- and
    16-bit images take the same path. The values are resampled as stored (sRGB for the usual
    8-bit photo), like a camera's own downscaled JPEG.

    Args:
        image: ``(3, H, W)`` uint8 or uint16.
        factor: In ``(0, 1]``; each side becomes ``max(1, round(side * factor))``.

    Returns:
        ``(3, h, w)`` C-contiguous array of the same dtype (``image`` itself for factor 1).
    """
    if not 0 < factor <= 1:
        raise ValueError(f"downscale factor must be in (0, 1], got {factor}")
    if factor == 1:
        return image
    height, width = image.shape[1:]
    size = (max(1, round(height * factor)), max(1, round(width * factor)))
    x = torch.from_numpy(image.astype(np.float32))[None]
    y = torch.nn.functional.interpolate(x, size=size, mode="bicubic", antialias=True)[0]
    top = float(np.iinfo(image.dtype).max)
    return np.ascontiguousarray(y.round().clamp(0, top).numpy().astype(image.dtype))


def downscaled(image: np.ndarray, factor: float) -> torch.Tensor:
    """A decoded photo, ``(H, W, 3)`` 8- or 16-bit, at ``factor`` of its size
    (:func:`downscale`) as a ``(3, h, w)`` float32 tensor in [0, 1] (divided by its dtype's
    largest value): what the gate and the colour studies score."""
    top = float(np.iinfo(image.dtype).max)
    small = downscale(np.ascontiguousarray(image.transpose(2, 0, 1)), factor)
    return torch.from_numpy(small.astype(np.float32) / np.float32(top))


def dihedral(patch: np.ndarray, code: int) -> np.ndarray:
    """A view of ``patch`` in dihedral orientation ``code`` (0-7).

    The three bits of ``code`` select, in this order: swap the two spatial axes (4), reverse the
    rows (2), reverse the columns (1). The 8 combinations are the 8 distinct symmetries of a
    square: the 4 rotations, with and without a mirror flip.

    Shape:
        patch: ``(C, P, P)``; output: the same (a strided view, no copy).
    """
    if code & 4:
        patch = patch.transpose(0, 2, 1)
    if code & 2:
        patch = patch[:, ::-1]
    if code & 1:
        patch = patch[:, :, ::-1]
    return patch


class DeviceImages:
    """An :class:`ImageCache`'s images copied once to a device, as integers, in one flat buffer.

    Why our own rather than a padded ``(N, 3, H, W)`` tensor: the training photos come in both
    orientations (481x321 and 321x481) and, with ``data.scales``, at several sizes, so padding to
    the largest would take 1.5-2x the memory; a flat buffer with each image's offset and size
    takes exactly the cache's bytes (the 432 BSDS500 photos: 200 MB) and is read by one gather.

    16-bit images are stored as int16 with the same bits (torch gathers no uint16) and read back
    with ``& 0xFFFF``.

    Args:
        cache: The decoded images.
        device: Where to hold them.

    Attributes:
        flat: ``(total,)`` uint8 or int16 samples of every image, channel-first, one after another.
        offsets: ``(N,)`` int64 index of each image's first sample in ``flat``.
        heights, widths: ``(N,)`` int64 sizes.
        max_value: 255 or 65535, as the cache's.
    """

    def __init__(self, cache: ImageCache, device: torch.device | str) -> None:
        wide = cache.dtype == np.uint16
        parts = [
            torch.from_numpy(a.view(np.int16) if wide else a).reshape(-1) for a in cache.arrays
        ]
        sizes = [part.numel() for part in parts]
        self.device = torch.device(device)
        self.flat = torch.cat(parts).to(self.device)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        self.offsets = torch.from_numpy(starts).to(self.device)
        self.heights = cache.sizes[:, 0].to(self.device)
        self.widths = cache.sizes[:, 1].to(self.device)
        self.max_value = cache.max_value
        self.wide = wide
        # Each integer's value in [0, 1], divided on the host as ImageCache's arrays are: a
        # division on the device may multiply by the reciprocal instead (CUDA does), which
        # differs in the last bit, so the same seed would not give the same patches.
        levels = np.arange(cache.max_value + 1, dtype=np.float32)
        self.values = torch.from_numpy(levels / np.float32(cache.max_value)).to(self.device)

    @property
    def nbytes(self) -> int:
        """Device memory the samples take, in bytes."""
        return self.flat.numel() * self.flat.element_size()

    def patches(
        self, index: torch.Tensor, corner: torch.Tensor, code: torch.Tensor, size: int
    ) -> torch.Tensor:
        """The patches :meth:`PatchSampler.draw` chose, cut out by one gather on the device.

        The same values as :func:`dihedral` of each window (tested against it): for output pixel
        ``(i, j)`` the window's row is ``j'`` and column ``i'`` when the axes are swapped (bit 4),
        else ``(i', j')``, where ``i' = size - 1 - i`` if rows are reversed (bit 2) and
        ``j' = size - 1 - j`` if columns are (bit 1).

        Shape:
            index, code: ``(B,)``; corner: ``(B, 2)``; output: ``(B, 3, size, size)`` float32
            in [0, 1] on the device.
        """
        dev = self.device
        index, corner, code = (t.to(dev, non_blocking=True) for t in (index, corner, code))
        b = index.numel()
        ar = torch.arange(size, device=dev)
        i, j = ar.view(1, size, 1), ar.view(1, 1, size)
        code = code.view(b, 1, 1)
        ii = torch.where((code & 2).bool(), size - 1 - i, i)
        jj = torch.where((code & 1).bool(), size - 1 - j, j)
        swap = (code & 4).bool()
        rows = torch.where(swap, jj, ii) + corner[:, 0].view(b, 1, 1)
        cols = torch.where(swap, ii, jj) + corner[:, 1].view(b, 1, 1)
        width = self.widths[index].view(b, 1, 1)
        plane = (self.heights[index] * self.widths[index]).view(b, 1, 1, 1)
        pixel = (self.offsets[index].view(b, 1, 1) + rows * width + cols).unsqueeze(1)
        samples = self.flat[pixel + torch.arange(3, device=dev).view(1, 3, 1, 1) * plane]
        values = (samples.int() & 0xFFFF) if self.wide else samples
        return self.values[values.long()]


@dataclass(frozen=True)
class MinedWindows:
    """Windows chosen in advance (for example where a network errs most in colour:
    :func:`splitcam.training.mining.mine_colour`) that a :class:`PatchSampler` draws from with
    probability ``share`` per patch.

    ``index``, ``corner`` and ``code`` are as :meth:`PatchSampler.draw` returns them, for
    patches of side ``patch_size``; ``score`` is what chose them (kept for the record).
    """

    index: torch.Tensor
    corner: torch.Tensor
    code: torch.Tensor
    score: torch.Tensor
    patch_size: int
    share: float

    def __post_init__(self) -> None:
        n = len(self.index)
        if n == 0 or any(len(t) != n for t in (self.corner, self.code, self.score)):
            raise ValueError("mined windows need as many corners, codes and scores as indices")
        if not 0.0 <= self.share <= 1.0:
            raise ValueError(f"share must be a probability in [0, 1], got {self.share}")

    def tensors(self) -> dict[str, torch.Tensor]:
        """The windows as tensors to save (``from_tensors`` reads them back)."""
        return {"index": self.index, "corner": self.corner, "code": self.code, "score": self.score}

    @classmethod
    def from_tensors(
        cls, tensors: dict[str, torch.Tensor], patch_size: int, share: float
    ) -> MinedWindows:
        return cls(
            tensors["index"].long(),
            tensors["corner"].long(),
            tensors["code"].long(),
            tensors["score"],
            patch_size,
            share,
        )


class PatchSampler:
    """Random square patches in random dihedral orientations, drawn from an :class:`ImageCache`.

    Every patch picks an image uniformly (not weighted by image area), a window uniformly among
    all positions inside that image, and one of the 8 orientations uniformly. All randomness comes
    from the sampler's own generator: a fixed number of draws per batch, so the sequence of
    batches depends only on the seed, the rank and the number of batches drawn before.

    For distributed training every rank builds a sampler with the same ``seed`` and its own
    ``rank``; the generator is seeded with ``seed + 1_000_003 * rank``, so ranks draw different
    patches. ``world_size`` is only checked (``0 <= rank < world_size``): each rank draws its own
    full batch.

    Args:
        cache: The images to draw from.
        patch_size: Side of the square patches, at most the smallest image side.
        seed: Seed of the generator.
        rank: Index of this process among ``world_size`` processes.
        world_size: Number of processes drawing patches.
        augment: Apply the random dihedral transforms (off: every patch in its original
            orientation; the transforms are still drawn, so the windows do not change).
        partial: Probability that a batch ends part-way through a period in its rows, and
            independently in its columns: the last ``r`` rows (columns) of its whole periods
            are cut off, ``r`` uniform in ``1 .. period - 1``. (Patches are first cut to whole
            periods: a 64-pixel side holds 21 periods of 3 and one column, which is cut.) An
            image whose size is not a multiple of the period ends part-way, and a network
            trained on whole periods only never saw such an edge (on the 481x321 held-out
            images it got the last column badly wrong). 0 draws nothing extra, so the patch
            sequence is the same as without this option.
        period: The sensor's period (rows, columns): patches hold whole periods of it, and
            ``partial`` cuts into it.
        hard: Weight of detail in choosing patches (0: uniform). Each patch is picked among
            :data:`HARD_POOL` patches drawn as above, with probability ``(1 - hard) / HARD_POOL
            + hard * e / sum(e)``, ``e`` each candidate's gradient energy (mean squared
            difference of neighbouring pixels): patches with texture and edges, where
            reconstruction errs most, come more often, and flat ones still come. The
            candidates of one batch are drawn without replacement.
        colour: Chroma augmentation and dead-leaves scenes mixed into each batch after it is
            cut (:class:`~splitcam.data.colour.ColourMix`), drawn on the same generator; None
            or an inactive mix draws nothing, so the patch sequence is unchanged.
        mined: Windows chosen in advance: each patch is one of them (uniformly) with
            probability ``mined.share``, instead of its random window (two extra draws per
            patch); None draws nothing, so the patch sequence is unchanged.
        device: Hold the images on this device (:class:`DeviceImages`) and build each batch
            there by one gather; None: build batches on the host from the cache's arrays, which
            on a CPU is faster (``benchmarks/bench_data.py``). Either way the random choices are
            drawn on the CPU generator, so one seed gives the same patches.

    Raises:
        ValueError: Bad patch size, rank, world size, ``partial`` or ``period``.
    """

    def __init__(
        self,
        cache: ImageCache,
        *,
        patch_size: int = 64,
        seed: int = 0,
        rank: int = 0,
        world_size: int = 1,
        augment: bool = True,
        partial: float = 0.0,
        period: tuple[int, int] = (1, 1),
        hard: float = 0.0,
        device: torch.device | str | None = None,
        colour: ColourMix | None = None,
        mined: MinedWindows | None = None,
    ) -> None:
        if not 0.0 <= hard <= 1.0:
            raise ValueError(f"hard must be in [0, 1], got {hard}")
        if patch_size < 1:
            raise ValueError(f"patch_size must be positive, got {patch_size}")
        if not 0.0 <= partial <= 1.0:
            raise ValueError(f"partial must be a probability in [0, 1], got {partial}")
        if len(period) != 2 or min(period) < 1 or max(period) >= patch_size:
            raise ValueError(f"period must be two sides in 1 .. patch_size - 1, got {period}")
        if world_size < 1 or not 0 <= rank < world_size:
            raise ValueError(f"need 0 <= rank < world_size, got rank={rank}, world={world_size}")
        smallest = int(cache.sizes.min())
        if patch_size > smallest:
            raise ValueError(
                f"patch_size {patch_size} exceeds the smallest image side {smallest}; build the "
                f"cache with min_size={patch_size}"
            )
        self.cache = cache
        self.patch_size = patch_size
        self.seed = seed
        self.rank = rank
        self.world_size = world_size
        self.augment = augment
        self.partial = float(partial)
        self.hard = float(hard)
        self.period = (int(period[0]), int(period[1]))
        self.generator = torch.Generator(device="cpu")
        self.generator.manual_seed(seed + _RANK_STRIDE * rank)
        # Number of window positions along each axis, per image.
        self._positions = (cache.sizes - patch_size + 1).to(torch.float64)
        #: The images on the device batches are built on, or None (built on the host).
        self.images = DeviceImages(cache, device) if device is not None else None
        #: Colour shown beyond the photos' (chroma augmentation, dead leaves), or None.
        self.colour = colour if colour is not None and colour.active else None
        #: Windows drawn from with probability ``mined.share``, or None.
        self.mined: MinedWindows | None = None
        self.use_mined(mined)

    def use_mined(self, mined: MinedWindows | None) -> None:
        """Draw from ``mined`` from the next batch on (see ``mined`` in the class).

        Raises:
            ValueError: Windows of another patch size, or of images this sampler lacks.
        """
        if mined is not None:
            inside = (mined.index >= 0) & (mined.index < len(self.cache))
            if mined.patch_size != self.patch_size or not bool(inside.all()):
                raise ValueError(
                    f"mined windows are {mined.patch_size}-pixel windows of other images than "
                    f"this sampler's {self.patch_size}-pixel patches of {len(self.cache)} images"
                )
        self.mined = mined if mined is not None and mined.share > 0 else None

    @property
    def whole_periods(self) -> tuple[int, int]:
        """The patch's rows and columns cut to whole periods (what every batch is cut to before
        ``partial`` cuts further)."""
        rows, cols = (self.patch_size - self.patch_size % side for side in self.period)
        return rows, cols

    @property
    def device(self) -> torch.device:
        """Where :meth:`sample` returns its batches."""
        return self.images.device if self.images is not None else torch.device("cpu")

    def draw(self, batch_size: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Draw the random choices of one batch without building it.

        Returns:
            ``(index, corner, code)``: image index ``(B,)``, window top-left corner ``(B, 2)``
            as (row, column), and dihedral code 0-7 ``(B,)``; all int64.
        """
        if batch_size < 1:
            raise ValueError(f"batch_size must be positive, got {batch_size}")
        gen = self.generator
        index = torch.randint(len(self.cache), (batch_size,), generator=gen)
        # Uniform in [0, 1) times the number of positions, floored: unbiased for any image size.
        unit = torch.rand((batch_size, 2), generator=gen, dtype=torch.float64)
        positions = self._positions[index]
        corner = torch.minimum((unit * positions).long(), positions.long() - 1)
        code = torch.randint(8, (batch_size,), generator=gen)
        return index, corner, code

    def sample(self, batch_size: int) -> torch.Tensor:
        """Draw a batch of patches.

        Args:
            batch_size: Number of patches.

        Returns:
            float32 patches in [0, 1] on :attr:`device`: ``assemble(*draw(batch_size))``, cut
            to whole periods, then cut to end part-way through a period with probability
            ``partial`` (see the class).

        Shape:
            Output: ``(B, 3, P - r, P - c)`` with ``B = batch_size``, ``P = patch_size`` and
            ``r, c`` the rows and columns cut: ``P mod period``, plus ``1 .. period - 1`` with
            probability ``partial``.
        """
        if self.hard > 0:
            pool = self._with_mined(*self.draw(batch_size * HARD_POOL))
            batch = self._harder(self.assemble(*pool), batch_size)
        else:
            batch = self.assemble(*self._with_mined(*self.draw(batch_size)))
        # Whole periods first (no draw): a 64-pixel patch of a 1x3 pattern would otherwise
        # always end one column into a period, and a network trained only on that edge loses
        # 2-3 dB on crops that end on a whole period (docs/results/edges/).
        cut = [self.patch_size - side for side in self.whole_periods]
        if self.partial > 0:
            for i, side in enumerate(self.period):
                # Both draws happen for every batch, so the sequence does not depend on the period.
                hit = float(torch.rand((), generator=self.generator)) < self.partial
                r = int(torch.randint(1, max(side, 2), (), generator=self.generator))
                cut[i] += r if hit and side > 1 else 0
        batch = batch[..., : self.patch_size - cut[0], : self.patch_size - cut[1]]
        return self.colour(batch, self.generator) if self.colour is not None else batch

    def _with_mined(
        self, index: torch.Tensor, corner: torch.Tensor, code: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The drawn windows, each replaced by a mined one with probability ``mined.share``."""
        if self.mined is None:
            return index, corner, code
        n = len(index)
        take = torch.rand(n, generator=self.generator) < self.mined.share
        pick = torch.randint(len(self.mined.index), (n,), generator=self.generator)[take]
        index, corner, code = index.clone(), corner.clone(), code.clone()
        index[take] = self.mined.index[pick]
        corner[take] = self.mined.corner[pick]
        code[take] = self.mined.code[pick]
        return index, corner, code

    def _harder(self, candidates: torch.Tensor, batch_size: int) -> torch.Tensor:
        """``batch_size`` of ``candidates`` chosen by detail (see ``hard`` in the class)."""
        energy = (
            (
                candidates.diff(dim=-1).square().mean((1, 2, 3))
                + candidates.diff(dim=-2).square().mean((1, 2, 3))
            )
            .double()
            .cpu()
        )
        n = len(candidates)
        share = energy / energy.sum() if float(energy.sum()) > 0 else torch.full((n,), 1 / n)
        weights = (1 - self.hard) / n + self.hard * share
        pick = torch.multinomial(weights, batch_size, replacement=False, generator=self.generator)
        return candidates[pick.to(candidates.device)]

    def assemble(
        self, index: torch.Tensor, corner: torch.Tensor, code: torch.Tensor
    ) -> torch.Tensor:
        """Build the patches chosen by :meth:`draw` (no randomness involved).

        Each patch is a strided numpy view (slice, transpose, reversal) copied once into the
        integer batch, which is converted to float in one pass. Numpy is used rather than torch
        because per-patch numpy views cost a few microseconds and numpy never spreads these
        small copies over threads; torch's thread pool made the same work several times slower
        on a busy 2-core machine.

        Args:
            index: Image index per patch.
            corner: Window top-left (row, column) per patch.
            code: Dihedral code per patch, see :func:`dihedral` (ignored unless ``augment``).

        Returns:
            float32 patches in [0, 1], the same values :func:`~splitcam.data.images.read_image`
            gives for those pixels, on :attr:`device` (built there by
            :meth:`DeviceImages.patches` when the images are held on a device).

        Shape:
            index: ``(B,)``; corner: ``(B, 2)``; code: ``(B,)``; output: ``(B, 3, P, P)``.
        """
        size = self.patch_size
        if self.images is not None:
            return self.images.patches(index, corner, code if self.augment else code * 0, size)
        arrays = self.cache.arrays
        codes = code.tolist() if self.augment else [0] * len(index)
        batch = np.empty((len(index), 3, size, size), dtype=self.cache.dtype)
        rows, cols = corner.T.tolist()
        for b, (i, y, x, c) in enumerate(zip(index.tolist(), rows, cols, codes, strict=True)):
            batch[b] = dihedral(arrays[i][:, y : y + size, x : x + size], c)
        values = np.divide(batch, np.float32(self.cache.max_value), dtype=np.float32)
        return torch.from_numpy(values)

    def state_dict(self) -> dict[str, Any]:
        """The sampler's position in its random sequence, to store in a checkpoint.

        Returns:
            ``{"generator_state": uint8 tensor, "rank": int, "num_images": int}``; the last two
            guard :meth:`load_state_dict` against restoring into the wrong rank or data.
        """
        return {
            "generator_state": self.generator.get_state(),
            "rank": self.rank,
            "num_images": len(self.cache),
        }

    def load_state_dict(self, state: dict[str, Any] | torch.Tensor) -> None:
        """Continue the random sequence from a :meth:`state_dict`.

        Args:
            state: A dict from :meth:`state_dict`, or the generator state tensor alone.

        Raises:
            ValueError: The state was saved by another rank or for a different number of images
                (restoring it would silently duplicate or change the patch stream).
        """
        if isinstance(state, torch.Tensor):
            state = {"generator_state": state}
        for key, mine in (("rank", self.rank), ("num_images", len(self.cache))):
            if key in state and int(state[key]) != mine:
                raise ValueError(
                    f"sampler state was saved with {key}={int(state[key])}, this sampler has {mine}"
                )
        generator_state = state["generator_state"]
        if not isinstance(generator_state, torch.Tensor) or generator_state.dtype != torch.uint8:
            raise ValueError("generator_state must be a torch.uint8 tensor")
        self.generator.set_state(generator_state.cpu())


def load_validation(
    folder: str | os.PathLike[str], max_images: int | None = None
) -> list[tuple[str, torch.Tensor]]:
    """Whole images of a folder, for validation.

    Unreadable and greyscale files are skipped with one warning, like :class:`ImageCache`.

    Args:
        folder: The folder (see :func:`list_images`).
        max_images: Keep at most this many images (the first ones in sorted order).

    Returns:
        ``(name, image)`` pairs: the file name stem and a float32 image in [0, 1].

    Shape:
        image: ``(3, H, W)``.

    Raises:
        FileNotFoundError: See :func:`list_images`.
        ValueError: No usable image in the folder.
    """
    cache = ImageCache(folder, min_size=1, max_images=max_images, progress=False)
    return [(name, cache.image(i)) for i, name in enumerate(cache.names)]
