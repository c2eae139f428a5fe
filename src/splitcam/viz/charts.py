"""Charts of evaluation results: PSNR and CIEDE2000 against noise."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..io import atomic_path

__all__ = ["exposure_chart", "sigma_chart"]


def sigma_chart(
    curves: Sequence[tuple[str, Mapping[str, Mapping[str, float]]]],
    path: str | os.PathLike,
    references: Mapping[str, Sequence[tuple[float, float]]] | None = None,
) -> Path:
    """PSNR and CIEDE2000 against sigma for every method (the paper's Fig. 9).

    Args:
        curves: ``(label, {sigma: {"psnr": .., "ciede2000": ..}})`` per method (photon-model
            levels, keys ``"N<photons>"``, are left out: :func:`exposure_chart` draws those).
        path: PNG to write.
        references: Reference PSNR curves ``{label: [(sigma, psnr), ...]}``, drawn grey dashed
            (the paper's trained networks).
    """
    import matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.6))
    ax1, ax2 = fig.subplots(1, 2)
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (label, per_sigma) in enumerate(curves):
        colour = colours[i % len(colours)]
        sig = sorted((s for s in per_sigma if not s.startswith("N")), key=float)  # N...: exposures
        xs = [float(s) for s in sig]
        ax1.plot(xs, [per_sigma[s]["psnr"] for s in sig], "o-", color=colour, label=label)
        ax2.plot(xs, [per_sigma[s]["ciede2000"] for s in sig], "o-", color=colour, label=label)
    for ref, points in (references or {}).items():
        xs, values = zip(*points, strict=True)
        ax1.plot(xs, values, "--", color="grey", alpha=0.7, lw=1)
        ax1.annotate(
            f"paper {ref}",
            (xs[-1], values[-1]),
            fontsize=7,
            color="dimgrey",
            xytext=(3, 0),
            textcoords="offset points",
            va="center",
        )
    ax1.set_xlabel("noise σ (8-bit units)")
    ax1.set_ylabel("PSNR (dB)")
    ax1.set_title(
        "PSNR (grey dashed: the paper's trained network)" if references else "PSNR", fontsize=10
    )
    ax2.set_xlabel("noise σ (8-bit units)")
    ax2.set_ylabel("CIEDE2000 (lower is better)")
    ax2.set_title("colour error", fontsize=10)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    ax2.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    return path


def exposure_chart(
    results: Mapping[str, Mapping[float, Mapping[str, float]]],
    path: str | os.PathLike,
    *,
    title: str = "LMMSE at equal exposure (photon model)",
) -> Path:
    """PSNR and CIEDE2000 against exposure (log axis) for every pattern; the Bayer filter
    dashed black."""
    import matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.6))
    ax1, ax2 = fig.subplots(1, 2)
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (label, per) in enumerate(results.items()):
        xs = sorted(per)
        bayer = label == "bayer" or label.startswith("bayer+")
        style = {"color": "black", "ls": "--"} if bayer else {"color": colours[i % len(colours)]}
        style = {"marker": "o", "ms": 3, "ls": "-", **style}
        ax1.plot(xs, [per[x]["psnr"] for x in xs], label=label, **style)
        ax2.plot(xs, [per[x]["ciede2000"] for x in xs], label=label, **style)
    for ax, name in ((ax1, "PSNR (dB)"), (ax2, "CIEDE2000 (lower is better)")):
        ax.set_xscale("log")
        ax.set_xlabel("exposure N: photo-electrons of a lossless full-light pixel")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3, which="both")
    ax1.set_title(title, fontsize=10)
    ax2.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    return path
