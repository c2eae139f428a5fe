"""Zoomed crops (splitcam.viz.zoom): the detail region and the figure's rows."""

from __future__ import annotations

import torch
from PIL import Image

from splitcam.viz.zoom import detail_region, zoom_figure


def test_detail_region_finds_the_textured_part():
    img = torch.zeros(3, 100, 120)
    img[:, 60:90, 10:40] = torch.rand(3, 30, 30, generator=torch.Generator().manual_seed(1))
    top, left, h, w = detail_region(img, size=30)
    assert (h, w) == (30, 30) and abs(top - 60) <= 1 and abs(left - 10) <= 1


def test_zoom_figure_wraps_many_methods_onto_rows_of_whole_crops(tmp_path):
    """18 cells (scene, truth, 16 methods) in rows of 6 make a figure of 3 rows of 6 cells, not
    one strip of 18; two methods stay on one row of 4 cells."""

    rgb = torch.full((3, 40, 40), 0.5)
    rgb[:, 10:30, 10:30] = torch.rand(3, 20, 20, generator=torch.Generator().manual_seed(1))
    outputs = {f"m{i}": (torch.full((3, 40, 40), i / 16), None) for i in range(16)}
    path = zoom_figure(rgb, outputs, tmp_path / "z.png", region=(0, 0, 40), columns=6)
    # The image is cut to what is drawn, so its size is within a few per cent of the cells'.
    width, height = Image.open(path).size
    assert abs(width / (2.6 * 6 * 130) - 1) < 0.05 and abs(height / (3.1 * 3 * 130) - 1) < 0.1
    few = zoom_figure(rgb, dict(list(outputs.items())[:2]), tmp_path / "few.png")
    width, height = Image.open(few).size
    assert abs(width / (2.6 * 4 * 130) - 1) < 0.05 and abs(height / (3.1 * 130) - 1) < 0.15
