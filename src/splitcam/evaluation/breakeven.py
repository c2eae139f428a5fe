"""Where a lossy colour router ties a filter array: the break-even map (model.md §§11, 14, 15).

:func:`break_even` scores the closed-form LMMSE of ``router(eta, chi)`` (the same efficiency and
crosstalk in every band, on pattern A's geometry) over a grid of ``(eta, chi)`` against a
reference pattern (default ``rgbw``, an ideal RGBW filter array) at each exposure of the photon
model, and finds for each grid point the exposure where the difference router − reference
changes sign. :func:`verdict` classifies one difference curve; it is what every grid point goes
through. Cells with ``eta + chi > 1`` would create light and are marked ``infeasible``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io import write_text
from ..io.domains import LINEAR
from ..patterns import Pattern, builtin, check_pattern, router
from ..recon.base import Reconstructor
from ..recon.closed_form import closed_form_lmmse
from .exposure import (
    crossings,
    crossover_interval,
    default_exposures,
    exposure_study,
    interval_ends,
)
from .protocol import Images
from .tables import markdown_table

__all__ = [
    "DEFAULT_CHIS",
    "DEFAULT_ETAS",
    "against",
    "break_even",
    "crossings",
    "preset_points",
    "verdict",
    "write_break_even",
]

DEFAULT_ETAS = tuple(round(float(v), 3) for v in np.linspace(0.3, 1.0, 8))
"""Band efficiencies of the default grid: 0.3 to 1 in 8 steps."""
DEFAULT_CHIS = tuple(round(float(v), 3) for v in np.linspace(0.0, 0.35, 8))
"""Crosstalk of the default grid: 0 to 0.35 in 8 steps."""


def verdict(photons: Sequence[float], diff: Sequence[float], tol: float = 0.0) -> dict[str, Any]:
    """Classify a difference curve ``candidate − reference`` (higher is better) over exposure.

    Returns:
        ``{"verdict", "break_even", "crossings"}``. ``verdict``: ``tie`` (every difference
        within ``tol`` of 0), ``always`` (never worse, better somewhere), ``never`` (never
        better), ``below`` (better below ``break_even`` only), ``above`` (better above it only)
        or ``mixed`` (several crossings). ``break_even``: the exposure of the crossing (of
        several, the highest), None without one.
    """
    found = crossings(photons, diff, tol)
    if all(abs(d) <= tol for d in diff):
        kind = "tie"
    elif not found:
        kind = "always" if max(diff) > tol else "never"
    elif len(found) == 1:
        kind = "below" if found[0][1] == "down" else "above"
    else:
        kind = "mixed"
    return {
        "verdict": kind,
        "break_even": found[-1][0] if found else None,
        "crossings": [[n, way] for n, way in found],
    }


def _label(eta: float, chi: float) -> str:
    return f"router(eta={eta:g};chi={chi:g})"


def break_even(
    images: Images,
    *,
    etas: Sequence[float] = DEFAULT_ETAS,
    chis: Sequence[float] = DEFAULT_CHIS,
    photons: Sequence[float] | None = None,
    reference: Pattern | None = None,
    metric: str = "psnr",
    candidate: Callable[[float, float], Pattern] | None = None,
    method: Callable[[Pattern], Reconstructor] | None = None,
    read_noise: float = 2.0,
    domain: str = LINEAR,
    tol: float = 0.0,
    progress: bool = False,
    **settings: Any,
) -> dict[str, Any]:
    """The break-even map of routers against ``reference`` (closed-form LMMSE of each, or
    ``method``'s reconstruction of each).

    Args:
        images: Test images ``[(name, (3, H, W))]``.
        etas: The grid's band efficiencies, the same for R, G and B.
        chis: The grid's crosstalk fractions, the same for R, G and B.
        photons: Exposures ``N`` (default: 9 log-spaced from 1 to 10^4).
        reference: The pattern to tie (default: the built-in ``rgbw``).
        metric: ``psnr`` or ``ssim`` (higher is better) or ``ciede2000`` (lower is better; the
            difference is then taken reference − router so that positive still means the
            router is better).
        candidate: ``(eta, chi) -> Pattern`` (default :func:`~splitcam.patterns.router`).
        method: ``pattern -> Reconstructor``, how every sensor of the map (the reference too)
            is reconstructed, e.g. a network for any pattern trained under the photon model
            (default: each pattern's closed-form LMMSE).
        read_noise: The photon model's read noise (electrons), as in
            :func:`~splitcam.evaluation.exposure.exposure_study`.
        domain: The light domain, as there.
        settings: The photon model's other settings, as there.
        tol: Differences within ``tol`` of 0 (in the metric's unit) count as ties
            (:func:`verdict`).

    Returns:
        ``{"reference", "metric", "read_noise", "domain", "photons", "etas", "chis",
        "reference_curve": [value per N], "cells": [{"eta", "chi", "label", "verdict",
        "break_even", "crossings", "difference": [per N]}]}``, cells row by row (eta outer);
        :func:`verdict` says what each verdict means, ``infeasible`` marks ``eta + chi > 1``.

    Raises:
        ValueError: An unknown metric, or a bad exposure setting.
    """
    if metric not in ("psnr", "ssim", "ciede2000"):
        raise ValueError(f"metric must be psnr, ssim or ciede2000, got {metric!r}")
    sign = -1.0 if metric == "ciede2000" else 1.0
    photons = sorted(float(n) for n in (photons or default_exposures()))
    make = candidate or (lambda e, x: router(e, x, name=_label(e, x)))
    study = {"photons": photons, "read_noise": read_noise, "domain": domain, "progress": False}

    reconstruct = method or _closed_form(domain)

    def curve_of(rec: Reconstructor) -> dict[float, dict[str, float]]:
        return exposure_study(images, patterns=[], methods=[rec], **study, **settings)[rec.name]

    ref = builtin("rgbw") if reference is None else check_pattern(reference, "reference")
    ref_method = reconstruct(ref)
    ref_curve = curve_of(ref_method)
    # the map's reconstruction, named as the reference's without the pattern: net-universal-photon
    label = "closed-form LMMSE" if method is None else ref_method.name.removesuffix(f"-{ref.name}")
    ref_values = [ref_curve[n][metric] for n in photons]
    ref_images = _images(ref_curve, photons, metric)
    grid = [(float(e), float(x)) for e in etas for x in chis]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(grid), desc="break-even map")
    cells = []
    for eta, chi in grid:
        cell: dict[str, Any] = {"eta": eta, "chi": chi, "label": _label(eta, chi)}
        if eta + chi > 1 + 1e-12:
            cell.update(verdict="infeasible", break_even=None, crossings=[], difference=None)
        else:
            curve = curve_of(reconstruct(make(eta, chi)))
            diff = [sign * (curve[n][metric] - r) for n, r in zip(photons, ref_values, strict=True)]
            cell.update(verdict(photons, diff, tol), difference=diff)
            ours = _images(curve, photons, metric)
            if ours is not None and ref_images is not None:
                cell.update(_interval(photons, sign * (ours - ref_images), cell))
        cells.append(cell)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return {
        "reference": ref.name,
        "method": label,
        "metric": metric,
        "read_noise": read_noise,
        "domain": domain,
        "tol": tol,
        "photons": photons,
        "etas": [float(e) for e in etas],
        "chis": [float(x) for x in chis],
        "reference_curve": ref_values,
        "reference_images": ref_images.tolist() if ref_images is not None else None,
        "cells": cells,
    }


def against(
    result: dict[str, Any],
    reference: Pattern,
    images: Images,
    *,
    method: Callable[[Pattern], Reconstructor] | None = None,
    **settings: Any,
) -> dict[str, Any]:
    """The map of :func:`break_even` against another reference, without reconstructing a router
    again: each router's curve is the old reference's plus its difference, so only the new
    reference is reconstructed (on the same ``images``, exposures, photon model and
    reconstruction: ``method`` and ``settings`` as given to :func:`break_even`).

    Raises:
        ValueError: As :func:`break_even`.
    """
    ref = check_pattern(reference, "reference")
    domain = result["domain"]
    reconstruct = method or _closed_form(domain)
    photons = result["photons"]
    if settings.pop("read_noise", result["read_noise"]) != result["read_noise"]:
        raise ValueError("against(): the map's read noise is its own; give no other")
    study = {"photons": photons, "read_noise": result["read_noise"], "domain": domain}
    rec = reconstruct(ref)
    curve = exposure_study(images, patterns=[], methods=[rec], progress=False, **study, **settings)
    values = [curve[rec.name][n][result["metric"]] for n in photons]
    sign = -1.0 if result["metric"] == "ciede2000" else 1.0
    shift = [sign * (old - new) for old, new in zip(result["reference_curve"], values, strict=True)]
    theirs = _images(curve[rec.name], photons, result["metric"])
    cells = []
    for cell in result["cells"]:
        if cell["difference"] is None:
            cells.append(dict(cell))
            continue
        diff = [d + s for d, s in zip(cell["difference"], shift, strict=True)]
        where = {k: cell[k] for k in ("eta", "chi", "label")}
        new = {**where, **verdict(photons, diff, result["tol"]), "difference": diff}
        old_images = result.get("reference_images")
        if cell.get("difference_images") is not None and theirs is not None and old_images:
            # per image: router − new reference = (router − old) + (old − new)
            per_shift = sign * (np.asarray(old_images) - theirs)
            new.update(_interval(photons, np.asarray(cell["difference_images"]) + per_shift, new))
        cells.append(new)
    return {
        **result,
        "reference": ref.name,
        "reference_curve": values,
        "reference_images": theirs.tolist() if theirs is not None else None,
        "cells": cells,
    }


def _images(curve: dict, photons: Sequence[float], metric: str) -> np.ndarray | None:
    """``(images, exposures)`` per-image scores of an exposure-study curve, or None."""
    if "per_image" not in curve[photons[0]]:
        return None
    return np.array([curve[n]["per_image"][metric] for n in photons]).T


def _interval(photons: Sequence[float], diff_images: np.ndarray, cell: dict) -> dict[str, Any]:
    """The per-image differences of a cell, kept (for :func:`against`), and where the router
    wins below a break-even exposure, its 90 % bootstrap interval over the images
    (:func:`~splitcam.evaluation.exposure.crossover_interval`)."""
    out: dict[str, Any] = {"difference_images": diff_images.tolist(), "interval": None}
    if cell["verdict"] == "below":
        iv = crossover_interval(diff_images, np.zeros_like(diff_images), list(photons))
        out["interval"] = [iv["low"], iv["high"]]
    return out


def _closed_form(domain: str) -> Callable[[Pattern], Reconstructor]:
    """The map's default reconstruction: each pattern's closed-form LMMSE."""
    return lambda p: closed_form_lmmse(p, domain=domain, name=f"lmmse-{p.name}")


def preset_points(names: Sequence[str] = ("router-zou", "router-best")) -> dict[str, tuple]:
    """``{name: (eta, chi)}``: a router preset's effective efficiency and crosstalk, the means
    over R, G and B of the ``eta`` and ``chi`` in its metadata (white light)."""
    out = {}
    for name in names:
        meta = builtin(name).metadata
        out[name] = (float(np.mean(meta["eta"])), float(np.mean(meta["chi"])))
    return out


def write_break_even(
    result: dict[str, Any], out: str | os.PathLike[str], *, note: str = ""
) -> Path:
    """``breakeven.json`` (the result), ``breakeven.png`` (the map,
    :func:`splitcam.viz.breakeven.breakeven_chart`, with the router presets marked) and
    ``breakeven.md`` (the map as a table) in ``out``; returns the ``.md`` path."""
    from ..viz.breakeven import breakeven_chart, cell_text

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    presets = preset_points()
    write_text(out / "breakeven.json", json.dumps({**result, "presets": presets}, indent=1) + "\n")
    chart = breakeven_chart(result, out / "breakeven.png", presets=presets)
    cells = {(c["eta"], c["chi"]): c for c in result["cells"]}
    lines = [
        f"# Break-even map: router(η, χ) against {result['reference']}",
        "",
        note,
        "",
        f"Light domain: {result['domain']}. "
        f"{result.get('method', 'closed-form LMMSE').capitalize()} of each sensor, "
        f"{result['metric'].upper()}, read noise {result['read_noise']:g} e-, exposures "
        + ", ".join(f"{n:.3g}" for n in result["photons"])
        + f"; differences within {result['tol']:g} count as ties.",
        "",
        "Each cell: `<N` the router is better below exposure N, `>N` above it, `a–b` between "
        "a and b (several crossings, the last two shown), `N*` other crossings (the highest), "
        "`all` / `none` better at every / no exposure, empty: "
        "η + χ > 1 (infeasible). Rows η, columns χ.",
        "",
    ]
    lines += _map_table(result, lambda e, x: cell_text(cells[(e, x)]))
    if any(c.get("interval") for c in result["cells"]):
        lines += [
            "",
            "90 % intervals over the images of the break-even exposures `<N` (bootstrap, 2000 "
            "resamples; `<1`: in some resamples the router never wins, `>N`: in some it wins "
            "at every exposure studied):",
            "",
        ]
        lines += _map_table(result, lambda e, x: _interval_cell(cells[(e, x)], result["photons"]))
    lines += ["", "Router presets (mean η, χ over R, G, B):", ""]
    lines += [f"- {name}: η = {e:.3f}, χ = {x:.3f}" for name, (e, x) in presets.items()]
    lines += ["", f"![break-even map]({chart.name})", ""]
    path = out / "breakeven.md"
    write_text(path, "\n".join(lines))
    return path


def _map_table(result: dict[str, Any], text: Callable[[float, float], str]) -> list[str]:
    """The map as a Markdown table: rows η, columns χ, each cell ``text(eta, chi)``."""
    return markdown_table(
        ["η \\ χ", *(f"{x:g}" for x in result["chis"])],
        ([f"{e:g}", *(text(e, x) for x in result["chis"])] for e in result["etas"]),
    )


def _interval_cell(cell: dict, photons: Sequence[float]) -> str:
    """A cell's interval as the map's table writes it (``140–520``), or nothing."""
    interval = cell.get("interval")
    if not interval:
        return ""
    return "{}–{}".format(*interval_ends({"low": interval[0], "high": interval[1]}, photons))
