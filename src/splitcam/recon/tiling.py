"""Tiled reconstruction: run a reconstruction on a large raw image with bounded peak memory.

The image is cut into overlapping tiles that are reconstructed one at a time and written into a
preallocated result (:func:`tiled`, the one mechanism; :func:`reconstruct` runs a network
through it, and the LMMSE filters and classical demosaicking use it too). Two things make the
tiled result equal the untiled one up to float error:

- every tile starts at a multiple of the period, because the methods assign position classes
  from tile-local coordinates (and the packed network groups pixels into cells from there);
- every output pixel is taken from a tile in which it lies at least ``overlap >= radius`` pixels
  from each tile edge that is not an image edge, where ``radius`` is the reach of the method (the
  network's receptive radius, the LMMSE filter radius, a demosaicking algorithm's support), so
  whatever the method does at tile edges never reaches it. Tile edges that are image edges are
  the image's own edges, so the method's border handling applies there unchanged.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from numbers import Integral
from typing import Any, NamedTuple

import torch
from torch import nn

from ..checks import check_period, check_raw, is_int

__all__ = ["DEFAULT_TILE", "Span", "reconstruct", "tile_spans", "tiled"]

#: Tile size of the methods that tile on their own (LMMSE, classical demosaicking): a 512x512
#: tile keeps their intermediates to tens of megabytes, and larger tiles are no faster.
DEFAULT_TILE = 512


class Span(NamedTuple):
    """One tile along one axis.

    The tile reads input ``[start, stop)`` and supplies output ``[keep_start, keep_stop)``.
    """

    start: int
    stop: int
    keep_start: int
    keep_stop: int


def _ceil_to(value: int, multiple: int) -> int:
    return -(-value // multiple) * multiple


def tile_spans(size: int, tile: int, overlap: int, period: int) -> list[Span]:
    """Cut one axis of length ``size`` into overlapping tiles.

    Tiles start at multiples of ``period`` and are at most ``tile`` long; the kept parts cover
    ``[0, size)`` exactly once, and each lies at least ``overlap`` pixels from any end of its tile
    that is not an end of the axis.

    Args:
        size: Length of the axis, ``>= 1``.
        tile: Maximum tile length.
        overlap: Context to keep on each inner side of a tile.
        period: The pattern period along this axis.

    Returns:
        The spans in increasing order; a single span ``(0, size, 0, size)`` if ``size <= tile``.

    Raises:
        ValueError: ``tile`` is too small to advance by at least one period
            (``tile < 2 * overlap + period`` when ``size > tile``).
    """
    if size <= tile:
        return [Span(0, size, 0, size)]
    # The tile after a tile starting at s may start at s + stride and keep from there + overlap,
    # which the earlier tile still covers with overlap to spare at its far end.
    stride = (tile - 2 * overlap) // period * period
    if stride < period:
        raise ValueError(
            f"tile={tile} is too small for overlap={overlap} with period {period}: "
            f"need tile >= {2 * overlap + period}"
        )
    spans: list[Span] = []
    start, keep_start = 0, 0
    while start + tile < size:
        keep_stop = start + stride + overlap
        spans.append(Span(start, start + tile, keep_start, keep_stop))
        start, keep_start = start + stride, keep_stop
    # Pull the last tile back so it is as long as allowed; it still starts at a multiple of the
    # period and no later than the tile it replaces, so its kept part keeps enough context.
    last_start = _ceil_to(size - tile, period)
    spans.append(Span(last_start, size, keep_start, size))
    return spans


def _network_period(net: nn.Module) -> tuple[int, int]:
    period = getattr(net, "period", None)
    if (
        not isinstance(period, tuple)
        or len(period) != 2
        or not all(isinstance(p, Integral) and p >= 1 for p in period)
    ):
        raise TypeError(f"net must have a `period` attribute (Ph, Pw), got {period!r}")
    return int(period[0]), int(period[1])


def _network_device(net: nn.Module, fallback: torch.device) -> torch.device:
    for tensor in net.parameters():
        return tensor.device
    return fallback


def tiled(
    fn: Callable[[torch.Tensor], torch.Tensor],
    raw: torch.Tensor,
    period: tuple[int, int],
    radius: int,
    *,
    tile: int | None = 512,
    overlap: int | None = None,
    progress: bool = False,
) -> torch.Tensor:
    """Apply a reconstruction ``fn`` to a raw image in overlapping tiles.

    ``fn`` must be *local* and *periodic*: each output pixel depends only on the raw pixels
    within ``radius`` of it (and on the image border where that lies within ``radius``), and on
    its position only through its phase within the period counted from the input's top-left
    pixel. The result then equals ``fn(raw)`` up to the float error of running ``fn`` on
    smaller inputs. The result is assembled on the device of ``raw``, in the dtype of ``fn``'s
    output; ``fn`` itself decides where it runs.

    Args:
        fn: The reconstruction of one tile: ``(N, 1, h, w)`` in, ``(N, C, h, w)`` out.
        raw: Raw image batch.
        period: ``(Ph, Pw)``: tiles start at multiples of it.
        radius: How far (in pixels) a raw pixel can influence an output pixel of ``fn``.
        tile: Maximum tile height and width in pixels; ``None`` runs the whole image at once, as
            does an image no larger than one tile.
        overlap: Context kept around each tile's output; at least ``radius``. Default: ``radius``
            rounded up to a multiple of the period (per axis), which loses no tile length since
            tiles advance in whole periods anyway.
        progress: Show a tqdm progress bar over the tiles.

    Returns:
        ``fn(raw)``, computed tile by tile.

    Raises:
        ValueError: ``tile``, ``overlap``, ``radius`` or ``period`` are invalid, ``overlap`` is
            smaller than ``radius``, or ``tile`` is too small for the overlap.

    Shape:
        - raw: ``(N, 1, H, W)``.
        - Output: ``(N, C, H, W)``.
    """
    check_raw(raw)
    ph, pw = check_period(period)
    if not is_int(radius) or radius < 0:
        raise ValueError(f"radius must be an integer >= 0, got {radius!r}")
    if tile is not None and (not is_int(tile) or tile < 1):
        raise ValueError(f"tile must be a positive integer or None, got {tile!r}")
    if overlap is None:
        overlap_h, overlap_w = _ceil_to(radius, ph), _ceil_to(radius, pw)
    elif not is_int(overlap) or overlap < radius:
        raise ValueError(
            f"overlap must be an integer >= the receptive radius {radius}, got {overlap!r}"
        )
    else:
        overlap_h = overlap_w = int(overlap)

    n, _, h, w = raw.shape
    if tile is None or (h <= tile and w <= tile):
        return fn(raw).to(raw.device).contiguous()
    rows = tile_spans(h, tile, overlap_h, ph)
    cols = tile_spans(w, tile, overlap_w, pw)
    out: torch.Tensor | None = None
    jobs = [(r, c) for r in rows for c in cols]
    for r, c in _maybe_progress(jobs, progress):
        rgb = fn(raw[:, :, r.start : r.stop, c.start : c.stop])
        if out is None:
            out = torch.empty((n, rgb.shape[1], h, w), dtype=rgb.dtype, device=raw.device)
        out[:, :, r.keep_start : r.keep_stop, c.keep_start : c.keep_stop] = rgb[
            :,
            :,
            r.keep_start - r.start : r.keep_stop - r.start,
            c.keep_start - c.start : c.keep_stop - c.start,
        ]
    assert out is not None  # there is always at least one tile
    return out


def reconstruct(
    net: nn.Module,
    raw: torch.Tensor,
    *,
    tile: int | None = 512,
    overlap: int | None = None,
    progress: bool = False,
    bf16: bool = False,
    channels_last: bool = False,
    sigma: float | None = None,
    kernels: torch.Tensor | None = None,
) -> torch.Tensor:
    """Reconstruct RGB from a raw image in overlapping tiles (:func:`tiled`), without autograd.

    The network's mode (train/eval) is left as it is. Tiles are moved to the device of the
    network's parameters and the result is assembled on the device of ``raw``, so a large image
    can stay in host memory while a GPU runs the network. All ``N`` images of the batch go through
    each tile together.

    Args:
        net: A reconstruction network with ``period`` and ``receptive_radius`` attributes (see
            :mod:`splitcam.recon.networks`).
        raw: Raw image batch.
        tile: Maximum tile height and width in pixels; ``None`` runs the whole image at once, as
            does an image no larger than one tile.
        overlap: Context kept around each tile's output; at least ``net.receptive_radius``.
            Default: ``net.receptive_radius`` rounded up to a multiple of the period (per axis).
        progress: Show a tqdm progress bar over the tiles.
        bf16: Run the network under bfloat16 autocast (much faster on CPUs with AVX512-BF16 or
            AMX; the output is returned in float32; costs some accuracy, see the README).
        channels_last: Run the convolutions in channels-last memory format (the network's
            weights are in it for the reconstruction and back in their own layout after it; the
            results are unchanged).
        sigma: Noise level of ``raw`` (8-bit units), for networks that take it
            (``net.uses_physics``, see :class:`splitcam.recon.networks.PhysicsReconNet`).
        kernels: Pixel kernels ``(Ph, Pw, 3, kh, kw)`` of the sensor, for the same networks.

    Returns:
        The RGB reconstruction, equal to ``net(raw)`` up to float error (bfloat16 error with
        ``bf16``).

    Raises:
        TypeError: ``raw`` is not a floating-point tensor, or ``net`` lacks ``period``.
        ValueError: ``raw`` has a bad shape, ``tile``/``overlap`` are invalid, ``overlap`` is
            smaller than the receptive radius, or ``tile`` is too small for the overlap.

    Shape:
        - raw: ``(N, 1, H, W)``.
        - Output: ``(N, 3, H, W)``.
    """
    check_raw(raw)
    if getattr(net, "period", 0) is None and kernels is not None:
        # A network for any pattern (UniversalReconNet): aligned to the pattern's period.
        period = tuple(net.tiling_period(tuple(kernels.shape[:2])))
    else:
        period = _network_period(net)
    radius = int(net.receptive_radius)
    device = _network_device(net, raw.device)
    memory_format = torch.channels_last if channels_last else torch.contiguous_format

    physics: tuple[Any, ...] = ()
    if getattr(net, "uses_physics", False):
        if sigma is None or kernels is None:
            raise ValueError(
                f"network {type(net).__name__} needs the noise level and the sensor's kernels"
            )
        physics = (sigma, kernels.to(device))

    def run(x: torch.Tensor) -> torch.Tensor:
        x = x.to(device).contiguous(memory_format=memory_format)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
            y = net(x, *physics)
        return y.to(raw.dtype) if bf16 else y

    layout = _weights_in(net, memory_format) if channels_last else contextlib.nullcontext()
    with torch.inference_mode(), layout:
        return tiled(run, raw, period, radius, tile=tile, overlap=overlap, progress=progress)


@contextlib.contextmanager
def _weights_in(net: nn.Module, memory_format: torch.memory_format) -> Iterator[None]:
    """The network's 4-D weights in ``memory_format`` for the reconstruction, and as they were
    afterwards: a network that is also being trained (validation reconstructs with the training
    network) must not come back in another layout, which changes the rounding of the steps
    after it (a resumed run then differed from an uninterrupted one by ~1e-8)."""
    params = [p for p in net.parameters() if p.dim() == 4]
    before = [p.data for p in params]
    with torch.no_grad():
        for p in params:
            p.data = p.data.contiguous(memory_format=memory_format)
    try:
        yield
    finally:
        for p, data in zip(params, before, strict=True):
            p.data = data


def _maybe_progress(items: list[Any], progress: bool) -> Any:
    if not progress:
        return items
    from tqdm.auto import tqdm

    return tqdm(items, desc="reconstruct", unit="tile")
