"""The break-even map of routers against a filter array, as a chart
(:func:`splitcam.evaluation.breakeven.break_even`)."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ._save import save_figure

__all__ = ["breakeven_chart", "cell_text"]

_NOTE = {"always": "all", "never": "none", "tie": "tie", "infeasible": ""}


def _short(n: float) -> str:
    """Two significant digits, written out below 10^4 (``300``, not ``3e+02``)."""
    if n < 10:
        return f"{n:.2g}"
    if n < 1e4:
        return f"{float(f'{n:.2g}'):.0f}"
    return f"{n:.1e}".replace("e+0", "e")


def cell_text(cell: Mapping[str, Any]) -> str:
    """What a cell of the map says: ``<N`` (the router wins below exposure N), ``>N`` (above),
    ``a–b`` (several crossings, the last two an up and a down one: the router wins between
    exposures a and b, and perhaps again below), ``N*`` (other crossings, the highest shown),
    ``all``, ``none``, ``tie`` or nothing (``eta + chi > 1``)."""
    kind = cell["verdict"]
    if kind in _NOTE:
        return _NOTE[kind]
    if kind == "mixed":
        (lo, up), (hi, down) = cell["crossings"][-2:]
        if (up, down) == ("up", "down"):
            return f"{_short(lo)}–{_short(hi)}"
        return f"{_short(cell['break_even'])}*"
    return {"below": "<", "above": ">"}[kind] + _short(cell["break_even"])


def breakeven_chart(
    result: Mapping[str, Any],
    path: str | os.PathLike,
    *,
    presets: Mapping[str, tuple[float, float]] | None = None,
    title: str | None = None,
) -> Path:
    """A heat map of the break-even exposure over (crosstalk, efficiency): colour log10 of the
    exposure where router − reference changes sign (of several, the highest); green where the
    router is better at every exposure studied, grey where it never is, hatched where
    ``eta + chi > 1``; each cell's text from :func:`cell_text`. ``presets``:
    ``{name: (eta, chi)}``, marked with a star."""
    import numpy as np
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    etas, chis = list(result["etas"]), list(result["chis"])
    cells = {(c["eta"], c["chi"]): c for c in result["cells"]}
    lo, hi = math.log10(min(result["photons"])), math.log10(max(result["photons"]))
    grid = np.full((len(etas), len(chis)), np.nan)
    for i, e in enumerate(etas):
        for j, x in enumerate(chis):
            if cells[(e, x)]["break_even"] is not None:
                grid[i, j] = math.log10(cells[(e, x)]["break_even"])
    # At least the width the two-line title needs, and room for the colour bar's label.
    fig = Figure(figsize=(max(7.5, 1.0 + 0.75 * len(chis)), max(4.0, 1.3 + 0.55 * len(etas))))
    ax = fig.subplots()
    image = ax.imshow(
        grid, origin="lower", aspect="auto", cmap="viridis", vmin=lo, vmax=hi,
        extent=(-0.5, len(chis) - 0.5, -0.5, len(etas) - 0.5),
    )  # fmt: skip
    fills = {"always": "#9be59b", "never": "#c8c8c8", "tie": "#ffffff", "infeasible": "#ffffff"}
    for i, e in enumerate(etas):
        for j, x in enumerate(chis):
            cell = cells[(e, x)]
            if cell["verdict"] in fills:
                hatch = "//" if cell["verdict"] == "infeasible" else None
                ax.add_patch(
                    Rectangle((j - 0.5, i - 0.5), 1, 1, fc=fills[cell["verdict"]], ec="none",
                              hatch=hatch)
                )  # fmt: skip
            dark = not np.isnan(grid[i, j]) and grid[i, j] < lo + 0.6 * (hi - lo)
            ax.text(j, i, cell_text(cell), ha="center", va="center", fontsize=7,
                    color="white" if dark else "black")  # fmt: skip
    ax.set_xticks(range(len(chis)), [f"{x:g}" for x in chis])
    ax.set_yticks(range(len(etas)), [f"{e:g}" for e in etas])
    ax.set_xlabel("crosstalk χ (every band)")
    ax.set_ylabel("band efficiency η (every band)")
    for name, (eta, chi) in (presets or {}).items():
        # grid coordinates: linear interpolation between the ticks
        x = float(np.interp(chi, chis, range(len(chis))))
        y = float(np.interp(eta, etas, range(len(etas))))
        ax.plot([x], [y], marker="*", ms=14, mfc="red", mec="white", ls="none")
        ax.annotate(name, (x, y), xytext=(6, 6), textcoords="offset points", fontsize=8,
                    color="red", fontweight="bold")  # fmt: skip
    bar = fig.colorbar(image, ax=ax)
    bar.set_label(f"log10 break-even exposure N (range {10**lo:g} to {10**hi:g})")
    method = result.get("method", "closed-form LMMSE").replace("closed-form LMMSE", "LMMSE")
    ax.set_title(
        title
        or f"router(η, χ) against {result['reference']}, {result['metric'].upper()}, {method}, "
        f"read noise {result['read_noise']:g} e⁻\n<N: router better below N; >N: above; a–b: "
        "between; all / none: at every / no exposure; hatched: η + χ > 1",
        fontsize=9,
        pad=14,
    )
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)
