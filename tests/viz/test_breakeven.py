"""The break-even chart (splitcam.viz.breakeven): on a small grid nothing is clipped."""

from __future__ import annotations

from PIL import Image

from splitcam.viz import _save
from splitcam.viz.breakeven import breakeven_chart


def test_a_small_map_keeps_its_title_labels_and_routers_inside_the_image(tmp_path, monkeypatch):
    etas, chis = [0.5, 0.7, 0.9], [0.0, 0.2]
    verdicts = iter(["below", "above", "always", "never", "tie", "infeasible"])
    cells = []
    for e in etas:
        for x in chis:
            kind = next(verdicts)
            cells.append({"eta": e, "chi": x, "verdict": kind,
                          "break_even": 300.0 if kind in ("below", "above") else None})  # fmt: skip
    result = {"etas": etas, "chis": chis, "cells": cells, "photons": [10.0, 10000.0],
              "reference": "rgbw", "metric": "psnr", "read_noise": 2.0}  # fmt: skip
    figures = []
    save = _save.save_figure
    monkeypatch.setattr(
        "splitcam.viz.breakeven.save_figure",
        lambda fig, p, **k: figures.append(fig) or save(fig, p, **k),
    )
    path = breakeven_chart(result, tmp_path / "map.png", presets={"router-zou": (0.9, 0.2)})
    (fig,) = figures
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    drawn = fig.get_tightbbox(renderer)  # inches: every artist, title and labels included
    with Image.open(path) as image:
        width, height = image.size
    # The image holds all of it (before, the title and the colour bar's label ran off a
    # 300x354-pixel map).
    assert width >= drawn.width * 120 - 2 and height >= drawn.height * 120 - 2
    assert any(t.get_text() == "router-zou" for t in fig.axes[0].texts)
