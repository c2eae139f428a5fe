"""Training curves from a run's ``metrics.jsonl``."""

from __future__ import annotations

import math
import os
import warnings
from numbers import Real
from pathlib import Path

from ..io import read_json_lines
from ..physics.noise import level_heading, level_key
from ._save import save_figure


def _valid(row: object) -> bool:
    """A logged step: a JSON object with an integer step and numbers for every other value."""
    return (
        isinstance(row, dict)
        and isinstance(row.get("step"), int)
        and all(
            isinstance(v, Real) and not isinstance(v, bool) and not math.isnan(v)
            for k, v in row.items()
            if k != "step"
        )
    )


def read_metrics(run: str | os.PathLike) -> list[dict]:
    """The logged steps of a run's ``metrics.jsonl``.

    Damaged lines (cut short by a killed process, or edited by hand) are skipped with one
    warning that names the file and the line numbers.

    Raises:
        FileNotFoundError: No metrics file.
        ValueError: No valid logged step.
    """
    path = Path(run) / "metrics.jsonl" if Path(run).is_dir() else Path(run)
    if not path.is_file():
        raise FileNotFoundError(f"no metrics.jsonl in {str(run)!r}")
    lines, damaged = read_json_lines(path)
    rows = [row for _, _, row in lines if _valid(row)]
    damaged = sorted(damaged + [number for number, _, row in lines if not _valid(row)])
    if damaged:
        shown = ", ".join(map(str, damaged[:10])) + (", ..." if len(damaged) > 10 else "")
        warnings.warn(
            f"{str(path)!r}: skipped {len(damaged)} damaged line(s): {shown}",
            UserWarning,
            stacklevel=2,
        )
    if not rows:
        raise ValueError(f"{str(path)!r} holds no logged steps yet")
    return rows


def plot_run(run: str | os.PathLike, out: str | os.PathLike | None = None) -> Path:
    """Loss (log scale) and training/validation PSNR against step, saved as a PNG."""
    from matplotlib.figure import Figure

    rows = read_metrics(run)
    folder = Path(run) if Path(run).is_dir() else Path(run).parent
    out = Path(out) if out else folder / "curves.png"
    train = [r for r in rows if "loss" in r]
    val = [r for r in rows if "val_psnr" in r]
    fig = Figure(figsize=(11, 4))
    ax1, ax2 = fig.subplots(1, 2)
    ax1.plot([r["step"] for r in train], [r["loss"] for r in train], lw=1)
    ax1.set_yscale("log")
    ax1.set_xlabel("step")
    ax1.set_ylabel("training loss (MSE)")
    ax1.grid(alpha=0.3)
    ax2.plot(
        [r["step"] for r in train],
        [r["train_psnr"] for r in train],
        lw=0.8,
        alpha=0.6,
        label="training batches (noisy, all sigmas)",
    )

    # keys val_psnr_<level label>: val_psnr_15 (sigma 15), val_psnr_N100 (exposure 100)
    sigmas = sorted({k for r in val for k in r if k.startswith("val_psnr_")}, key=level_key)
    for key in sigmas:
        ax2.plot(
            [r["step"] for r in val],
            [r.get(key, float("nan")) for r in val],
            marker="o",
            ms=3,
            label=f"validation, {level_heading(key)}",
        )
    ax2.set_xlabel("step")
    ax2.set_ylabel("PSNR (dB)")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8)
    last = val[-1] if val else train[-1]
    name = Path(run).name if Path(run).is_dir() else Path(run).parent.name
    fig.suptitle(
        f"{name}: step {last['step']}"
        + (f", validation PSNR {last['val_psnr']:.2f} dB (mean over sigmas)" if val else "")
    )
    fig.tight_layout()
    return save_figure(fig, out)


def active_minutes(rows: list[dict]) -> list[float]:
    """Minutes of training at each logged row, with pauses left out: a gap between consecutive
    rows longer than 10x their median gap (the run was stopped and resumed later, in another
    session or after another run) counts as one median gap. Wall-clock time since the first
    row would draw a resumed run as if it had trained through its pause."""
    times = [float(r["time"]) for r in rows]
    gaps = [b - a for a, b in zip(times, times[1:], strict=False)]
    if not gaps:
        return [0.0] * len(rows)
    typical = sorted(gaps)[len(gaps) // 2]
    minutes, total = [0.0], 0.0
    for gap in gaps:
        total += typical if gap > 10 * max(typical, 1e-9) else max(gap, 0.0)
        minutes.append(total / 60)
    return minutes


def compare_runs(runs: list[str | os.PathLike], out: str | os.PathLike) -> Path:
    """Validation PSNR of several runs against wall-clock minutes and against steps: the
    picture of an equal-time comparison."""
    import matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4))
    ax1, ax2 = fig.subplots(1, 2)
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, run in enumerate(runs):
        every = [r for r in read_metrics(run) if "time" in r]
        timed = [(r, m) for r, m in zip(every, active_minutes(every), strict=True)]
        rows = [r for r, _ in timed if "val_psnr" in r]
        if not rows:
            raise ValueError(f"run {str(run)!r} has no validation results")
        val_minutes = [m for r, m in timed if "val_psnr" in r]
        keys = sorted(
            (k for k in rows[0] if k.startswith("val_psnr_")),
            key=level_key,
        )
        for j, key in enumerate(keys):
            style = ["o-", "s--", "^:"][j % 3]
            label = f"{Path(run).name}, {level_heading(key)}"
            minutes = [m - val_minutes[0] for m in val_minutes]
            ax1.plot(minutes, [r[key] for r in rows], style, color=colours[i], ms=3, label=label)
            ax2.plot(
                [r["step"] for r in rows],
                [r[key] for r in rows],
                style,
                color=colours[i],
                ms=3,
                label=label,
            )
    ax1.set_xlabel("training minutes since the first validation (pauses left out)")
    ax2.set_xlabel("step")
    ax2.set_xscale("symlog", linthresh=100)
    for ax in (ax1, ax2):
        ax.set_ylabel("validation PSNR (dB)")
        ax.grid(alpha=0.3)
    # Below both panels, one column per run: long run names never cover the curves.
    handles, labels = ax1.get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=1, frameon=False)
    fig.set_size_inches(11, 4 + 0.17 * len(labels))
    fig.tight_layout(rect=(0, 0.17 * len(labels) / (4 + 0.17 * len(labels)) + 0.02, 1, 1))
    return save_figure(fig, out, dpi=120)
