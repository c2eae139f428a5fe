"""Bring your own pattern: write a pattern file, then score it with the LMMSE and the shipped
network for any pattern.

Two patterns are written as TOML files: pattern D with its kernels edited (each splitter keeps
20 % more of every colour on its own pixel), and a random valid router from
``splitcam.patterns.random``. Each file is scored like a library pattern, by name of the file:
the closed-form LMMSE (solved from the shipped image statistics for kernels it has not seen)
and ``universal``, the shipped network that reconstructs any pattern it is told. Writes
``own_patterns.png`` (the edited pattern, where each colour's light goes) and
``own_patterns_psnr.png`` (PSNR of both methods on every pattern).

    python examples/02_your_own_pattern.py [--out DIR] [--tiny]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from splitcam import patterns
from splitcam.data.testsets import centre_crop, default_images
from splitcam.evaluation.protocol import mean_psnr
from splitcam.patterns.random import random_pattern
from splitcam.recon import build_method
from splitcam.viz.patterns import draw_pattern


def edited_d() -> patterns.Pattern:
    """Pattern D with 20 % more of every colour kept on the splitter's own pixel (light taken
    evenly from the other taps, so every kernel still sums to what it did)."""
    d = patterns.get("D")
    k = np.array(d.kernels, dtype=np.float64)  # (splitters, 3 colours, kh, kw)
    kh, kw = k.shape[-2:]
    centre = k[..., kh // 2, kw // 2].copy()
    total = k.sum((-1, -2))
    keep = np.minimum(centre + 0.2 * (total - centre), total)
    others = total - centre
    scale = np.where(others > 0, (total - keep) / np.where(others > 0, others, 1), 0.0)
    k = k * scale[..., None, None]
    k[..., kh // 2, kw // 2] = keep
    return dataclasses.replace(
        d, name="D-kept", kernels=k, provenance="edited", description="D, 20 % more kept"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples-out/02", help="output folder")
    parser.add_argument("--tiny", action="store_true", help="2 small images: seconds, for CI")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    files = [
        patterns.save(edited_d(), out / "d-kept.toml"),
        patterns.save(
            random_pattern(
                np.random.default_rng(4),
                families=("router",),
                max_period=2,
                max_kernel=3,
                name="my-random",
            ),
            out / "my-random.toml",
        ),
    ]
    for f in files:
        p = patterns.load(f)
        m = patterns.measure(p)
        print(f"{f.name}: period {p.period}, kernels {p.kernel_size}, white {m.white:.3f}")
    draw_pattern(patterns.load(files[0]), out / "own_patterns.png")

    size, count = (48, 2) if args.tiny else (256, 6)
    images = [(n, centre_crop(im, size)) for n, im in default_images()[:count]]
    sigma = 10.0
    specs = ["D", *(str(f) for f in files)]
    scores: dict[str, dict[str, float]] = {}
    for spec in specs:
        label = Path(spec).name
        scores[label] = {}
        for method in ("lmmse", "universal"):
            psnr = mean_psnr(build_method(method, pattern=spec), images, [sigma])[sigma]
            scores[label][method] = psnr
        print(
            f"{label:<16} LMMSE {scores[label]['lmmse']:6.2f} dB   "
            f"universal {scores[label]['universal']:6.2f} dB   (σ = {sigma:g})"
        )

    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 3.8))
    ax = fig.subplots()
    labels = list(scores)
    for k, method in enumerate(("lmmse", "universal")):
        xs = [i + (k - 0.5) * 0.38 for i in range(len(labels))]
        ax.bar(xs, [scores[lab][method] for lab in labels], 0.38, label=method)
    ax.set_xticks(range(len(labels)), labels)
    ax.set_ylabel(f"PSNR (dB) at σ = {sigma:g}")
    ax.set_ylim(max(0.0, min(min(v.values()) for v in scores.values()) - 3), None)
    ax.set_title(f"Your patterns, {len(images)} sample photos ({size}x{size})")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path = out / "own_patterns_psnr.png"
    fig.savefig(path, dpi=110)
    print(f"wrote {path} and {out / 'own_patterns.png'}")


if __name__ == "__main__":
    main()
