"""Where a network's error lies against a peer's: by colour channel and by the saturation of the
true pixel, per test set, from an evaluation that saved its images.

    splitcam evaluate --model bayer --method demosaicnet --method lmmse --patterns bayer \\
        --datasets kodak24,mcmaster --sigmas 0 --precision fp32 --save-images --out runs/gap
    python studies/colour/gap_by_chroma.py runs/gap [--sigma 0] \\
        [--out docs/results/colour/gap-by-chroma.md]

For each test set and method: the PSNR of the mean squared error of each channel (8-bit values,
as the evaluation scores them), and the PSNR over the pixels whose true chroma (the length of
(Cb, Cr) in the BT.601 opponent space of :func:`splitcam.data.colour.rgb_to_opponent`, in 8-bit
units) falls in each bin, with each bin's share of the pixels. The test sets are described here;
they choose nothing.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from splitcam.data.colour import rgb_to_opponent
from splitcam.data.testsets import load_datasets
from splitcam.evaluation.metrics import quantize

#: Bin edges of the true pixel's chroma, 8-bit units
EDGES = (0, 10, 20, 40, 60, 80, 256)


def chroma_bins(rgb: torch.Tensor) -> np.ndarray:
    """The chroma bin of every pixel of a ``(3, H, W)`` image in [0, 1]: ``(H, W)`` indices."""
    ycc = rgb_to_opponent(rgb.double())
    chroma = 255 * torch.linalg.vector_norm(ycc[1:], dim=0)
    return np.digitize(chroma.numpy(), EDGES[1:-1])


def psnr(sq_err: float, count: int) -> float:
    return 10 * math.log10(255**2 * count / sq_err) if sq_err > 0 else math.inf


def describe(folder: Path, sigma: float, crop: int, datasets: str | None = None) -> list[str]:
    """The tables of every test set of the evaluation in ``folder`` (``datasets``: the
    evaluation's ``--datasets``, names or folders; default: the names its images are under)."""
    images = folder / "images"
    methods = sorted(p.name for p in images.iterdir() if p.is_dir()) if images.is_dir() else []
    if not methods:
        raise SystemExit(f"{images}: no saved images (evaluate with --save-images)")
    if datasets is None:
        datasets = ",".join(
            sorted({p.name for m in methods for p in (images / m).iterdir() if p.is_dir()})
        )
    lines = []
    for name, pictures in load_datasets(datasets):
        bins = len(EDGES) - 1
        channel = {m: np.zeros(3) for m in methods}
        binned = {m: np.zeros(bins) for m in methods}
        pixels, counts = 0, np.zeros(bins)
        for image, rgb in pictures:
            cut = (slice(None), slice(crop, -crop or None), slice(crop, -crop or None))
            truth = quantize(rgb)[cut].astype(np.float64)
            index = chroma_bins(rgb)[cut[1:]]
            counts += np.bincount(index.ravel(), minlength=bins)
            pixels += index.size
            for m in methods:
                file = images / m / name / f"{image}_sigma{sigma:g}.png"
                rec = np.asarray(Image.open(file).convert("RGB"), dtype=np.float64)
                err = (rec.transpose(2, 0, 1)[cut] - truth) ** 2
                channel[m] += err.reshape(3, -1).sum(1)
                binned[m] += np.bincount(index.ravel(), err.sum(0).ravel(), minlength=bins)
        labels = [f"{lo}-{hi}" for lo, hi in zip(EDGES[:-1], EDGES[1:], strict=False)]
        lines += [f"## {name} (σ {sigma:g}, {len(pictures)} images)", ""]
        lines += ["| method | R | G | B | " + " | ".join(labels) + " |"]
        lines += ["|---" * (4 + bins) + "|"]
        share = " | ".join(f"{100 * c / pixels:.0f} %" for c in counts)
        lines += [f"| pixels in the bin | | | | {share} |"]
        for m in methods:
            rgb_cells = " | ".join(f"{psnr(e, pixels):.2f}" for e in channel[m])
            bin_cells = " | ".join(
                f"{psnr(e, 3 * c):.2f}" if c else "" for e, c in zip(binned[m], counts, strict=True)
            )
            lines += [f"| {m} | {rgb_cells} | {bin_cells} |"]
        lines += [""]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="an evaluation's --out, run with --save-images")
    parser.add_argument("--sigma", type=float, default=0.0)
    parser.add_argument("--crop", type=int, default=0, help="border pixels left out (as evaluate)")
    parser.add_argument("--datasets", default=None, help="as given to evaluate (default: by name)")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    lines = [
        "# Where the error lies: by channel and by the true pixel's chroma",
        "",
        "PSNR (dB) of the 8-bit error: of each channel over every pixel, then of the three "
        "channels over the pixels whose true chroma (|(Cb, Cr)|, BT.601, 8-bit units) is in "
        "the bin. From `studies/colour/gap_by_chroma.py` (its docstring has the commands).",
        "",
        *describe(args.folder, args.sigma, args.crop, args.datasets),
    ]
    text = "\n".join(lines)
    if args.out:
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
