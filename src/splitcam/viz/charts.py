"""Charts of evaluation results: PSNR and CIEDE2000 against noise."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..physics.noise import level_key, parse_level_label
from ._save import save_figure

__all__ = ["difference_chart", "exposure_chart", "sigma_chart"]


def method_kind(label: str) -> str:
    """``lmmse``, ``classical`` (Bayer demosaicking) or ``network``, from a method's label."""
    name = label.rsplit(": ", 1)[-1]  # a report prefixes the result folder
    if name.startswith("lmmse"):
        return "lmmse"
    if name.startswith("bayer+"):
        return "classical"
    return "network"


#: Line style and marker per kind of method: a pattern's curves share a colour.
KIND_STYLES = {
    "network": {"ls": "-", "marker": "o"},
    "lmmse": {"ls": "--", "marker": "s"},
    "classical": {"ls": ":", "marker": "^"},
}


def _palette(n: int) -> list:
    """``n`` distinguishable colours: the default cycle up to 10, tab20 up to 20, then a
    continuous colour map."""
    import matplotlib

    if n <= 10:
        return matplotlib.rcParams["axes.prop_cycle"].by_key()["color"][:n]
    cmap = matplotlib.colormaps["tab20" if n <= 20 else "turbo"]
    return [cmap(i / max(n - 1, 1)) if n > 20 else cmap(i) for i in range(n)]


def sigma_chart(
    curves: Sequence[tuple[str, Mapping[str, Mapping[str, float]]]],
    path: str | os.PathLike,
    references: Mapping[str, Sequence[tuple[float, float]]] | None = None,
    *,
    patterns_of: Mapping[str, str] | None = None,
) -> Path:
    """PSNR and CIEDE2000 against sigma for every method (the paper's Fig. 9).

    Each pattern has its own colour and each kind of method its own line style and marker
    (network solid, LMMSE dashed, classical demosaicking dotted), so every line can be told
    apart; the x ticks are the sigmas measured.

    Args:
        curves: ``(label, {sigma: {"psnr": .., "ciede2000": ..}})`` per method (photon-model
            levels, keys ``"N<photons>"``, are left out: :func:`exposure_chart` draws those).
        path: PNG to write.
        references: Reference PSNR curves ``{label: [(sigma, psnr), ...]}``, drawn grey dashed
            (the paper's trained networks).
        patterns_of: The pattern of each label (default: each label its own colour).
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.6))
    ax1, ax2 = fig.subplots(1, 2)
    group: dict[str, str] = {}
    seen: set[tuple[str, str]] = set()
    for label, _ in curves:
        key = (patterns_of or {}).get(label, label)
        if (key, method_kind(label)) in seen:  # two networks of one pattern name: apart
            key = label
        seen.add((key, method_kind(label)))
        group[label] = key
    keys = list(dict.fromkeys(group.values()))
    colour_of = dict(zip(keys, _palette(len(keys)), strict=True))
    measured: set[float] = set()
    for label, per_sigma in curves:
        style = {"color": colour_of[group[label]], "ms": 4, **KIND_STYLES[method_kind(label)]}
        sig = sorted((s for s in per_sigma if parse_level_label(s)[0] == "sigma"), key=level_key)
        xs = [parse_level_label(s)[1] for s in sig]
        measured.update(xs)
        ax1.plot(xs, [per_sigma[s]["psnr"] for s in sig], label=label, **style)
        ax2.plot(xs, [per_sigma[s]["ciede2000"] for s in sig], label=label, **style)
    # The paper's network of each pattern, grey dashed and labelled at its right end.
    for ref, points in (references or {}).items():
        xs, ys = zip(*sorted(points), strict=True)
        ax1.plot(xs, ys, "--", color="grey", alpha=0.7, lw=1, gid=f"reference:{ref}")
        ax1.annotate(
            f"paper {ref}",
            (xs[-1], ys[-1]),
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
        ax.set_xticks(sorted(measured))
        ax.set_xticklabels([f"{x:g}" for x in sorted(measured)])
    ax2.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def exposure_chart(
    results: Mapping[str, Mapping[float, Mapping[str, float]]],
    path: str | os.PathLike,
    *,
    title: str | None = None,
    networks: Mapping[str, str] | None = None,
) -> Path:
    """PSNR and CIEDE2000 against exposure (log axis) for every pattern's LMMSE (thin, dashed),
    and for the networks (``networks``: ``{label: pattern name}``; thick, in their pattern's
    colour, one line style per way of making them: solid for the first, dash-dot for the
    second, ...); the Bayer filter in black."""
    import matplotlib
    from matplotlib.figure import Figure

    networks = dict(networks or {})
    fig = Figure(figsize=(12, 4.8))
    ax1, ax2 = fig.subplots(1, 2)
    cycle = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    order = list(dict.fromkeys(networks.get(label, label) for label in results))
    colour = {p: cycle[i % len(cycle)] for i, p in enumerate(order)}
    from ..recon.registry import network_kind

    # networks of one kind (one model for any pattern, or each sensor's own) share a line style
    family = {label: network_kind(label, p) for label, p in networks.items()}
    styles = ["-", "-.", ":", (0, (6, 2))]
    line = {f: styles[i % len(styles)] for i, f in enumerate(dict.fromkeys(family.values()))}
    for label, per in results.items():
        pattern = networks.get(label, label)
        bayer = pattern == "bayer" or pattern.startswith("bayer+")
        style = {"color": "black" if bayer else colour[pattern], "marker": "o", "ms": 3}
        if label in networks:
            style.update(ls=line[family[label]], lw=2.0)
        else:
            style.update(ls="--" if networks or bayer else "-", lw=1.0 if networks else 1.5)
        xs = sorted(per)
        ax1.plot(xs, [per[x]["psnr"] for x in xs], label=label, **style)
        ax2.plot(xs, [per[x]["ciede2000"] for x in xs], label=label, **style)
    for ax, name in ((ax1, "PSNR (dB)"), (ax2, "CIEDE2000 (lower is better)")):
        ax.set_xscale("log")
        ax.set_xlabel("exposure N: photo-electrons of a lossless full-light pixel")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3, which="both")
    if title is None:
        title = "LMMSE (thin dashed) and networks (thick)" if networks else "LMMSE"
        title += " at equal exposure (photon model)"
    ax1.set_title(title, fontsize=10)
    ax2.legend(fontsize=7 if len(results) > 8 else 8, loc="upper right")
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def difference_chart(
    curves: Sequence[Mapping],
    path: str | os.PathLike,
    *,
    title: str | None = None,
    xlabel: str = "exposure N: photo-electrons of a lossless full-light pixel",
    unit: str = "",
    legend: str = "upper right",
) -> Path:
    """Candidate − reference against exposure (log axis), one panel per reference: the mean
    over images as a line, its bootstrap band shaded, and each crossover (the exposure below
    which the candidate wins) marked with its interval as a bar on the zero line.

    ``curves``: what :func:`splitcam.evaluation.exposure.difference_curves` returns (their
    exposures may be given in another unit, e.g. lux, named by ``unit`` in the legend);
    ``legend``: where the legend goes (matplotlib's ``loc``)."""
    import matplotlib
    from matplotlib.figure import Figure

    references = list(dict.fromkeys(c["reference"] for c in curves))
    candidates = list(dict.fromkeys(c["candidate"] for c in curves))
    cycle = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {c: cycle[i % len(cycle)] for i, c in enumerate(candidates)}
    fig = Figure(figsize=(5.2 * len(references), 4.4))
    axes = fig.subplots(1, len(references), squeeze=False)[0]
    for ax, reference in zip(axes, references, strict=True):
        mine = [c for c in curves if c["reference"] == reference]
        for k, c in enumerate(mine):
            xs, col = c["photons"], colour[c["candidate"]]
            cross = c["crossover"]
            point = cross["crossover"]
            where = (
                "never"
                if point is None
                else ("always" if point == float("inf") else f"{float(f'{point:.2g}'):g}")
            )
            below = f"wins below {where}{' ' + unit if unit and point else ''}"
            ax.plot(xs, c["mean"], "-o", ms=3, color=col, label=f"{c['candidate']} ({below})")
            ax.fill_between(xs, c["low"], c["high"], color=col, alpha=0.18, lw=0)
            if point is not None and point != float("inf"):
                lo = cross["low"] if cross["low"] > 0 else xs[0]
                hi = min(cross["high"], xs[-1])
                y = -0.08 * (k + 1)
                ax.plot([lo, hi], [y, y], color=col, lw=3, alpha=0.7, solid_capstyle="butt")
                ax.plot([point], [y], "|", color="black", ms=9)
        ax.axhline(0.0, color="black", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel(xlabel)
        metric = mine[0]["metric"].upper() if mine else ""
        ax.set_ylabel(f"{metric}: candidate − {reference}" + (" (dB)" if metric == "PSNR" else ""))
        ax.set_title(f"against {reference}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, loc=legend)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)
