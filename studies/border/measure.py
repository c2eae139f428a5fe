"""What each network loses at the image border: PSNR with a 4-pixel border left out minus the
PSNR of the whole image.

    python studies/border/measure.py [MODEL_OR_RUN ...] [--images 12] [--threads 1]
        [--out FILE.md]

Every model is a shipped model's name (default: all of them), a model file or a run folder. The
photos are the last ``--images`` of the training photos (``$SPLITCAM_DATA/train``, sorted by
name; no run trains or
selects on the last 24, see ``studies/universal/heldout.py``), scored by the evaluation
protocol at sigma 0 and 15 twice: whole (481x321 or 321x481, odd sides: the last row and column
are part-way through every period above 1) and cropped to even sides (480x320). A network that
is right at the border loses nothing there (the 4-pixel crop then changes the PSNR by noise
only, a few hundredths of a dB either way).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from splitcam.data.imageio import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.evaluation.metrics import mean_over_images
from splitcam.evaluation.protocol import score, score_images
from splitcam.recon.loading import model_names, model_serves_any_pattern
from splitcam.recon.registry import build_method

SIGMAS = [0.0, 15.0]
DATA = training_folder()
BORDER = 4


def border_loss(method, images, sigmas=SIGMAS) -> dict[float, tuple[float, float]]:
    """``{sigma: (whole-image PSNR, PSNR with BORDER pixels left out)}``, means over images;
    each reconstruction is scored both ways."""
    whole: dict[float, list[float]] = {s: [] for s in sigmas}
    inner: dict[float, list[float]] = {s: [] for s in sigmas}
    originals = dict(images)
    for name, sigma, pred, values in score_images(method, images, sigmas):
        whole[sigma].append(values["psnr"])
        inner[sigma].append(score(pred, originals[name], crop=BORDER)["psnr"])
    return {s: (mean_over_images(whole[s]).mean, mean_over_images(inner[s]).mean) for s in sigmas}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*")
    parser.add_argument("--images", type=int, default=12)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    paths = list_images(DATA)[-args.images :]
    odd = [(p.name, torch.from_numpy(read_image(p)).permute(2, 0, 1).contiguous()) for p in paths]
    even = [(n, x[:, : x.shape[1] // 2 * 2, : x.shape[2] // 2 * 2]) for n, x in odd]
    lines = [
        f"{len(odd)} held-out photos, sigma 0 / 15: whole-image PSNR (dB) and the loss at the "
        f"border (PSNR with a {BORDER}-pixel border left out minus the whole-image PSNR)",
        "",
        "| model | sides | PSNR σ0 | PSNR σ15 | border loss σ0 | border loss σ15 |",
        "|---|---|---|---|---|---|",
    ]
    print("\n".join(lines), flush=True)
    for spec in args.models or model_names():
        if spec in model_names() and model_serves_any_pattern(spec):
            continue  # needs a pattern; measured by studies/universal/heldout.py
        method = build_method(spec)
        for label, images in (("odd", odd), ("even", even)):
            res = border_loss(method, images)
            row = (
                f"| {Path(str(spec)).name} | {label} | "
                + " | ".join(f"{res[s][0]:.2f}" for s in SIGMAS)
                + " | "
                + " | ".join(f"{res[s][1] - res[s][0]:+.2f}" for s in SIGMAS)
                + " |"
            )
            lines.append(row)
            print(row, flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
