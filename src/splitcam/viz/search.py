"""Figures of a design search (:mod:`splitcam.design.search`): the Pareto front of two scores,
and the score curves of the trials with the ones pruned."""

from __future__ import annotations

import os
from collections.abc import Sequence

from ._save import save_figure

__all__ = ["draw_curves", "draw_front"]


def _save(fig, out: str | os.PathLike | None):
    if out is not None:
        save_figure(fig, out)
    return fig


def draw_front(
    points: Sequence[tuple[float, float]],
    front: Sequence[tuple[float, float]],
    out: str | os.PathLike | None = None,
    *,
    xlabel: str = "light collected",
    ylabel: str = "closed-form LMMSE PSNR (dB)",
    labels: Sequence[str] = (),
    baselines: Sequence[tuple[float, float]] = (),
    title: str | None = None,
):
    """Every trial's two scores and the Pareto front among them (both scores: higher is better).

    The trials are grey dots (collection labelled ``trials``), the front red dots (``Pareto
    front``) annotated with ``labels`` and joined by the staircase that bounds what they
    dominate, the baselines (e.g. the designer's default settings) black stars
    (``baselines``).

    Args:
        points: ``(x, y)`` of every finished trial.
        front: ``(x, y)`` of the trials on the front.
        out: PNG to write (``None``: only return the figure).
        xlabel: Label of the x axis.
        ylabel: Label of the y axis.
        labels: One label per front point (e.g. the trial numbers).
        baselines: ``(x, y)`` of trials to mark as baselines.
        title: Figure title.

    Returns:
        The :class:`matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.subplots()
    if points:
        xs, ys = zip(*points, strict=True)
        ax.scatter(xs, ys, s=18, c="0.6", label="trials", zorder=2)
    ordered = sorted(zip(front, list(labels) or [""] * len(front), strict=True))
    if ordered:
        xs, ys = zip(*(p for p, _ in ordered), strict=True)
        ax.step(xs, ys, where="pre", color="tab:red", lw=1, alpha=0.6, zorder=3)
        ax.scatter(xs, ys, s=36, c="tab:red", label="Pareto front", zorder=4)
        for (x, y), text in ordered:
            if text:
                ax.annotate(text, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=8)
    if baselines:
        xs, ys = zip(*baselines, strict=True)
        ax.scatter(xs, ys, s=90, marker="*", c="k", label="baselines", zorder=5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return _save(fig, out)


def draw_curves(
    curves: Sequence[tuple[str, Sequence[tuple[int, float]], bool]],
    out: str | os.PathLike | None = None,
    *,
    ylabel: str = "closed-form LMMSE PSNR (dB)",
    title: str | None = None,
):
    """The score of every trial at its reports against the design steps: finished trials as
    coloured lines, pruned ones as grey dashed lines ending where they stopped.

    Args:
        curves: ``(label, [(step, score), ...], pruned)`` per trial.
        out: PNG to write (``None``: only return the figure).
        ylabel: Label of the score axis.
        title: Figure title.

    Returns:
        The :class:`matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.subplots()
    for label, points, pruned in curves:
        if not points:
            continue
        steps, scores = zip(*sorted(points), strict=True)
        if pruned:
            ax.plot(
                steps, scores, ls="--", marker="x", color="0.6", lw=1, label=f"{label} (pruned)"
            )
        else:
            ax.plot(steps, scores, marker="o", ms=3, lw=1.2, label=label)
    ax.set_xlabel("design step")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if len(curves) <= 12:
        ax.legend(loc="lower right", fontsize=7)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return _save(fig, out)
