"""Reports: evaluation results side by side with the paper's numbers, pattern figures and
PSNR/CIEDE2000-against-sigma charts (the paper's Table 1-3, Fig. 6 and Fig. 9)."""

from __future__ import annotations

import json
import os
from pathlib import Path

from .. import patterns
from ..viz.charts import sigma_chart
from ..viz.patterns import draw_pattern

#: SPEC section 8: mean over Kodak24 and McMaster (42 images), PSNR dB / SSIM, from 10^6 GPU
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
PAPER_SIGMAS = ("0", "5", "10", "15", "20")


def paper_row(pattern: patterns.Pattern) -> str | None:
    """The paper's row for a pattern: its name, or "X optimised" for one learned from X."""
    if pattern.provenance == "learned":
        start = str(pattern.metadata.get("start", ""))
        key = f"{start} optimised"
    else:
        key = pattern.name
    return key if key in PAPER else None


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
            pattern_file = folder / "patterns" / f"{method}.json"
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
    lines = [
        "# splitcam report",
        "",
        "Ours: mean over all images evaluated (`all`); the paper: mean over Kodak24 + McMaster "
        "(42 images) after 10^6 GPU training steps on DIV2K. Cells: ours PSNR dB / SSIM, then "
        "(paper PSNR, difference ours − paper). B, C and E are modelled patterns (SPEC "
        "section 2), so their gaps are not only a matter of training budget.",
        "",
    ]
    sigmas = list(dict.fromkeys(s for _, _, e, _ in entries for s in e["all"]))
    lines.append(
        "| result | method | pattern | images | " + " | ".join(f"σ={s}" for s in sigmas) + " |"
    )
    lines.append("|---|---|---|---|" + "---|" * len(sigmas))
    for folder, method, entry, pattern in entries:
        ref = paper_row(pattern)
        cells = []
        for s in sigmas:
            st = entry["all"].get(s)
            if st is None:
                cells.append("–")
                continue
            cell = f"{st['psnr']:.2f} / {st['ssim']:.4f}"
            if ref and s in PAPER_SIGMAS:
                p_psnr = PAPER[ref][PAPER_SIGMAS.index(s)][0]
                cell += f" ({p_psnr:.2f}, {st['psnr'] - p_psnr:+.2f})"
            cells.append(cell)
        n = max(st["n_images"] for st in entry["all"].values())
        lines.append(f"| {folder} | {method} | {pattern.name} | {n} | " + " | ".join(cells) + " |")
    lines += ["", "## CIEDE2000 (lower is better)", ""]
    lines.append("| result | method | " + " | ".join(f"σ={s}" for s in sigmas) + " |")
    lines.append("|---|---|" + "---|" * len(sigmas))
    for folder, method, entry, _ in entries:
        cells = [
            f"{entry['all'][s]['ciede2000']:.3f}" if s in entry["all"] else "–" for s in sigmas
        ]
        lines.append(f"| {folder} | {method} | " + " | ".join(cells) + " |")
    lines += ["", "## Patterns", ""]
    drawn: set[str] = set()
    for *_, pattern in entries:
        key = f"{pattern.name}-{pattern.provenance}"
        if key in drawn:
            continue
        drawn.add(key)
        path = out / "patterns" / f"{pattern.name}.png"
        draw_pattern(pattern, path)
        lines.append(f"![pattern {pattern.name}](patterns/{path.name})")
    several = len({f for f, *_ in entries}) > 1
    curves = [
        (f"{folder}: {method}" if several else method, entry["all"])
        for folder, method, entry, _ in entries
    ]
    refs = dict.fromkeys(r for *_, pattern in entries if (r := paper_row(pattern)))
    references = {
        ref: [(float(s), p) for s, (p, _) in zip(PAPER_SIGMAS, PAPER[ref], strict=True)]
        for ref in refs
    }
    chart = sigma_chart(curves, out / "sigma_curves.png", references)
    lines += ["", "## PSNR and CIEDE2000 against noise", "", f"![curves]({chart.name})", ""]
    report = out / "report.md"
    report.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return report
