"""Validation PSNR against patches seen, one curve per batch size and rate (docs/results/batch).

    python studies/batch/plot.py RUN [RUN ...] [--out docs/results/batch/curves.png]
        [--logs docs/results/batch/logs]

Each RUN is a run folder of ``experiments/studies/batch/*.toml``; its validation rows are copied
to ``--logs`` (one ``NAME.jsonl`` per run) so the figure can be redrawn without the runs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from splitcam.io import read_json_lines  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "docs" / "results" / "batch"

#: The rule a batch-64 rate follows, by its ratio to batch 8's 1e-3 per 8 patches.
RULES = {0.000354: " (square root)", 0.001: " (linear)", 0.000125: " (unscaled)"}


def curve(run: Path) -> tuple[int, list[dict]]:
    config = json.loads((run / "config.json").read_text())
    batch = int(config["data"]["batch_size"])
    rows = [row for _, _, row in read_json_lines(run / "metrics.jsonl")[0]]
    return batch, [r for r in rows if "val_psnr_0" in r]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument(
        "--out", type=Path, default=ROOT / "docs" / "results" / "batch" / "curves.png"
    )
    parser.add_argument("--logs", type=Path, default=RESULTS / "logs")
    args = parser.parse_args()
    args.logs.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.8), sharex=True)
    keys = ("val_psnr_0", "val_psnr_15")
    kept: dict[str, list[float]] = {k: [] for k in keys}
    for run in args.runs:
        batch, rows = curve(run)
        lr = json.loads((run / "config.json").read_text())["optim"]["lr"]
        (args.logs / f"{run.name}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
        patches = [r["step"] * batch / 1000 for r in rows]
        rule = RULES.get(round(lr * 8 / batch, 6) if batch != 8 else None, "")
        label = f"batch {batch}, lr {lr:g}{rule}"
        diverged = min(r["val_psnr"] for r in rows) < rows[0]["val_psnr"] - 1
        for ax, key in zip(axes, keys, strict=True):
            values = [r[key] for r in rows]
            if diverged:
                label += f" (diverged: down to {min(values):.1f} dB, ends {values[-1]:.1f})"
                ax.plot([], [], marker="v", ls="--", label=label)  # below the axis
                label = ""
                continue
            kept[key] += values
            ax.plot(patches, values, marker="o", label=label)
    for ax, key, sigma in zip(axes, keys, (0, 15), strict=True):
        ax.set_ylim(min(kept[key]) - 0.3, max(kept[key]) + 0.3)
        ax.set_xlabel("patches seen (thousands)")
        ax.set_ylabel(f"validation PSNR at σ {sigma} (dB)")
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8)
    fig.suptitle("Pattern D from scratch, equal patches seen: batch 64 against batch 8")
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
