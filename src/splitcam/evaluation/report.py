"""Reports: evaluation results side by side with the paper's numbers, pattern figures and
PSNR/CIEDE2000-against-sigma charts (the paper's Table 1-3, Fig. 6 and Fig. 9)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from .. import patterns
from ..io import write_text
from ..io.domains import SRGB
from ..io.paper import PAPER_PATTERNS, PAPER_SIGMAS, TABLE1_PATTERNS
from ..physics.noise import level_heading, level_key, parse_level_label
from ..viz.charts import exposure_chart, sigma_chart
from ..viz.patterns import draw_pattern
from .tables import (
    DROP_SETS,
    ENTRY_FIELDS,
    domain_line,
    markdown_row,
    markdown_rule,
    markdown_table,
    method_of_label,
)

#: The paper's test sets: its numbers are means over all their images, whole.
PAPER_DATASETS = {"kodak24": 24, "mcmaster": 18}

#: model.md §8: mean over Kodak24 and McMaster (42 images), PSNR dB / SSIM, from 10^6 GPU
#: training steps on DIV2K (Liu & Lam, Tables 1-3).
PAPER = {
    "A": [(40.02, 0.9764), (37.58, 0.9569), (35.72, 0.9376), (34.44, 0.9207), (33.47, 0.9052)],
    "B": [(32.93, 0.9198), (32.70, 0.9132), (32.33, 0.9035), (31.93, 0.8937), (31.54, 0.8836)],
    "C": [(31.53, 0.9159), (31.37, 0.9088), (31.08, 0.8986), (30.77, 0.8881), (30.45, 0.8773)],
    "D": [(40.35, 0.9773), (38.56, 0.9650), (36.62, 0.9491), (35.17, 0.9341), (34.02, 0.9195)],
    "E": [(35.65, 0.9674), (34.84, 0.9552), (33.89, 0.9404), (33.08, 0.9264), (32.37, 0.9125)],
    "A optimised": [
        (40.33, 0.9772),
        (38.38, 0.9631),
        (36.57, 0.9468),
        (35.27, 0.9319),
        (34.25, 0.9178),
    ],
    "D optimised": [
        (41.03, 0.9797),
        (38.98, 0.9668),
        (36.96, 0.9508),
        (35.49, 0.9361),
        (34.34, 0.9219),
    ],
}
#: The level labels of the paper's columns (``"0"`` ... ``"20"``).
PAPER_LEVELS = tuple(f"{s:g}" for s in PAPER_SIGMAS)

#: The shipped model that reproduces each row of the paper's Tables 1-3 (and bayer beside them).
PAPER_MODELS = {
    "A": "A",
    "B": "B",
    "C": "C",
    "D": "D",
    "E": "E",
    "bayer": "bayer",
    "A optimised": "A-opt",
    "D optimised": "D-opt",
    "D optimised (random init.)": "D-opt-random",
}


def paper_row(pattern: patterns.Pattern) -> str | None:
    """The paper's row for a pattern: its name, or "X optimised" for one learned from X."""
    if pattern.provenance == "learned":
        start = str(pattern.metadata.get("start", ""))
        key = f"{start} optimised"
    else:
        key = pattern.name
    return key if key in PAPER else None


def comparable(method: str, entry: dict) -> bool:
    """Whether a result compares with the paper's numbers: a network (not the LMMSE or a
    classical demosaicker) scored on all of Kodak24 and McMaster, whole (cropped datasets are
    named ``kodak24-256px``), in the paper's light domain (srgb)."""
    if method.startswith("lmmse") or method.startswith("bayer+"):
        return False
    if entry.get("domain", SRGB) != SRGB:
        return False
    sets = {k for k in entry if k != "all" and k not in ENTRY_FIELDS}
    if sets != set(PAPER_DATASETS):
        return False
    return all(
        max(st["n_images"] for st in entry[name].values()) == n
        for name, n in PAPER_DATASETS.items()
    )


def _load(results: list[str | os.PathLike]) -> list[tuple[str, str, dict, patterns.Pattern]]:
    """``(folder, method, summary entry, pattern)`` for every method of every result folder."""
    out = []
    for folder in results:
        folder = Path(folder)
        summary_path = folder / "summary.json"
        if not summary_path.is_file():
            raise FileNotFoundError(
                f"{str(folder)!r} has no summary.json; give folders written by `splitcam evaluate`"
            )
        try:
            summary = json.loads(summary_path.read_text(encoding="utf-8"))
            if not isinstance(summary, dict):
                raise ValueError("not a JSON object")
        except (ValueError, UnicodeDecodeError) as exc:
            raise ValueError(
                f"{str(summary_path)!r} is damaged ({exc}); run `splitcam evaluate` "
                f"again to rewrite it"
            ) from None
        for method, entry in summary.items():
            if "all" not in entry:
                raise ValueError(
                    f"{str(folder)!r} holds image sets cut differently (whole photos and "
                    f"centre crops); give a folder of one evaluation's image sets"
                )
            name = method_of_label(method, entry.get("domain", SRGB))
            pattern_file = folder / "patterns" / f"{name}.json"
            pattern = (
                patterns.load(pattern_file)
                if pattern_file.is_file()
                else patterns.get(entry["pattern"])
            )
            out.append((folder.name, method, entry, pattern))
    if not out:
        raise ValueError("no methods found in the given result folders")
    return out


def make_report(results: list[str | os.PathLike], out: str | os.PathLike) -> Path:
    """Write ``report.md``, ``patterns/*.png`` and ``sigma_curves.png`` into ``out``."""
    out = Path(out)
    (out / "patterns").mkdir(parents=True, exist_ok=True)
    entries = _load(results)
    sigmas = sorted({s for _, _, e, _ in entries for s in e["all"]}, key=level_key)
    lines = [
        "# splitcam report",
        "",
        "Ours: mean over all images evaluated (`all`); the paper: mean over Kodak24 + McMaster "
        "(42 images) after 10^6 GPU training steps on DIV2K. Cells: ours PSNR dB / SSIM, then, "
        "for a network scored on all of Kodak24 and McMaster whole (what the paper's numbers "
        "are), (paper PSNR, difference ours − paper). B, C and E are modelled patterns "
        "(docs/model.md section 2), so their gaps are not only a matter of training budget.",
        "",
        domain_line(e.get("domain", SRGB) for _, _, e, _ in entries),
        "",
        *_score_tables(entries, sigmas),
        "",
        "## Patterns",
        "",
        *_pattern_figures(entries, out / "patterns"),
        *_curve_charts(entries, sigmas, out),
    ]
    report = out / "report.md"
    write_text(report, "\n".join(lines) + "\n")
    return report


def _score_tables(entries: list, sigmas: list[str]) -> list[str]:
    """PSNR / SSIM per level (with the paper's where comparable), then CIEDE2000."""
    headings = [level_heading(s) for s in sigmas]
    rows = []
    for folder, method, entry, pattern in entries:
        ref = paper_row(pattern) if comparable(method, entry) else None
        cells = []
        for s in sigmas:
            st = entry["all"].get(s)
            if st is None:
                cells.append("–")
                continue
            cell = f"{st['psnr']:.2f} / {st['ssim']:.4f}"
            if ref and s in PAPER_LEVELS:
                p_psnr = PAPER[ref][PAPER_LEVELS.index(s)][0]
                cell += f" ({p_psnr:.2f}, {st['psnr'] - p_psnr:+.2f})"
            cells.append(cell)
        n = max(st["n_images"] for st in entry["all"].values())
        rows.append([folder, method, pattern.name, str(n), *cells])
    lines = markdown_table(["result", "method", "pattern", "images", *headings], rows)
    lines += ["", "## CIEDE2000 (lower is better)", ""]
    rows = [
        [
            folder,
            method,
            *(f"{entry['all'][s]['ciede2000']:.3f}" if s in entry["all"] else "–" for s in sigmas),
        ]
        for folder, method, entry, _ in entries
    ]
    return lines + markdown_table(["result", "method", *headings], rows)


def _pattern_figures(entries: list, folder: Path) -> list[str]:
    """One figure per distinct pattern (two different patterns of one name get one each)."""
    lines: list[str] = []
    drawn: list[tuple[patterns.Pattern, str]] = []
    for *_, pattern in entries:
        if any(pattern.equals(p) and pattern.name == p.name for p, _ in drawn):
            continue
        # Two different patterns of one name (two runs' "D-learned") get a figure each.
        taken = {name for _, name in drawn}
        name, k = pattern.name, 2
        while name in taken:
            name, k = f"{pattern.name}-{k}", k + 1
        drawn.append((pattern, name))
        path = folder / f"{name}.png"
        draw_pattern(pattern, path)
        lines.append(f"![pattern {name}](patterns/{path.name})")
    return lines


def _curve_charts(entries: list, sigmas: list[str], out: Path) -> list[str]:
    """The charts against noise (with the paper's curves) and against exposure, where the
    results hold such levels."""
    lines: list[str] = []
    several = len({f for f, *_ in entries}) > 1
    curves = [
        (f"{folder}: {method}" if several else method, entry["all"])
        for folder, method, entry, _ in entries
    ]
    kinds = {
        (f"{folder}: {method}" if several else method): pattern.name
        for folder, method, _, pattern in entries
    }
    refs = dict.fromkeys(
        r
        for _, method, entry, pattern in entries
        if comparable(method, entry) and (r := paper_row(pattern))
    )
    references = {
        ref: [(float(s), p) for s, (p, _) in zip(PAPER_LEVELS, PAPER[ref], strict=True)]
        for ref in refs
    }
    if any(parse_level_label(s)[0] == "sigma" for s in sigmas):
        chart = sigma_chart(curves, out / "sigma_curves.png", references, patterns_of=kinds)
        lines += ["", "## PSNR and CIEDE2000 against noise", "", f"![curves]({chart.name})", ""]
    exposures = {
        label: {
            value: st
            for s, st in per.items()
            for kind, value in [parse_level_label(s)]
            if kind == "photons"
        }
        for label, per in curves
    }
    if any(exposures.values()):
        chart = exposure_chart(
            {k: v for k, v in exposures.items() if v},
            out / "exposure_curves.png",
            title="at equal exposure (photon model)",
        )
        lines += ["", "## PSNR and CIEDE2000 against exposure", "", f"![exposure]({chart.name})"]
    return lines


#: The curves of the paper's Fig. 9, by the names of its rows.
FIG9 = ("bayer", "D", "D optimised", "D optimised (random init.)")


def _cell(ours: dict | None, paper: tuple[float, float] | None) -> str:
    if ours is None:
        return "–"
    text = f"{ours['psnr']:.2f} / {ours['ssim']:.4f}"
    if paper is not None:
        text += f" ({paper[0]:.2f}, {ours['psnr'] - paper[0]:+.2f})"
    return text


def _ranks(values: dict[str, float]) -> dict[str, int]:
    order = sorted(values, key=lambda k: -values[k])
    return {k: order.index(k) + 1 for k in values}


Check = tuple[str, bool, str]


def _d_ahead_of_a(at, sigmas: list[str], have) -> list[Check]:
    if not have("A", "D"):
        return []
    d = [at("D", s) - at("A", s) for s in sigmas]
    return [("D ahead of A at every σ", all(x > 0 for x in d), "D − A: " + _db(d))]


def _b_and_c_last(at, sigmas: list[str], have) -> list[Check]:
    if not have("A", "B", "C", "D"):
        return []
    # With E not yet evaluated the ranking is among the four there are: B and C last among
    # A-D is what "last of A-E" requires of them (E is third in the paper).
    present = [k for k in TABLE1_PATTERNS if have(k)]
    among = "" if len(present) == len(TABLE1_PATTERNS) else f" (among {', '.join(present)})"
    bottom = {len(present) - 1, len(present)}
    last = []
    for s in sigmas:
        ranks = _ranks({k: at(k, s) for k in present})
        last.append({ranks["B"], ranks["C"]} == bottom)
    spread = {k: at(k, sigmas[0]) - at(k, sigmas[-1]) for k in present}
    flat = max(spread["B"], spread["C"]) < min(spread["A"], spread["D"])
    drops = ", ".join(f"{k} {v:.2f}" for k, v in spread.items())
    return [
        (
            "B and C last at every σ" + among,
            all(last),
            f"last two at {sum(last)} of {len(sigmas)} σ",
        ),
        (
            "B and C nearly flat in σ (drop smaller than A's and D's)",
            flat,
            f"drop σ={sigmas[0]}→{sigmas[-1]}: {drops} dB",
        ),
    ]


def _optimised_ahead(at, sigmas: list[str], have) -> list[Check]:
    out = []
    for start in ("A", "D"):
        opt = f"{start} optimised"
        if have(start, opt):
            d = [at(opt, s) - at(start, s) for s in sigmas]
            out.append((f"{opt} ahead of {start} at every σ", all(x > 0 for x in d), _db(d)))
    return out


def _optimised_ahead_of_bayer(at, sigmas: list[str], have) -> list[Check]:
    if not have("D optimised", "bayer"):
        return []
    dp = [at("D optimised", s) - at("bayer", s) for s in sigmas]
    dc = [at("D optimised", s, "ciede2000") - at("bayer", s, "ciede2000") for s in sigmas]
    return [
        ("D optimised ahead of bayer in PSNR at every σ", all(x > 0 for x in dp), _db(dp)),
        (
            "D optimised ahead of bayer in CIEDE2000 at every σ",
            all(x < 0 for x in dc),
            ", ".join(f"{x:+.3f}" for x in dc),
        ),
    ]


def _random_start_close(at, sigmas: list[str], have) -> list[Check]:
    if not have("D optimised", FIG9[3]):
        return []
    d = [at(FIG9[3], s) - at("D optimised", s) for s in sigmas]
    return [
        (
            "D optimised from random within 0.3 dB of D optimised",
            all(abs(x) <= 0.3 for x in d),
            _db(d),
        )
    ]


def _db(values: list[float]) -> str:
    return ", ".join(f"{x:+.2f}" for x in values) + " dB"


#: The paper's conclusions, each a function ``(at, sigmas, have) -> [(statement, holds,
#: numbers)]`` that says nothing when its rows are missing; in the order of the report.
CONCLUSIONS = (
    _d_ahead_of_a,
    _b_and_c_last,
    _optimised_ahead,
    _optimised_ahead_of_bayer,
    _random_start_close,
)


def checks(summary: dict, rows: dict[str, str], sigmas: list[str]) -> list[Check]:
    """The paper's conclusions (model.md §8, :data:`CONCLUSIONS`), each ``(statement, holds,
    the numbers)``, on the mean over all images. ``rows`` maps paper row names to method names
    in ``summary``."""

    def at(row: str, s: str, metric: str = "psnr") -> float | None:
        method = rows.get(row)
        entry = summary.get(method, {}).get("all", {}).get(s) if method else None
        return None if entry is None else entry[metric]

    def have(*names: str) -> bool:
        return all(at(n, s) is not None for n in names for s in sigmas)

    return [check for conclusion in CONCLUSIONS for check in conclusion(at, sigmas, have)]


@dataclass(frozen=True)
class _Tables:
    """What every section of ``reproduce.md`` reads: the summary, the paper row → method map,
    the noise levels of the rows present (in the summary's order) and the folder written to."""

    summary: dict
    rows: dict[str, str]
    sigmas: list[str]
    out: Path

    @classmethod
    def of(cls, summary: dict, rows: dict[str, str], out: Path) -> _Tables:
        sigmas = list(
            dict.fromkeys(s for m in rows.values() if m in summary for s in summary[m]["all"])
        )
        return cls(summary, rows, sigmas, out)

    def has(self, row: str) -> bool:
        """Whether the paper row's method is in the summary."""
        return self.rows.get(row) in self.summary

    def ours(self, row: str, s: str) -> dict | None:
        """Our means of a paper row at one level (``None`` where it was not evaluated)."""
        m = self.rows.get(row)
        return self.summary[m]["all"].get(s) if m in self.summary else None

    @staticmethod
    def paper(row: str, s: str) -> tuple[float, float] | None:
        """The paper's PSNR and SSIM of a row at one level, where the paper has them."""
        if row in PAPER and s in PAPER_LEVELS:
            return PAPER[row][PAPER_LEVELS.index(s)]
        return None

    @property
    def head(self) -> str:
        return _line("pattern", [f"σ={s}" for s in self.sigmas])

    @property
    def rule(self) -> str:
        return markdown_rule(1 + len(self.sigmas))

    def cells_row(self, row: str) -> str:
        """A table line of ours beside the paper's (:func:`_cell`) at every level."""
        return _line(row, [_cell(self.ours(row, s), self.paper(row, s)) for s in self.sigmas])


def _line(first: str, cells: list[str]) -> str:
    """A markdown table line."""
    return markdown_row([first, *cells])


def _intro(t: _Tables) -> list[str]:
    n = max(
        (
            t.summary[m]["all"][s]["n_images"]
            for m in t.rows.values()
            if m in t.summary
            for s in t.summary[m]["all"]
        ),
        default=0,
    )
    domains = (t.summary[m].get("domain", SRGB) for m in t.rows.values() if m in t.summary)
    return [
        "# The paper's tables, reproduced with splitcam's shipped models",
        "",
        f"Ours: mean over {n} images; cells are our PSNR dB / SSIM, then (the paper's PSNR, "
        "ours − paper). The paper trained 10^6 GPU steps of batch 80 on DIV2K; our budgets are "
        "below. B, C and E are modelled patterns (model.md §2).",
        "",
        domain_line(domains),
        "",
    ]


def _budget_section(t: _Tables, budgets: dict[str, str] | None) -> list[str]:
    lines = ["## Budget of each model", ""]
    for row, method in t.rows.items():
        lines.append(f"- **{row}** (`{method}`): {(budgets or {}).get(row, 'unknown')}")
    return lines


def _table1_section(t: _Tables) -> list[str]:
    """Table 1 (A-E and bayer) and, for A-E, the ranks by PSNR at every level."""
    lines = ["", "## Table 1: every pattern, fixed", "", t.head, t.rule]
    present = [r for r in PAPER_PATTERNS if t.has(r)]
    lines += [t.cells_row(row) for row in present]
    ranked = [r for r in TABLE1_PATTERNS if r in present]
    if not ranked:
        return lines
    lines += [
        "",
        "Ranks by PSNR among A–E (ours; the paper's in brackets: D 1, A 2, E 3, B 4, C 5):",
        "",
        t.head.replace("pattern", "rank"),
        t.rule,
    ]
    paper_rank = {"D": 1, "A": 2, "E": 3, "B": 4, "C": 5}
    per_sigma = {s: _ranks({r: t.ours(r, s)["psnr"] for r in ranked}) for s in t.sigmas}
    for row in ranked:
        lines.append(_line(row, [f"{per_sigma[s][row]} ({paper_rank[row]})" for s in t.sigmas]))
    return lines


def _tables23_section(t: _Tables) -> list[str]:
    """Tables 2 and 3 (A, D against the pattern learned from it) with the gain of learning."""
    lines: list[str] = []
    for number, start in ((2, "A"), (3, "D")):
        opt = f"{start} optimised"
        if not (t.has(start) and t.has(opt)):
            continue
        lines += ["", f"## Table {number}: {start} against {start} optimised", "", t.head, t.rule]
        lines += [t.cells_row(start), t.cells_row(opt)]
        diff = []
        for s in t.sigmas:
            d = t.ours(opt, s)["psnr"] - t.ours(start, s)["psnr"]
            p0, p1 = t.paper(start, s), t.paper(opt, s)
            diff.append(f"{d:+.2f}" + (f" ({p1[0] - p0[0]:+.2f})" if p0 and p1 else ""))
        lines.append(_line("gain (paper)", diff))
    return lines


def _fig9_section(t: _Tables) -> list[str]:
    """Fig. 9: the PSNR/CIEDE2000 chart (drawn into the folder) and the CIEDE2000 table."""
    fig9 = [r for r in FIG9 if t.has(r)]
    if not fig9:
        return []
    chart = sigma_chart(
        [(r, t.summary[t.rows[r]]["all"]) for r in fig9],
        t.out / "fig9_sigma_curves.png",
        {
            r: [(float(s), p) for s, (p, _) in zip(PAPER_LEVELS, PAPER[r], strict=True)]
            for r in fig9
            if r in PAPER
        },
    )
    lines = [
        "",
        "## Fig. 9: bayer, D, D optimised and D optimised from random",
        "",
        _line("pattern", [f"CIEDE2000 σ={s}" for s in t.sigmas]),
        t.rule,
    ]
    for row in fig9:
        lines.append(_line(row, [f"{t.ours(row, s)['ciede2000']:.3f}" for s in t.sigmas]))
    return [*lines, "", f"![Fig. 9]({chart.name})"]


def _verdicts(summary: dict, rows: dict[str, str], sigmas: list[str], prefix: str) -> list[str]:
    """:func:`checks` as list items, each starting with ``prefix``."""
    return [
        f"- {prefix}{'holds' if holds else '**does not hold**'}: {statement} ({numbers})"
        for statement, holds, numbers in checks(summary, rows, sigmas)
    ]


def _conclusions_section(t: _Tables) -> list[str]:
    return [
        "",
        "## The paper's conclusions at our budget",
        "",
        *_verdicts(t.summary, t.rows, t.sigmas, ""),
    ]


def _sets_section(t: _Tables, baselines: dict[str, str] | None) -> list[str]:
    """Each test set's own mean PSNR (Kodak24 / McMaster) for every row, network and baseline,
    with the Kodak24-minus-McMaster drop: how much a method loses on saturated colour."""
    methods = {row: m for row, m in t.rows.items() if m in t.summary}
    methods |= {f"{row}, LMMSE": m for row, m in (baselines or {}).items() if m in t.summary}
    if "bayer+malvar2004" in t.summary:
        methods["bayer, Malvar 2004"] = "bayer+malvar2004"
    sets = DROP_SETS
    methods = {r: m for r, m in methods.items() if all(k in t.summary[m] for k in sets)}
    if not methods:
        return []
    lines = [
        "",
        "## Each test set apart",
        "",
        "PSNR dB on Kodak24 / McMaster, then Kodak24 minus McMaster: the paper's pooled tables "
        "hide how much a method loses on McMaster's saturated colours.",
        "",
        t.head.replace("pattern", "method"),
        t.rule,
    ]
    for row, method in methods.items():
        cells = []
        for level in t.sigmas:
            k, m = (t.summary[method][name].get(level) for name in sets)
            cells.append(
                f"{k['psnr']:.2f} / {m['psnr']:.2f} ({k['psnr'] - m['psnr']:.2f})"
                if k and m
                else "–"
            )
        lines.append(_line(row, cells))
    return lines


def _lmmse_section(t: _Tables, baselines: dict[str, str] | None) -> list[str]:
    """The training-free baselines: a table with the networks' gains over them, Malvar 2004,
    their ranks among A-E and the Table-1 conclusions checked on them."""
    base = {r: m for r, m in (baselines or {}).items() if m in t.summary}
    if not base:
        return []
    lines = [
        "",
        "## Without training: the LMMSE of every pattern",
        "",
        "The closed-form LMMSE (`--method lmmse`) of each pattern on the same images and "
        "noise: no network, so every pattern is compared even where its network is not "
        "shipped. Cells are PSNR dB / SSIM, then the shipped network's gain over it.",
        "",
        t.head,
        t.rule,
    ]
    lines += [_lmmse_row(t, row, base[row]) for row in PAPER_PATTERNS if row in base]
    if "bayer+malvar2004" in t.summary:
        malvar = t.summary["bayer+malvar2004"]["all"]
        lines.append(_line("bayer, Malvar 2004", [_cell(malvar.get(s), None) for s in t.sigmas]))
    lines += _lmmse_ranks(t, base)
    return lines + _verdicts(t.summary, base, t.sigmas, "LMMSE, ")


def _lmmse_row(t: _Tables, row: str, method: str) -> str:
    """A baseline's line: its PSNR / SSIM and the row's network's gain over it."""
    cells = []
    for s in t.sigmas:
        lm, net = t.summary[method]["all"].get(s), t.ours(row, s)
        cell = _cell(lm, None)
        if lm is not None and net is not None:
            cell += f" (net {net['psnr'] - lm['psnr']:+.2f})"
        cells.append(cell)
    return _line(row, cells)


def _lmmse_ranks(t: _Tables, base: dict[str, str]) -> list[str]:
    """The baselines of A-E ordered by PSNR at every level (none with fewer than two)."""
    ranked = [r for r in TABLE1_PATTERNS if r in base]
    if len(ranked) <= 1:
        return []
    order = {
        s: sorted(ranked, key=lambda r, s=s: -t.summary[base[r]]["all"][s]["psnr"])
        for s in t.sigmas
    }
    return [
        "",
        "Ranks by LMMSE PSNR among A–E: "
        + "; ".join(f"σ={s}: " + " ".join(order[s]) for s in t.sigmas),
        "",
    ]


def _learned_section(t: _Tables, learned: dict[str, patterns.Pattern] | None) -> list[str]:
    """The learned patterns, drawn under ``patterns/`` (Fig. 6)."""
    if not learned:
        return []
    lines = ["", "## Learned patterns (Fig. 6)", ""]
    (t.out / "patterns").mkdir(exist_ok=True)
    for row, pattern in learned.items():
        path = t.out / "patterns" / f"{row.replace(' ', '_').replace('.', '')}.png"
        draw_pattern(pattern, path)
        lines.append(f"![{row}](patterns/{path.name})")
    return lines


def _zoom_section(zooms: list[str] | None) -> list[str]:
    if not zooms:
        return []
    return ["", "## Zoomed crops (Figs. 4, 5, 7, 8)", "", *(f"![zoom]({z})" for z in zooms)]


def paper_tables(
    summary: dict,
    rows: dict[str, str],
    out: str | os.PathLike,
    *,
    budgets: dict[str, str] | None = None,
    learned: dict[str, patterns.Pattern] | None = None,
    zooms: list[str] | None = None,
    baselines: dict[str, str] | None = None,
) -> Path:
    """``reproduce.md``: the paper's Tables 1-3 and Fig. 9 with our numbers beside the paper's,
    the conclusions checked, the learned patterns (Fig. 6) and the zoomed crops.

    Args:
        summary: :func:`~splitcam.evaluation.tables.summarise` of the evaluation.
        rows: Paper row name (``A`` ... ``E``, ``bayer``, ``A optimised``, ``D optimised``,
            ``D optimised (random init.)``) → method name in ``summary``.
        out: Folder to write into.
        budgets: Paper row name → one line on the training budget of our model.
        learned: Paper row name → learned pattern, drawn under ``patterns/``.
        zooms: Zoom figures (paths relative to ``out``) to link.
        baselines: Paper row name (``A`` ... ``E``, ``bayer``) → a training-free method in
            ``summary`` (the LMMSE of that pattern), tabled with ranks and the Table-1
            conclusions checked on it: the patterns compared without any network, which also
            covers patterns whose network is not shipped yet.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t = _Tables.of(summary, rows, out)
    lines = [
        *_intro(t),
        *_budget_section(t, budgets),
        *_table1_section(t),
        *_tables23_section(t),
        *_fig9_section(t),
        *_conclusions_section(t),
        *_sets_section(t, baselines),
        *_lmmse_section(t, baselines),
        *_learned_section(t, learned),
        *_zoom_section(zooms),
    ]
    report = out / "reproduce.md"
    write_text(report, "\n".join(lines) + "\n")
    return report
