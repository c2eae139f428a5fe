"""Filters and splitters at equal exposure: image quality against light level, and the raw SNR
against theory (model.md §11).

:func:`exposure_study` scores the closed-form LMMSE of every pattern (its filters solved for the
photon model's signal-dependent noise, model.md §10) on test images simulated at exposures
from a few to thousands of photo-electrons per full-light pixel, with the same photon flux for
every pattern, and finds the exposure below which each splitter beats the Bayer filter.
:func:`raw_snr_check` compares the raw images' SNR of each pattern with the filter's before any
reconstruction, against ``10 log10 k`` (shot-noise limited) and ``20 log10 k`` (read-noise
limited) for a ``k``-fold signal gain.

Both take a light domain (model.md §13); the default is ``linear``, where photons belong: the
scenes are decoded to linear radiance before the sensor and the noise, the LMMSE filters come
from the linear image statistics, and reconstructions are encoded back to 8-bit sRGB to be
scored. ``srgb`` takes the display values as light (the paper's protocol).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..io import write_text
from ..io.domains import LINEAR
from ..patterns import Pattern, builtin, check_pattern
from ..physics.light import check_domain, decode_scene
from ..physics.noise import Exposure, add_exposure_noise, level_label
from ..physics.radiometry import Camera
from ..physics.sensor import SplitterSensor
from ..recon.base import Reconstructor
from ..recon.closed_form import closed_form_lmmse
from .metrics import mean_over_images
from .protocol import Images, check_method_domains, evaluate
from .tables import domain_line, markdown_table

__all__ = [
    "crossings",
    "crossover",
    "crossover_interval",
    "describe_crossover",
    "difference_curves",
    "interval_ends",
    "interval_text",
    "two_figures",
    "exposure_study",
    "raw_snr_check",
    "write_study",
]

DEFAULT_PATTERNS = ("A", "B", "C", "D", "E", "bayer")


def default_exposures(count: int = 9) -> list[float]:
    """Log-spaced full-light exposures from 1 to 10^4 photo-electrons."""
    return [float(v) for v in np.logspace(0, 4, count)]


def _patterns(patterns: Sequence[Pattern] | None) -> list[Pattern]:
    """The patterns given (each checked), or the built-in :data:`DEFAULT_PATTERNS`."""
    if patterns is None:
        return [builtin(name) for name in DEFAULT_PATTERNS]
    return [check_pattern(p) for p in patterns]


def exposure_study(
    images: Images,
    *,
    patterns: Sequence[Pattern] | None = None,
    photons: Sequence[float] | None = None,
    read_noise: float = 2.0,
    methods: Sequence[Reconstructor] = (),
    progress: bool = True,
    domain: str = LINEAR,
    out: str | os.PathLike[str] | None = None,
    scene_sets: dict[str, str] | None = None,
    restart: bool = False,
    rescore_changed: bool = False,
    **settings: Any,
) -> dict[str, dict[float, dict[str, float]]]:
    """``{label: {photons: {"psnr", "ssim", "ciede2000"}}}``: the closed-form LMMSE of each
    pattern (label: the pattern's name) and each of ``methods`` (label: the method's name, e.g.
    a network trained with ``--noise photon``) on ``images`` at each exposure (means over
    images), in the light domain ``domain`` (default ``linear``; every method must be of it).
    ``settings``: the other settings of :class:`~splitcam.physics.noise.Exposure`
    (``full_well``, ``gain``, ``bits``).

    It is :func:`~splitcam.evaluation.protocol.evaluate` at the photon model's exposures, so
    the numbers are the protocol's; with ``out``, its files are written there as each image is
    scored, and a run interrupted and started again with the same ``out`` continues where it
    stopped (results of the same method, image, exposure and sensor are reused); ``restart``
    discards the results ``out`` holds instead (for instance those of other weights), and
    ``rescore_changed`` (:func:`~splitcam.evaluation.protocol.evaluate`'s) scores again only
    the methods whose weights or pattern changed since (a model shipped since), keeping the
    others' results.
    ``scene_sets``: ``{image name: scene set}`` (Kodak24, McMaster, ...), so that crossovers
    are also given per set (:func:`write_study`); the images are scored as one set either way.

    Raises:
        ValueError: A bad exposure setting, an unknown domain, a method of another domain, or
            two methods of one name.
    """
    domain = check_method_domains(methods, domain)
    photons = list(photons or default_exposures())
    exposures = [Exposure(n, read_noise=read_noise, **settings) for n in photons]  # checked first
    loaded = _patterns(patterns)  # a pattern file is labelled by its pattern's name
    lmmse = {f"lmmse-{p.name}": p.name for p in loaded}
    todo: list[Reconstructor] = [
        closed_form_lmmse(p, domain=domain, name=label)
        for p, label in zip(loaded, lmmse, strict=True)
    ]
    todo += list(methods)
    rows = evaluate(
        todo,
        [("images", list(images))],
        exposures,
        out,
        progress=progress,
        domain=domain,
        resume=not restart,
        rescore_changed=rescore_changed,
    )
    results: dict[str, dict[float, dict[str, Any]]] = {}
    for method in todo:
        mine = [r for r in rows if r.method == method.name]
        results[lmmse.get(method.name, method.name)] = {
            n: _level_scores([r for r in mine if r.level == level], scene_sets)
            for n, level in zip(photons, map(level_label, exposures), strict=True)
        }
    return results


METRICS = ("psnr", "ssim", "ciede2000")


def _level_scores(rows: list, scene_sets: dict[str, str] | None = None) -> dict[str, Any]:
    """The means over images of one method at one exposure, and ``per_image``: each metric's
    values in the order of ``images`` (``set/image`` names: the image's scene set from
    ``scene_sets``, else its dataset), for intervals over images."""
    sets = scene_sets or {}
    rows = sorted(rows, key=lambda r: (sets.get(r.image, r.dataset), r.image))
    out: dict[str, Any] = {
        key: mean_over_images(getattr(r, key) for r in rows).mean for key in METRICS
    }
    out["per_image"] = {key: [float(getattr(r, key)) for r in rows] for key in METRICS}
    out["images"] = [f"{sets.get(r.image, r.dataset)}/{r.image}" for r in rows]
    return out


def two_figures(value: float) -> str:
    """``value`` to two significant figures, written plainly: 242 → ``240``, 72.9 → ``73``,
    1931 → ``1900``, 3.16 → ``3.2``."""
    return f"{float(f'{value:.2g}'):g}"


def crossover_interval(
    curves: Any,
    reference: Any,
    photons: Sequence[float],
    *,
    higher_is_better: bool = True,
    level: float = 0.9,
    draws: int = 2000,
    seed: int = 0,
) -> dict[str, Any]:
    """The crossover of :func:`crossover` with a bootstrap interval over images.

    Args:
        curves: ``(images, exposures)`` per-image scores of the candidate at ``photons``.
        reference: The same of the reference, on the same images in the same order.
        photons: The exposures.
        higher_is_better: False for CIEDE2000.
        level: The interval's coverage (0.9: the 5th and 95th percentiles of the crossovers of
            ``draws`` resamples of the images, with replacement).
        draws: The number of resamples.
        seed: Of the resampling.

    Returns:
        ``{"crossover", "low", "high", "never", "everywhere", "images", "draws", "level"}``:
        the crossover of the mean curves (None: never wins; inf: wins at every exposure), the
        interval's ends (0: the lower end lies below the lowest exposure studied, never
        winning; inf: above the highest), and the shares of resamples in which the candidate
        never wins or wins everywhere.
    """
    a = np.asarray(curves, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != len(photons) or a.shape[0] < 1:
        raise ValueError(
            f"expected per-image scores (images, {len(photons)}) of one shape, got "
            f"{a.shape} and {b.shape}"
        )
    sign = 1.0 if higher_is_better else -1.0
    diff = sign * (a - b)
    zero = dict.fromkeys(photons, 0.0)

    def cross(mean_diff: np.ndarray) -> float:
        v = crossover(dict(zip(photons, mean_diff.tolist(), strict=True)), zero)
        return 0.0 if v is None else v

    point = crossover(dict(zip(photons, diff.mean(0).tolist(), strict=True)), zero)
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, diff.shape[0], size=(draws, diff.shape[0]))
    values = np.array([cross(diff[idx].mean(0)) for idx in picks])
    tail = (1.0 - level) / 2.0
    low, high = np.quantile(values, [tail, 1.0 - tail], method="inverted_cdf")
    return {
        "crossover": point,
        "low": float(low),
        "high": float(high),
        "never": float(np.mean(values == 0.0)),
        "everywhere": float(np.mean(np.isinf(values))),
        "images": int(diff.shape[0]),
        "draws": draws,
        "level": level,
    }


def difference_curves(
    results: dict[str, dict[float, dict[str, Any]]],
    pairs: Sequence[tuple[str, str]],
    *,
    metric: str = "psnr",
    level: float = 0.9,
    draws: int = 2000,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """For each ``(candidate, reference)`` of ``pairs`` (labels of an exposure study's
    results with per-image scores): the mean difference candidate − reference at each
    exposure, its ``level`` bootstrap band over the images (percentiles of the resampled
    means, exposure by exposure) and the crossover with its interval
    (:func:`crossover_interval`); what :func:`splitcam.viz.charts.difference_chart` draws.
    CIEDE2000 differences are reference − candidate, so that positive always means the
    candidate is better."""
    photons = sorted(next(iter(results.values())))
    sign = -1.0 if metric == "ciede2000" else 1.0
    tail = (1.0 - level) / 2.0
    out = []
    for candidate, reference in pairs:
        ours, names = _per_image(results[candidate], metric, photons, None)
        theirs, their_names = _per_image(results[reference], metric, photons, None)
        if ours is None or theirs is None or names != their_names:
            raise ValueError(
                f"{candidate} against {reference}: per-image scores of the same images needed"
            )
        diff = sign * (ours - theirs)
        picks = np.random.default_rng(seed).integers(0, len(diff), size=(draws, len(diff)))
        means = diff[picks].mean(axis=1)  # (draws, exposures)
        out.append(
            {
                "candidate": candidate,
                "reference": reference,
                "metric": metric,
                "photons": photons,
                "mean": diff.mean(0).tolist(),
                "low": np.quantile(means, tail, axis=0, method="inverted_cdf").tolist(),
                "high": np.quantile(means, 1 - tail, axis=0, method="inverted_cdf").tolist(),
                "crossover": crossover_interval(
                    ours,
                    theirs,
                    photons,
                    higher_is_better=sign > 0,
                    level=level,
                    draws=draws,
                    seed=seed,
                ),
            }
        )
    return out


def interval_ends(interval: dict[str, Any], photons: Sequence[float]) -> tuple[str, str]:
    """The ends of a :func:`crossover_interval` as tables write them: two significant figures,
    ``<1`` or ``>10000`` where an end lies outside the exposures studied."""
    lo, hi = interval["low"], interval["high"]
    low = f"<{two_figures(min(photons))}" if lo == 0.0 else two_figures(lo)
    high = f">{two_figures(max(photons))}" if math.isinf(hi) else two_figures(hi)
    return low, high


def interval_text(interval: dict[str, Any], photons: Sequence[float]) -> str:
    """``[140, 520]``: a :func:`crossover_interval` as the crossover tables write it
    (:func:`interval_ends`)."""
    return "[{}, {}]".format(*interval_ends(interval, photons))


def crossover(
    curve: dict[float, float], reference: dict[float, float], higher_is_better: bool = True
) -> float | None:
    """The exposure below which ``curve`` beats ``reference``, interpolated in log exposure where
    their difference changes sign (the highest such crossing); ``inf`` if it wins everywhere,
    ``None`` if it never wins."""
    xs = sorted(curve)
    d = [(curve[x] - reference[x]) * (1 if higher_is_better else -1) for x in xs]
    if all(v > 0 for v in d):
        return math.inf
    if d[0] <= 0:
        return None
    for i in range(len(xs) - 1):
        if d[i] > 0 >= d[i + 1]:
            t = d[i] / (d[i] - d[i + 1])
            return float(
                10 ** (math.log10(xs[i]) + t * (math.log10(xs[i + 1]) - math.log10(xs[i])))
            )
    return None


def crossings(photons: Sequence[float], diff: Sequence[float], tol: float = 0.0) -> list[tuple]:
    """``[(N, "down" | "up")]``: where ``diff`` (in order of ``photons``) changes sign,
    interpolated linearly in log exposure; ``down``: positive below, negative above. Values
    within ``tol`` of 0 count as 0 and are stepped over."""
    signed = [(x, d) for x, d in zip(photons, diff, strict=True) if abs(d) > tol]
    out = []
    for (x0, d0), (x1, d1) in zip(signed, signed[1:], strict=False):
        if (d0 > 0) != (d1 > 0):
            t = d0 / (d0 - d1)
            at = 10 ** (math.log10(x0) + t * (math.log10(x1) - math.log10(x0)))
            out.append((float(at), "down" if d0 > 0 else "up"))
    return out


def describe_crossover(curve: dict[float, float], ref: dict[float, float]) -> str:
    """Where ``curve`` beats ``ref`` (higher is better), as the crossover tables say it: the
    exposure below which it wins (:func:`crossover`); where it does not win at the lowest
    exposure but does higher up, the exposures where it wins (between two crossings, or above
    one); or never.

    >>> describe_crossover({1: 2.0, 100: 0.0}, {1: 1.0, 100: 1.0})
    'N ≈ 10'
    >>> describe_crossover({1: 0.0, 10: 2.0, 100: 0.0}, {1: 1.0, 10: 1.0, 100: 1.0})
    'never below; between N ≈ 3.2 and 32'
    """
    v = crossover(curve, ref)
    if v is not None:
        return "every exposure studied" if math.isinf(v) else f"N ≈ {two_figures(v)}"
    xs = sorted(curve)
    found = crossings(xs, [curve[x] - ref[x] for x in xs])
    if not found:
        return "never"
    if found[-1][1] == "up":
        return f"never below; above N ≈ {two_figures(found[-1][0])}"
    lo = next(n for n, way in reversed(found) if way == "up")
    return f"never below; between N ≈ {two_figures(lo)} and {two_figures(found[-1][0])}"


def _per_image(result: dict, key: str, photons: list[float], subset: str | None):
    """``(images, exposures)`` scores of one result (only the images of dataset ``subset``),
    with the image names; None where the result holds no per-image scores."""
    first = result[photons[0]]
    if "per_image" not in first:
        return None, None
    names = first["images"]
    keep = [i for i, n in enumerate(names) if subset is None or n.split("/")[0] == subset]
    values = np.array([[result[n]["per_image"][key][i] for n in photons] for i in keep])
    return values, [names[i] for i in keep]


def _crossover_table(
    results: dict[str, dict[float, dict[str, Any]]],
    photons: list[float],
    refs: list[str],
    references_of: dict[str, dict[str, str]] | None = None,
    title_suffix: str = "",
    subset: str | None = None,
    record: list | None = None,
) -> list[str]:
    """A crossover section of ``exposure.md``: one row per label of ``results`` (a pattern's,
    or a network's), PSNR and CIEDE2000 columns per reference; ``references_of[label][ref]``:
    the label ``label`` is compared with for reference pattern ``ref`` (default ``ref``
    itself); a reference a row has none of shows ``—``. Where the results hold per-image
    scores, each crossover is followed by its 90 % bootstrap interval over the images
    (:func:`crossover_interval`), appended to ``record`` as data; ``subset``: only the images
    of that dataset."""
    if refs == ["bayer"]:
        title = "## Crossover: the exposure below which each pattern beats the Bayer filter"
        head = ["pattern", "PSNR", "CIEDE2000"]
    else:
        title = "## Crossover: the exposure below which each pattern beats " + " and ".join(refs)
        head = ["pattern", *(f"vs {r}: {m}" for r in refs for m in ("PSNR", "CIEDE2000"))]
    if subset is not None:
        title += f", {subset} only"
    rows = []
    intervals = False
    for p, r in results.items():
        mine = (references_of or {}).get(p, {name: name for name in refs})
        if len(refs) == 1 and mine.get(refs[0]) == p:
            continue
        row = []
        for name in refs:
            against = mine.get(name)
            if against is None or against == p or against not in results:
                row += ["—", "—"]
                continue
            for key, sign in (("psnr", 1), ("ciede2000", -1)):
                ours, names = _per_image(r, key, photons, subset)
                theirs, their_names = _per_image(results[against], key, photons, subset)
                if ours is not None and names == their_names and len(names):
                    curve = {n: sign * v for n, v in zip(photons, ours.mean(0), strict=True)}
                    ref = {n: sign * v for n, v in zip(photons, theirs.mean(0), strict=True)}
                    interval = crossover_interval(ours, theirs, photons, higher_is_better=sign > 0)
                    text = describe_crossover(curve, ref)
                    point = interval["crossover"]
                    if point is not None and math.isinf(point):
                        text += f" (in {interval['everywhere']:.0%} of resamples)"
                    elif point is not None:
                        text += f" {interval_text(interval, photons)}"
                    intervals = True
                    if record is not None:
                        record.append(
                            {
                                "candidate": p,
                                "reference": against,
                                "metric": key,
                                "scene_set": subset or "all",
                                "text": text,
                                **interval,
                            }
                        )
                else:
                    curve = {n: sign * r[n][key] for n in photons}
                    ref = {n: sign * results[against][n][key] for n in photons}
                    text = describe_crossover(curve, ref)
                row.append(text)
        rows.append([p, *row])
    lines = ["", title + title_suffix, ""]
    if intervals:
        lines += [
            "Each crossover with its 90 % interval over the images (bootstrap: the 5th and "
            "95th percentiles of the crossovers of 2000 resamples of the images); an end "
            "written `<` the lowest exposure: in at least 5 % of resamples the candidate never "
            "wins, `>` the highest: in at least 5 % it wins at every exposure studied. A "
            "candidate that wins at every exposure: the share of resamples in which it does.",
            "",
        ]
    return [*lines, *markdown_table(head, rows)]


def _crossover_sections(
    results: dict, photons: list[float], references: Sequence[str], networks: dict | None
) -> tuple[list[str], list[dict]]:
    """The crossover tables of ``exposure.md`` (the LMMSE's, then the networks'; pooled, then
    each scene set apart where there are several) and their records as data."""
    networks = networks or {}
    lines: list[str] = []
    lmmse = {k: v for k, v in results.items() if k not in networks}
    refs = [r for r in references if r in lmmse]
    net_refs = [r for r in references if r in networks.values()]
    nets = {k: v for k, v in results.items() if k in networks}
    crossovers: list[dict] = []
    # Pooled over every image, then each scene set apart where there are several.
    first = next(iter(results.values()))[photons[0]]
    sets = sorted({n.split("/")[0] for n in first.get("images", [])})
    for subset in [None, *sets] if len(sets) > 1 else [None]:
        if refs:
            suffix = " (closed-form LMMSE)" if networks else ""
            lines += _crossover_table(
                lmmse, photons, refs, title_suffix=suffix, subset=subset, record=crossovers
            )
        if net_refs:
            lines += _crossover_table(
                nets,
                photons,
                net_refs,
                network_references(networks, net_refs),
                title_suffix=" (networks, each against the reference's network)",
                subset=subset,
                record=crossovers,
            )
    return lines, crossovers


def _lux_section(crossovers: list[dict], camera: Camera, photons: list[float]) -> list[str]:
    """The pooled PSNR crossovers in scene lux (each record gets ``lux``: the crossover and its
    interval's ends in lux, None where they lie outside the exposures studied)."""

    def lux(n: float | None) -> float | None:
        return None if n is None or n == 0.0 or math.isinf(n) else camera.lux(n)

    rows = []
    for c in crossovers:
        c["lux"] = [lux(c["crossover"]), lux(c["low"]), lux(c["high"])]
        if c["scene_set"] != "all" or c["metric"] != "psnr":
            continue
        point, low, high = c["lux"]
        if point is None:
            continue
        lo = f"<{two_figures(camera.lux(min(photons)))}" if low is None else two_figures(low)
        hi = f">{two_figures(camera.lux(max(photons)))}" if high is None else two_figures(high)
        rows.append(
            [
                c["candidate"],
                c["reference"],
                c["text"].split(" [")[0],
                f"{two_figures(point)} lux [{lo}, {hi}]",
            ]
        )
    if not rows:
        return []
    return [
        "",
        f"## The crossovers in lux ({camera.describe()})",
        "",
        f"N = 1 photo-electron is {camera.lux(1.0):.3g} lux on the scene with this camera "
        "(splitcam.physics.radiometry: the camera equation on axis; photons counted over "
        "400-700 nm). PSNR crossovers pooled over the images, with their 90 % intervals:",
        "",
        *markdown_table(["sensor", "beats", "below N", "below scene illuminance"], rows),
    ]


def network_references(networks: dict[str, str], refs: Sequence[str]) -> dict[str, dict[str, str]]:
    """``{label: {ref: label of the network it is compared with}}`` for the networks of an
    exposure study (``networks``: ``{label: pattern name}``): a network is compared only with
    the network of the reference pattern of the same kind
    (:func:`~splitcam.recon.registry.network_kind`: ``net-universal-photon-A`` against
    ``net-universal-photon-rgbw``, ``net-A-photon`` against ``net-rgbw-photon``); none where
    there is no such network (a comparison with a network made another way would measure the two
    trainings as much as the two sensors).

    >>> nets = {"net-u-A": "A", "net-u-rgbw": "rgbw", "net-A-ph": "A", "net-bayer-ph": "bayer"}
    >>> refs = network_references(nets, ["bayer", "rgbw"])
    >>> refs["net-u-A"], refs["net-A-ph"]
    ({'rgbw': 'net-u-rgbw'}, {'bayer': 'net-bayer-ph'})
    """
    from ..recon.registry import network_kind

    kind = {label: network_kind(label, pattern) for label, pattern in networks.items()}
    return {
        label: {
            ref: other
            for ref in refs
            for other, theirs in networks.items()
            if theirs == ref and kind[other] == kind[label]
        }
        for label in networks
    }


def raw_snr_check(
    images: Images,
    *,
    patterns: Sequence[Pattern] | None = None,
    shot_limited: float = 1e4,
    read_limited: float = 10.0,
    read_noise: float = 20.0,
    domain: str = LINEAR,
) -> dict[str, dict[str, float]]:
    """Raw SNR of each pattern against the Bayer filter, before reconstruction, of the scenes
    as light of ``domain`` (default ``linear``: decoded to radiance).

    SNR of a raw image: ``10 log10(mean clean^2 / mean noise^2)`` over all its pixels. ``k``: the
    pattern's mean raw signal over the filter's on the same images. Shot-limited: no read noise
    at ``shot_limited`` photo-electrons (the gain in SNR should be ``10 log10 k``);
    read-limited: no shot noise, ``read_noise`` electrons at ``read_limited`` photo-electrons
    (``20 log10 k``).

    Returns:
        ``{pattern: {"k", "shot_gain_db", "shot_theory_db", "read_gain_db", "read_theory_db"}}``.
    """
    domain = check_domain(domain)
    regimes = {
        "shot": Exposure(shot_limited, read_noise=0.0),
        "read": Exposure(read_limited, read_noise=read_noise, shot=False),
    }
    signal: dict[str, float] = {}
    snr: dict[str, dict[str, float]] = {}
    for pattern in _patterns(patterns):
        name = pattern.name
        sensor = SplitterSensor(pattern)
        clean_power, total = 0.0, 0.0
        noise_power = {r: 0.0 for r in regimes}
        count = 0
        for image_name, rgb in images:
            with torch.no_grad():
                clean = sensor(decode_scene(rgb[None].double(), domain))
            clean_power += float((clean**2).sum())
            total += float(clean.sum())
            count += clean.numel()
            for regime, exposure in regimes.items():
                noisy = add_exposure_noise(clean, image_name, exposure)
                noise_power[regime] += float(((noisy - clean) ** 2).sum())
        signal[name] = total / count
        snr[name] = {r: 10 * math.log10(clean_power / noise_power[r]) for r in regimes}
    ref = "bayer"
    out = {}
    for name in signal:
        k = signal[name] / signal[ref]
        out[name] = {
            "k": k,
            "shot_gain_db": snr[name]["shot"] - snr[ref]["shot"],
            "shot_theory_db": 10 * math.log10(k),
            "read_gain_db": snr[name]["read"] - snr[ref]["read"],
            "read_theory_db": 20 * math.log10(k),
        }
    return out


def _camera_record(camera: Camera) -> dict:
    """The camera in the study's JSON; the scene light where it is not D65's (relit scenes)."""
    record = {"settings": camera.describe(), "electrons_per_lux": camera.electrons_per_lux}
    if camera.white != 1:
        record.update(illuminant=camera.illuminant, white=camera.white)
    return record


def write_study(
    results: dict[str, dict[float, dict[str, float]]],
    snr: dict[str, dict[str, float]] | None,
    out: str | os.PathLike[str],
    *,
    note: str = "",
    domain: str = LINEAR,
    references: Sequence[str] = ("bayer",),
    networks: dict[str, str] | None = None,
    camera: Camera | None = None,
) -> Path:
    """``exposure.md`` (tables, crossovers, raw SNR check), ``exposure.json`` and
    ``exposure.png`` (PSNR and CIEDE2000 against exposure) in ``out``; ``domain``: the light
    domain the results are of, stated in both files. ``references``: the patterns every other
    is compared with in the crossover table (those among ``results``; default the Bayer
    filter), two columns (PSNR, CIEDE2000) each. ``networks``: ``{label: pattern name}`` of the
    results that are networks' (the others are the LMMSE's, labelled by pattern); they get a
    crossover table of their own, each network against the reference's network
    (:func:`network_references`), the best reconstruction of each sensor against the best of
    the reference. ``camera``: the crossovers pooled over the images are also stated in scene
    lux for that camera (:class:`~splitcam.physics.radiometry.Camera`), in both files."""
    domain = check_domain(domain)
    from ..viz.charts import exposure_chart

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    chart = exposure_chart(results, out / "exposure.png", networks=networks)
    photons = sorted(next(iter(results.values())))
    lines = _score_sections(results, photons, note, domain, networks)
    crossing, crossovers = _crossover_sections(results, photons, references, networks)
    lines += crossing
    if camera is not None and crossovers:
        lines += _lux_section(crossovers, camera, photons)
    if snr:
        lines += _raw_snr_section(snr)
    lines += ["", f"![exposure]({chart.name})", ""]
    record = {
        "results": {p: {f"{n:g}": v for n, v in r.items()} for p, r in results.items()},
        "crossovers": crossovers,
        "camera": None if camera is None else _camera_record(camera),
        "raw_snr": snr,
        "domain": domain,
    }
    write_text(out / "exposure.json", json.dumps(record, indent=1) + "\n")
    path = out / "exposure.md"
    write_text(path, "\n".join(lines))
    return path


def _score_sections(
    results: dict[str, dict[float, dict[str, float]]],
    photons: list[float],
    note: str,
    domain: str,
    networks: dict[str, str] | None,
) -> list[str]:
    """The study's opening and its PSNR and CIEDE2000 tables, one column per exposure."""
    head = ["pattern", *(f"N={n:.3g}" if n < 1000 else f"N={n:.0f}" for n in photons)]
    return [
        "# Filters and splitters at equal exposure",
        "",
        note,
        "",
        domain_line([domain]),
        "",
        "Closed-form LMMSE of every pattern"
        + (", and the networks (rows `net-...`)," if networks else "")
        + " under the photon model (shot noise, read noise, "
        "the same photon flux for every pattern); `N`: photo-electrons a lossless, "
        "filterless pixel collects from a white scene.",
        "",
        "## PSNR (dB)",
        "",
        *markdown_table(
            head, ([p, *(f"{r[n]['psnr']:.2f}" for n in photons)] for p, r in results.items())
        ),
        "",
        "## CIEDE2000 (lower is better)",
        "",
        *markdown_table(
            head,
            ([p, *(f"{r[n]['ciede2000']:.3f}" for n in photons)] for p, r in results.items()),
        ),
    ]


def _raw_snr_section(snr: dict[str, dict[str, float]]) -> list[str]:
    """The raw SNR check against the Bayer filter, before any reconstruction."""
    return [
        "",
        "## Raw SNR against the Bayer filter, before reconstruction",
        "",
        "`k`: mean raw signal over the filter's. Shot-limited gain should be "
        "10·log10 k, read-limited 20·log10 k.",
        "",
        *markdown_table(
            ["pattern", "k", "shot-limited gain (theory)", "read-limited gain (theory)"],
            (
                [
                    p,
                    f"{v['k']:.3f}",
                    f"{v['shot_gain_db']:+.2f} dB ({v['shot_theory_db']:+.2f})",
                    f"{v['read_gain_db']:+.2f} dB ({v['read_theory_db']:+.2f})",
                ]
                for p, v in snr.items()
            ),
        ),
    ]
