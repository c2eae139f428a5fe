"""Compare the library's patterns: design measures and closed-form LMMSE PSNR on sample photos.

Every pattern of ``splitcam.patterns.names()`` (the paper's splitters A-E, the Bayer, RGBW and
Quad Bayer filters, published routers) is measured (light collected, light moved) and scored
with its training-free LMMSE on the photographs that ship inside scikit-image, with the paper's
protocol (8-bit rounding, PSNR on the whole image). Writes ``patterns_psnr.png``: a bar chart of
PSNR per pattern at each noise level.

    python examples/01_compare_patterns.py [--out DIR] [--tiny]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from splitcam import patterns
from splitcam.data.testsets import centre_crop, default_images
from splitcam.evaluation.protocol import mean_psnr
from splitcam.recon import build_method


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples-out/01", help="output folder")
    parser.add_argument("--tiny", action="store_true", help="2 small images: seconds, for CI")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    size, count = (64, 2) if args.tiny else (256, 6)
    images = [(n, centre_crop(im, size)) for n, im in default_images()[:count]]
    sigmas = [0.0, 10.0] if args.tiny else [0.0, 10.0, 20.0]

    rows = []
    print(f"{'pattern':<12} {'white':>6} {'split':>6}  " + "  ".join(f"σ={s:<4g}" for s in sigmas))
    for name in patterns.names():
        pattern = patterns.get(name)
        m = patterns.measure(pattern)
        psnr = mean_psnr(build_method("lmmse", pattern=pattern), images, sigmas)
        rows.append((name, psnr))
        cells = "  ".join(f"{psnr[s]:6.2f}" for s in sigmas)
        print(f"{name:<12} {m.white:6.3f} {m.split_fraction:6.2f}  {cells}")

    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.2))
    ax = fig.subplots()
    width = 0.8 / len(sigmas)
    for k, s in enumerate(sigmas):
        xs = [i + (k - (len(sigmas) - 1) / 2) * width for i in range(len(rows))]
        ax.bar(xs, [psnr[s] for _, psnr in rows], width, label=f"σ = {s:g}")
    ax.set_xticks(range(len(rows)), [name for name, _ in rows], rotation=30, ha="right")
    ax.set_ylabel("PSNR (dB), closed-form LMMSE")
    low = min(min(p.values()) for _, p in rows)
    ax.set_ylim(max(0.0, low - 3), None)
    ax.set_title(f"Library patterns on {len(images)} sample photos ({size}x{size} crops)")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path = out / "patterns_psnr.png"
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
