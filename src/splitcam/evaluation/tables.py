"""Evaluation results as rows, files and tables: one row per method, image and sigma
(:class:`EvalRow`), ``per_image.csv`` written row by row (so an interrupted evaluation keeps what
it did), and the means per image set in the layout of the paper's Table 1.

Every row records its light domain (model.md §13: ``srgb``, the paper's protocol, or
``linear``); a file written without the ``domain`` column reads as ``srgb``. Results of one
method in two domains are kept apart: in summaries and tables a method of the linear domain is
labelled ``<method> (linear)`` (:func:`result_label`), and every table says its domain."""

from __future__ import annotations

import csv
import json
import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import astuple, dataclass, fields
from pathlib import Path

from ..io import appending, atomic_path, write_text
from ..io.domains import DOMAINS, LINEAR, SRGB
from ..physics.noise import Exposure, level_heading, level_key, level_label
from .metrics import mean_over_images

__all__ = [
    "markdown_row",
    "markdown_rule",
    "markdown_table",
    "CSV_NAME",
    "ENTRY_FIELDS",
    "METRICS",
    "EvalRow",
    "append_rows",
    "domain_line",
    "image_crop",
    "pooled_groups",
    "markdown_tables",
    "method_of_label",
    "read_rows",
    "result_label",
    "summarise",
    "write_summary",
]

METRICS = ("psnr", "ssim", "ciede2000")
CSV_NAME = "per_image.csv"
# Scores at full precision: a resumed evaluation reads them back and must summarise exactly like
# an uninterrupted one.
_FORMATS = {
    "sigma": "{:g}",
    "psnr": "{!r}",
    "ssim": "{!r}",
    "ciede2000": "{!r}",
    "photons": "{:g}",
}


def result_label(method: str, domain: str = SRGB) -> str:
    """What labels a method's results of a light domain in summaries and tables: the method's
    name in ``srgb``, ``"<name> (linear)"`` in ``linear``."""
    return method if domain == SRGB else f"{method} ({domain})"


def method_of_label(label: str, domain: str = SRGB) -> str:
    """The method's name of a :func:`result_label`."""
    return label if domain == SRGB else label.removesuffix(f" ({domain})")


@dataclass(frozen=True)
class EvalRow:
    """The scores of one method on one image at one noise level.

    The noise level is the paper's Gaussian ``sigma`` (8-bit units) when ``photons`` is 0, else
    the photon model's exposure ``photons`` (full-light photo-electrons; ``sigma`` is 0 and the
    sensor's other settings are the evaluation's, in its ``evaluation.json``). ``domain``: the
    light domain the scene was simulated and reconstructed in (scores are always of 8-bit sRGB).
    ``noise``: the label of a level of another :class:`~splitcam.physics.noise.NoiseModel`
    (empty for the Gaussian and photon models, which ``sigma`` and ``photons`` identify).
    """

    method: str
    pattern: str
    dataset: str
    image: str
    sigma: float
    psnr: float
    ssim: float
    ciede2000: float
    photons: float = 0.0
    domain: str = SRGB
    noise: str = ""

    @property
    def key(self) -> tuple[str, str, str, str, str]:
        """What identifies the row in an evaluation: method, dataset, image, noise level,
        light domain."""
        return (self.method, self.dataset, self.image, self.level, self.domain)

    @property
    def label(self) -> str:
        """The method's label in summaries and tables (:func:`result_label`)."""
        return result_label(self.method, self.domain)

    @property
    def level(self) -> str:
        """The noise level as it labels tables and summaries: ``"15"`` (sigma) or ``"N1000"``
        (photo-electrons)."""
        if self.noise:
            return self.noise
        return level_label(Exposure(self.photons) if self.photons else self.sigma)

    def cells(self) -> list[str]:
        return [
            _FORMATS.get(f.name, "{}").format(v)
            for f, v in zip(fields(self), astuple(self), strict=True)
        ]


def append_rows(path: str | os.PathLike, rows: Iterable[EvalRow]) -> None:
    """Append rows to a CSV file (header first if the file is new), flushed to disk. A file
    written before a column was added is rewritten whole, with today's header, first."""
    path = Path(path)
    rows = list(rows)
    new = not path.is_file() or path.stat().st_size == 0
    names = [f.name for f in fields(EvalRow)]
    if not new:
        with open(path, newline="", encoding="utf-8") as fh:
            header = next(csv.reader(fh), None)
        if header != names:
            rows = read_rows(path) + rows
            with atomic_path(path) as tmp:
                append_rows(tmp, rows)
            return
    with appending(path, newline="") as fh:
        writer = csv.writer(fh)
        if new:
            writer.writerow(names)
        for row in rows:
            writer.writerow(row.cells())
        fh.flush()
        os.fsync(fh.fileno())


def read_rows(path: str | os.PathLike) -> list[EvalRow]:
    """Rows of a ``per_image.csv``; a last line cut short by a kill is dropped. Files without
    the ``noise`` column read as rows of the Gaussian or photon model; without ``domain`` also,
    as rows of the ``srgb`` domain; without ``photons`` also, as Gaussian rows.

    Raises:
        ValueError: The file is not a per-image results file (the message names it).
    """
    path = Path(path)
    names = [f.name for f in fields(EvalRow)]
    with open(path, newline="", encoding="utf-8") as fh:
        lines = list(csv.reader(fh))
    if not lines:
        return []
    if lines[0] not in (names, names[:-1], names[:-2], names[:-3]):
        raise ValueError(f"{str(path)!r} is not a splitcam per-image results file")
    numbers = slice(4, min(len(lines[0]), 9))  # sigma ... photons
    rows = []
    for cells in lines[1:]:
        if len(cells) != len(lines[0]) or (len(cells) > 9 and cells[9] not in DOMAINS):
            continue  # a line cut short by a kill
        try:
            rows.append(EvalRow(*cells[:4], *(float(v) for v in cells[numbers]), *cells[9:]))
        except (TypeError, ValueError):
            continue  # a line cut short by a kill
    return rows


def write_summary(rows: Sequence[EvalRow], out_dir: str | os.PathLike) -> dict:
    """``per_image.csv`` (rewritten from ``rows``), ``summary.json`` and ``table.md`` in
    ``out_dir``; returns the summary."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(out_dir / CSV_NAME) as tmp:
        append_rows(tmp, rows)
    summary = summarise(rows)
    write_text(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    write_text(out_dir / "table.md", markdown_tables(summary))
    return summary


_CROPPED = re.compile(r"-(\d+)px$")


def image_crop(dataset: str) -> str:
    """How a dataset's images were cut before scoring: ``"256px"`` for the centre crops that
    ``--max-size 256`` names ``NAME-256px``, ``"whole"`` otherwise."""
    match = _CROPPED.search(dataset)
    return f"{match.group(1)}px" if match else "whole"


def pooled_groups(rows: Sequence[EvalRow]) -> dict[str, set[str]]:
    """The pooled image sets of a summary and the datasets each pools: ``{"all": every
    dataset}`` when every dataset's images were cut alike, else one ``"all-<crop>"`` per crop
    (``all-whole``, ``all-256px``): a 256-px crop of a photo never ranks beside the whole
    photo. Where a dataset's own name starts with ``all`` the pool is ``all-sets`` instead, so
    the two never merge."""
    crops: dict[str, set[str]] = {}
    for row in rows:
        crops.setdefault(image_crop(row.dataset), set()).add(row.dataset)
    # A folder of images named like the pool would merge with it: the pool is renamed.
    pool = "all-sets" if any(d.startswith("all") for d in {r.dataset for r in rows}) else "all"
    if len(crops) <= 1:
        return {pool: {r.dataset for r in rows}}
    return {f"{pool}-{crop}": sets for crop, sets in crops.items()}


def summarise(rows: Sequence[EvalRow]) -> dict:
    """``{label: {"pattern": name, "domain": domain, dataset|pool: {level: {metric: mean,
    "n_images": n, "n_infinite": k}}}}``, ``label`` the method's name, ``"<name> (linear)"``
    for its results in the linear domain (:func:`result_label`), ``level`` as
    :attr:`EvalRow.level` (``"15"`` or ``"N1000"``), a pool as :func:`pooled_groups` names
    it: ``"all"``, or ``"all-whole"`` and ``"all-256px"`` in a folder of both."""
    summary: dict = {}
    labels = list(dict.fromkeys(r.label for r in rows))
    pools = pooled_groups(rows)
    for label in labels:
        mine = [r for r in rows if r.label == label]
        groups = list(dict.fromkeys(r.dataset for r in mine))
        entry: dict = {"pattern": mine[0].pattern, "domain": mine[0].domain}
        mine_pools = [p for p, sets in pools.items() if sets & set(groups)]
        for group in [*groups, *mine_pools]:
            chosen = (
                [r for r in mine if r.dataset in pools[group]]
                if group in pools
                else [r for r in mine if r.dataset == group]
            )
            per_sigma = {}
            for level in sorted({r.level for r in chosen}, key=level_key):
                at = [r for r in chosen if r.level == level]
                stats = {}
                for metric in METRICS:
                    m = mean_over_images(getattr(r, metric) for r in at)
                    stats[metric] = m.mean
                    if metric == "psnr":
                        stats["n_infinite"] = m.n_infinite
                stats["n_images"] = len(at)
                per_sigma[level] = stats
            entry[group] = per_sigma
        summary[label] = entry
    return summary


#: The fields of a summary entry that are not image sets.
ENTRY_FIELDS = ("pattern", "domain")

_DOMAIN_TEXT = {
    SRGB: "srgb (the paper's protocol: the 8-bit sRGB values / 255 are the light the sensor sees)",
    LINEAR: "linear (scenes decoded to linear radiance before the sensor and the noise, "
    "reconstructions encoded back to 8-bit sRGB before scoring; model.md §13)",
}


def domain_line(domains: Iterable[str]) -> str:
    """The line that says which light domain(s) a table's results are in."""
    found = list(dict.fromkeys(domains)) or [SRGB]
    if len(found) == 1:
        return f"Light domain: {_DOMAIN_TEXT[found[0]]}."
    marked = ", ".join(f"`<method> ({d})`" for d in found if d != SRGB)
    return (
        f"Light domains: rows labelled {marked} are of that domain, the others of srgb. "
        + "; ".join(_DOMAIN_TEXT[d] for d in found)
        + "."
    )


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """The lines of a Markdown table: the header, the rule, one line per row (cells as given).
    Every table splitcam writes is made here.

    >>> markdown_table(["method", "σ=0"], [["lmmse", "30.00"]])
    ['| method | σ=0 |', '|---|---|', '| lmmse | 30.00 |']
    """
    return [markdown_row(header), markdown_rule(len(header))] + [markdown_row(r) for r in rows]


def aligned_table(rows: Sequence[dict[str, str]]) -> str:
    """A Markdown table whose columns are padded to line up, so that it also reads as plain
    text in a terminal (the listings of ``splitcam patterns``, ``models``, ...): the keys of
    the first row are the header.

    >>> print(aligned_table([{"name": "A", "white": "1.000"}]))
    | name | white |
    |------|-------|
    | A    | 1.000 |
    """
    keys = list(rows[0])
    widths = {k: max(len(k), *(len(r[k]) for r in rows)) for k in keys}
    lines = ["| " + " | ".join(k.ljust(widths[k]) for k in keys) + " |"]
    lines.append("|" + "|".join("-" * (widths[k] + 2) for k in keys) + "|")
    lines += ["| " + " | ".join(r[k].ljust(widths[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def markdown_row(cells: Sequence[str]) -> str:
    """One line of a Markdown table (:func:`markdown_table`), for tables written line by line."""
    return "| " + " | ".join(cells) + " |"


def markdown_rule(columns: int) -> str:
    """The rule under a Markdown table's header of ``columns`` columns."""
    return "|" + "---|" * columns


def markdown_tables(summary: dict) -> str:
    """PSNR/SSIM per sigma in the layout of the paper's Table 1 (one table per image set), and
    CIEDE2000 likewise."""
    methods = list(summary)
    groups = list(dict.fromkeys(g for m in methods for g in summary[m] if g not in ENTRY_FIELDS))
    if len(groups) == 2 and groups[1] == "all":  # one image set: "all" would repeat it
        groups = groups[:1]
    sigmas = list(dict.fromkeys(s for m in methods for g in groups for s in summary[m].get(g, {})))
    lines: list[str] = [domain_line(summary[m].get("domain", SRGB) for m in methods), ""]
    for group in groups:
        n = max(
            (
                summary[m][group][s]["n_images"]
                for m in methods
                if group in summary[m]
                for s in summary[m][group]
            ),
            default=0,
        )
        counts = {st["n_images"] for m in methods for st in summary[m].get(group, {}).values()}
        lines += [f"### {group} ({n} image{'s' if n != 1 else ''}): PSNR (dB) / SSIM", ""]
        if len(counts) > 1:
            lines += [
                "Cells over fewer images are marked (n = ...): they are means over other "
                "images and do not rank against the rest.",
                "",
            ]
        headings = [level_heading(s) for s in sigmas]
        rows = []
        for m in methods:
            cells = []
            for s in sigmas:
                st = summary[m].get(group, {}).get(s)
                mark = f" (n = {st['n_images']})" if st and st["n_images"] != n else ""
                cells.append("–" if st is None else f"{_db(st['psnr'])} / {st['ssim']:.4f}{mark}")
            rows.append([m, summary[m]["pattern"], *cells])
        lines += markdown_table(["method", "pattern", *headings], rows)
        lines += ["", f"### {group}: CIEDE2000 (lower is better)", ""]
        rows = [
            [
                m,
                *(
                    "–"
                    if (st := summary[m].get(group, {}).get(s)) is None
                    else f"{st['ciede2000']:.3f}"
                    for s in sigmas
                ),
            ]
            for m in methods
        ]
        lines += markdown_table(["method", *headings], rows)
        lines.append("")
    lines += colour_drop_lines(summary, sigmas)
    return "\n".join(lines)


#: The two test sets whose difference measures how a method holds on saturated colour: Kodak24
#: (photographs of muted colour, like the training photos) and McMaster (saturated colours and
#: sharp colour edges, weak correlation between channels).
DROP_SETS = ("kodak24", "mcmaster")


def colour_drop_lines(summary: dict, sigmas: Sequence[str]) -> list[str]:
    """A table of each method's Kodak24 PSNR minus its McMaster PSNR at each level, when both
    sets (cut alike) are in the summary: how much a method loses on saturated colour. Empty
    otherwise."""
    groups = {g for m in summary.values() for g in m if g not in ENTRY_FIELDS}
    pairs = [
        (g, DROP_SETS[1] + g.removeprefix(DROP_SETS[0]))
        for g in sorted(groups)
        if g.startswith(DROP_SETS[0]) and DROP_SETS[1] + g.removeprefix(DROP_SETS[0]) in groups
    ]
    lines: list[str] = []
    for kodak, mcmaster in pairs:
        rows = []
        for method, entry in summary.items():
            if kodak not in entry or mcmaster not in entry:
                continue
            cells = [
                _db(entry[kodak][s]["psnr"] - entry[mcmaster][s]["psnr"])
                if s in entry[kodak] and s in entry[mcmaster]
                else "–"
                for s in sigmas
            ]
            rows.append([method, *cells])
        if rows:
            lines += [
                f"### {kodak} minus {mcmaster}: PSNR (dB), the drop on saturated colour",
                "",
            ]
            lines += markdown_table(["method", *(level_heading(s) for s in sigmas)], rows)
            lines.append("")
    return lines


def _db(v: float) -> str:
    return "inf" if math.isinf(v) else f"{v:.2f}"
