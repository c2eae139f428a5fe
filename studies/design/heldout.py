"""Score designed patterns against their starts with the closed-form LMMSE on held-out images.

    python studies/design/heldout.py docs/results/design/*.toml [--train DIR]

For every pattern file written by `splitcam design`, its start (``metadata.start``) and the
designed pattern are each reconstructed by ``closed_form_lmmse(pattern)`` from the protocol's
simulated raw images (same noise for both, seeded by image name) of the LAST 32 images (sorted by
name) of the training folder: the images the shipped image statistics left out. Prints a Markdown
table: closed-form PSNR (no images), held-out PSNR of the whole images (``mean_psnr``, the
protocol) and of their interior (``--crop`` pixels off each side, where the closed form's
"away from the borders" holds) at sigma 0 and 15, start -> designed. Never Kodak24/McMaster.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from splitcam import patterns
from splitcam.data.images import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.design import closed_form_psnr
from splitcam.evaluation.metrics import mean_over_images, psnr
from splitcam.evaluation.protocol import mean_psnr, score_images
from splitcam.recon.closed_form import closed_form_lmmse

SIGMAS = [0.0, 15.0]


def held_out(folder: Path, count: int) -> list[tuple[str, torch.Tensor]]:
    files = list_images(folder)[-count:]
    return [(f.stem, torch.from_numpy(read_image(f)).permute(2, 0, 1).contiguous()) for f in files]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument(
        "--train",
        type=Path,
        default=training_folder(),
        help="training photos (default: $SPLITCAM_DATA/train, docs/commands.md)",
    )
    parser.add_argument("--count", type=int, default=32)
    parser.add_argument("--crop", type=int, default=8, help="border of the interior PSNR")
    args = parser.parse_args()
    images = held_out(args.train, args.count)
    print(f"{len(images)} held-out images: {images[0][0]} .. {images[-1][0]}", flush=True)
    by_name = dict(images)
    cache: dict[str, tuple[dict[float, float], dict[float, float]]] = {}

    def heldout_psnr(pattern: patterns.Pattern, key: str):
        """(whole images, interior): mean PSNR per sigma of the closed-form LMMSE."""
        if key not in cache:
            t0 = time.perf_counter()
            method = closed_form_lmmse(pattern)
            whole = mean_psnr(method, images, SIGMAS)
            inner: dict[float, list[float]] = {s: [] for s in SIGMAS}
            for name, sigma, pred, _ in score_images(method, images, SIGMAS):
                inner[sigma].append(psnr(pred, by_name[name], crop=args.crop))
            interior = {s: mean_over_images(v).mean for s, v in inner.items()}
            cache[key] = (whole, interior)
            print(f"  scored {key} in {time.perf_counter() - t0:.0f} s", flush=True)
        return cache[key]

    rows = []
    for path in args.files:
        designed = patterns.get(path)
        meta = designed.metadata
        start = patterns.get(meta["start"])
        cf = [closed_form_psnr(p, SIGMAS).tolist() for p in (start, designed)]
        (w0, i0), (w1, i1) = (
            heldout_psnr(start, f"start {start.name}"),
            heldout_psnr(designed, str(path)),
        )
        seed = f", seed {meta['seed']}" if meta["init"] == "random" else ""
        cells = [f"{start.name}, {meta['init']}{seed}, {meta['objective']}"]
        for i in range(len(SIGMAS)):
            cells.append(f"{cf[0][i]:.2f} → {cf[1][i]:.2f} ({cf[1][i] - cf[0][i]:+.2f})")
        for a, b in ((w0, w1), (i0, i1)):
            for s in SIGMAS:
                cells.append(f"{a[s]:.2f} → {b[s]:.2f} ({b[s] - a[s]:+.2f})")
        rows.append("| " + " | ".join([f"`{path.name}`", *cells]) + " |")
    print(f"\ninterior: {args.crop} pixels off each side of every image\n")
    print(
        "| file | start, init, objective | closed form σ=0 | closed form σ=15 "
        "| held-out σ=0 | held-out σ=15 "
        "| interior σ=0 | interior σ=15 |"
    )
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
