"""Draw a pattern: its unit cell and, for each site and colour, where the light goes (the paper's
Fig. 3), plus what each pixel ends up recording."""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

import numpy as np

from ..patterns import COLOURS, Pattern, measure, pixel_response
from ._save import save_figure

_RGB = {"R": (0.84, 0.15, 0.16), "G": (0.17, 0.63, 0.17), "B": (0.12, 0.37, 0.84)}


def _fmt(v: float) -> str:
    text = f"{v:.2f}".rstrip("0").rstrip(".")
    return text[1:] if text.startswith("0.") else text


def draw_pattern(pattern: Pattern, out: str | os.PathLike | None = None, *, dpi: int = 130):
    """Draw ``pattern`` and return the matplotlib figure (saved to ``out`` if given).

    Left: the unit cell, each pixel labelled with its splitter and filled with the colour mixture
    it records from a white scene (the sums of its Eq. 2 kernel). Right: one row per site of the
    cell and one column per colour; each small grid is the neighbourhood of the site (outlined
    centre = the pixel the light arrives at), shaded by the fraction of that colour's light that
    lands on each pixel, with the fraction written in.
    """
    from matplotlib.figure import Figure

    ph, pw = pattern.period
    kh, kw = pattern.kernel_size
    sites = [(i, j) for i in range(ph) for j in range(pw)]
    unit = 0.42  # inches per kernel cell
    mini_w, mini_h = max(kw, 3) * unit, max(kh, 1) * unit
    left_w = max(2.6, pw * 0.9)
    fig_w = left_w + 3 * (mini_w + 0.35) + 1.4
    fig_h = max(len(sites) * (mini_h + 0.45), ph * 0.9 + 1.2) + 1.6
    fig = Figure(figsize=(fig_w, fig_h))

    def box(x0: float, y0: float, w: float, h: float):
        return fig.add_axes((x0 / fig_w, y0 / fig_h, w / fig_w, h / fig_h))

    top = fig_h - 1.25
    response = pixel_response(pattern)
    cell = min(0.9, (left_w - 0.4) / pw)
    _draw_unit_cell(box(0.3, top - ph * cell - 0.05, pw * cell, ph * cell), pattern, response)

    x0 = left_w + 0.7
    for r, (i, j) in enumerate(sites):
        y0 = top - (r + 1) * (mini_h + 0.45) + 0.1
        s = pattern.layout[i, j]
        fig.text(
            (x0 - 0.15) / fig_w,
            (y0 + mini_h / 2) / fig_h,
            f"site ({i},{j})\ns{s}",
            ha="right",
            va="center",
            fontsize=8,
        )
        for c, colour in enumerate(COLOURS):
            ax = box(x0 + c * (mini_w + 0.35), y0, mini_w, mini_h)
            _draw_kernel(ax, pattern.kernels[s, c], colour, titled=r == 0)

    _caption(fig, fig_w, fig_h, pattern)
    if out is not None:
        save_figure(fig, out, dpi=dpi)
    return fig


def _draw_unit_cell(ax, pattern: Pattern, response: np.ndarray) -> None:
    """The unit cell: each pixel's splitter and the colour mixture it records from white."""
    from matplotlib.patches import Rectangle

    ph, pw = pattern.period
    peak = max(float(response.max()), 1e-12)
    for i in range(ph):
        for j in range(pw):
            rgb = response[i, j] / peak
            ax.add_patch(Rectangle((j, i), 1, 1, fc=rgb, ec="black", lw=1.2))
            text = f"s{pattern.layout[i, j]}\n" + " ".join(
                f"{c}{_fmt(v)}" for c, v in zip(COLOURS, response[i, j], strict=True)
            )
            ax.text(
                j + 0.5,
                i + 0.5,
                text,
                ha="center",
                va="center",
                fontsize=7,
                color="white" if rgb.mean() < 0.5 else "black",
            )
    ax.set_xlim(0, pw)
    ax.set_ylim(ph, 0)
    ax.set_axis_off()
    ax.set_title("unit cell: splitter and\nwhat each pixel records", fontsize=8)


def _draw_kernel(ax, kernel, colour: str, *, titled: bool) -> None:
    """One colour's kernel of one splitter: the neighbourhood shaded by the fraction of the
    light each pixel gets (outlined centre: the pixel the light arrives at)."""
    from matplotlib.patches import Rectangle

    kh, kw = kernel.shape
    ox = (max(kw, 3) - kw) / 2
    for a in range(kh):
        for b in range(kw):
            f = float(kernel[a, b])
            shade = np.array(_RGB[colour]) * f + np.ones(3) * (1 - f)
            centre = (a, b) == (kh // 2, kw // 2)
            ax.add_patch(
                Rectangle(
                    (ox + b, a),
                    1,
                    1,
                    fc=shade,
                    ec="black" if centre else "#aaaaaa",
                    lw=1.6 if centre else 0.6,
                    zorder=2 if centre else 1,
                )
            )
            if f > 1e-3:
                ax.text(
                    ox + b + 0.5,
                    a + 0.5,
                    _fmt(f),
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if f > 0.55 else "black",
                    zorder=3,
                )
    ax.set_xlim(0, max(kw, 3))
    ax.set_ylim(kh, 0)
    ax.set_aspect("equal")
    ax.set_axis_off()
    if titled:
        ax.set_title(f"{colour} light goes to", fontsize=8, color=_RGB[colour])


def _caption(fig, fig_w: float, fig_h: float, pattern: Pattern) -> None:
    """The pattern's name, provenance and measures above, the key to the numbers below."""
    m = measure(pattern)
    eff = "/".join(_fmt(e) for e in m.efficiency)
    width = int(fig_w * 13)
    lines = [
        *textwrap.wrap(f"Pattern {pattern.name}: {pattern.description}", width),
        *textwrap.wrap(f"{pattern.provenance}; {pattern.reference}", width),
        f"efficiency R/G/B {eff} · split {m.split_fraction:.2f} · spread {m.spread:.2f} px · "
        + (f"pools light in {m.pooling_unit}-pixel units" if m.pooling else "no pooling"),
    ]
    fig.text(0.5, 1 - 0.1 / fig_h, "\n".join(lines), ha="center", va="top", fontsize=8.5)
    fig.text(
        0.5,
        0.12 / fig_h,
        "Outlined centre: the pixel where the light arrives; other cells: "
        "its neighbours. Numbers: fraction of that colour's light.",
        ha="center",
        fontsize=7,
        color="#555555",
    )


def draw_height_maps(
    heights: list[tuple[str, np.ndarray]],
    out: str | os.PathLike,
    *,
    period: tuple[int, int] = (2, 2),
    pitch: float | list[float] = 1.0,
    max_height: float | list[float] = 1.2,
) -> Path:
    """Metasurface height maps of one ``period`` side by side (µm, each coloured from 0 to its
    ``max_height``), the pixel boundaries drawn as white lines; ``pitch`` (µm, one or one per
    map) scales the axes."""
    from matplotlib.figure import Figure

    n = len(heights)
    pitches = pitch if isinstance(pitch, list) else [pitch] * n
    tops = max_height if isinstance(max_height, list) else [max_height] * n
    cols = min(n, 4)
    rows = -(-n // cols)
    fig = Figure(figsize=(3.1 * cols, 2.9 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, (title, h), p, top in zip(axes.flat, heights, pitches, tops, strict=False):
        h = np.asarray(h)
        ph, pw = period
        extent = (0, pw * p, ph * p, 0)
        image = ax.imshow(h, cmap="viridis", vmin=0, vmax=top, extent=extent)
        for k in range(1, ph):
            ax.axhline(k * p, color="white", lw=0.8)
        for k in range(1, pw):
            ax.axvline(k * p, color="white", lw=0.8)
        ax.set_title(title, fontsize=8)
        ax.set_xlabel("µm", fontsize=7)
        ax.tick_params(labelsize=6)
        fig.colorbar(image, ax=ax, fraction=0.046, pad=0.03, label="height (µm)")
    fig.tight_layout()
    return save_figure(fig, out, dpi=120)


def draw_design(
    start: Pattern, designed: Pattern, path: str | os.PathLike[str], dpi: int = 110
) -> Path:
    """A designed pattern beside its start: two :func:`draw_pattern` figures side by side with
    a thin rule between them, written as one PNG (what ``splitcam design`` draws).

    Returns:
        The path written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    halves = []
    for pattern in (start, designed):
        canvas = FigureCanvasAgg(draw_pattern(pattern, dpi=dpi))
        canvas.draw()
        halves.append(np.asarray(canvas.buffer_rgba())[..., :3])
    height = max(h.shape[0] for h in halves)
    halves = [
        np.pad(h, ((0, height - h.shape[0]), (0, 0), (0, 0)), constant_values=255) for h in halves
    ]
    gap = np.full((height, 24, 3), 255, dtype=np.uint8)
    gap[:, 11:13] = 160
    image = np.concatenate([halves[0], gap, halves[1]], axis=1)
    fig = Figure(figsize=(image.shape[1] / dpi, image.shape[0] / dpi), dpi=dpi)
    fig.figimage(image)
    return save_figure(fig, path, dpi=dpi)
