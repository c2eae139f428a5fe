"""Side-by-side zoomed crops of several reconstructions of one scene (the paper's Figs. 4, 5,
7 and 8)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from ._save import save_figure

__all__ = ["check_region", "detail_region", "zoom_figure"]


def detail_region(rgb: torch.Tensor, size: int = 96) -> tuple[int, int, int, int]:
    """The ``size``-square window of the ground truth with the most detail (gradient energy):
    where reconstruction differences show. Chosen from the scene alone, so it is the same for
    every method. Returns ``(top, left, height, width)``."""
    grey = rgb.mean(0).numpy().astype(np.float64)
    h, w = grey.shape
    size = min(size, h, w)
    energy = np.zeros_like(grey)
    energy[:, 1:] += np.diff(grey, axis=1) ** 2
    energy[1:, :] += np.diff(grey, axis=0) ** 2
    integral = np.pad(energy.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    sums = (
        integral[size:, size:]
        - integral[:-size, size:]
        - integral[size:, :-size]
        + integral[:-size, :-size]
    )
    top, left = np.unravel_index(int(np.argmax(sums)), sums.shape)
    return int(top), int(left), size, size


def check_region(region: tuple[int, int, int], shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """``(top, left, size)`` clipped to an image of ``shape = (H, W)``:
    ``(top, left, height, width)``.

    Raises:
        ValueError: The region lies outside the image.
    """
    top, left, size = region
    h, w = min(size, shape[0] - top), min(size, shape[1] - left)
    if h < 1 or w < 1:
        raise ValueError(f"zoom region {tuple(region)} lies outside the {tuple(shape)} image")
    return top, left, h, w


def zoom_figure(
    rgb: torch.Tensor,
    outputs: Mapping[str, tuple[torch.Tensor, dict | None]],
    path: str | os.PathLike,
    title: str = "",
    region: tuple[int, int, int] | None = None,
    columns: int = 6,
) -> Path:
    """Ground truth and each method's output, zoomed on ``region`` (top, left, size), by
    default the most detailed region of the scene (:func:`detail_region`).

    Args:
        rgb: The scene, ``(3, H, W)`` in [0, 1].
        outputs: ``{label: (image (3, H, W), scores or None)}``; scores (``psnr``, ``ssim``,
            ``ciede2000``) are written under each panel.
        path: PNG to write.
        title: Figure title.
        region: ``(top, left, size)``.
        columns: Panels per row: many methods wrap onto several rows, so each crop stays large
            enough to compare (one row of 18 was a strip too thin to read).
    """
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    top, left, h, w = (
        detail_region(rgb) if region is None else check_region(region, tuple(rgb.shape[1:]))
    )
    panels = [("ground truth", rgb, None), *((n, p, s) for n, (p, s) in outputs.items())]
    cells = len(panels) + 1
    cols = max(1, min(columns, cells))
    rows = -(-cells // cols)
    fig = Figure(figsize=(2.6 * cols, 3.1 * rows))
    axes = list(np.atleast_1d(fig.subplots(rows, cols)).ravel())
    for ax in axes[cells:]:
        ax.set_visible(False)
    axes = axes[:cells]
    axes[0].imshow(rgb.permute(1, 2, 0).numpy())
    axes[0].add_patch(Rectangle((left, top), w, h, fill=False, ec="yellow", lw=1.5))
    axes[0].set_title("scene (region in yellow)", fontsize=8)
    for ax, (name, img, scores) in zip(axes[1:], panels, strict=True):
        crop = img[:, top : top + h, left : left + w].permute(1, 2, 0).numpy()
        ax.imshow(crop, interpolation="nearest")
        label = (
            name
            if scores is None
            else (
                f"{name}\n{scores['psnr']:.2f} dB, SSIM {scores['ssim']:.3f}, "
                f"ΔE {scores['ciede2000']:.2f}"
            )
        )
        ax.set_title(label, fontsize=7)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, dpi=130)
