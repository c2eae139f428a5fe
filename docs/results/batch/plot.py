"""Validation PSNR against patches seen, one curve per batch size and rate (docs/results/batch).

    python docs/results/batch/plot.py RUN [RUN ...] [--out docs/results/batch/curves.png]
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


def curve(run: Path) -> tuple[int, list[dict]]:
    config = json.loads((run / "config.json").read_text())
    batch = int(config["data"]["batch_size"])
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    return batch, [r for r in rows if "val_psnr_0" in r]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, default=Path(__file__).with_name("curves.png"))
    parser.add_argument("--logs", type=Path, default=Path(__file__).with_name("logs"))
    args = parser.parse_args()
    args.logs.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharex=True)
    for run in args.runs:
        batch, rows = curve(run)
        lr = json.loads((run / "config.json").read_text())["optim"]["lr"]
        (args.logs / f"{run.name}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
        patches = [r["step"] * batch / 1000 for r in rows]
        for ax, key in zip(axes, ("val_psnr_0", "val_psnr_15"), strict=True):
            ax.plot(patches, [r[key] for r in rows], marker="o", label=f"batch {batch}, lr {lr:g}")
    for ax, sigma in zip(axes, (0, 15), strict=True):
        ax.set_xlabel("patches seen (thousands)")
        ax.set_ylabel(f"validation PSNR at σ {sigma} (dB)")
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.suptitle("Pattern D from scratch, equal patches seen: batch 64 against batch 8")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
