"""Held-out photos for choosing colour levers: the training photos no run trains on, ranked by
colourfulness, the most colourful ones in a folder of their own.

    python studies/colour/heldout.py [--data DIR] [--out runs/colour/heldout] [--top 12]

Every run holds out the last 32 training photos by name (``data.val_split``'s default for 432
photos) and validates on the first 8 of them; none of the 32 is trained on. They are ranked by
Hasler and Suesstrunk's colourfulness (:func:`splitcam.data.colour.colourfulness`), and the
``--top`` most colourful are copied, whole, to ``OUT/colourful``; all 32 go to ``OUT/heldout``,
and to ``OUT/saturated`` with their chroma scaled by ``--saturate`` (1.8) in the BT.601
opponent space and clipped to the gamut (:func:`splitcam.data.colour.augment_chroma`, no hue
turned): photos as colourful as McMaster's, built from held-out photos alone. (That set is
of the same family of transforms as the chroma augmentation, so it measures holding on
saturated colour, and favours that lever by construction; the colourful set does not.)
All 32 also go to ``OUT/half`` at half their size (:func:`splitcam.data.patches.downscale`, as
``data.scales`` makes them): the photos are JPEGs with their chroma stored at half resolution,
so only at half size is their colour detail as fine as their luma's
(``studies/colour/chroma_detail.py``).
The table ``OUT/colourfulness.md`` lists every held-out photo with its score, and the mean
score of each test set beside them as a description of what the test sets hold (they choose
nothing). Then, for example:

    splitcam evaluate --model bayer --checkpoint runs/colour/bayer-chroma \\
        --datasets runs/colour/heldout/colourful,runs/colour/heldout/heldout,\
runs/colour/heldout/saturated --sigmas 0 15
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from splitcam.data.colour import augment_chroma, colourfulness
from splitcam.data.imageio import decode_image, read_image
from splitcam.data.patches import downscale, list_images
from splitcam.data.registry import dataset_folder, training_folder

HELD_OUT = 32


def score(path: Path) -> float:
    return colourfulness(torch.from_numpy(read_image(path)).permute(2, 0, 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(training_folder()))
    parser.add_argument("--out", default="runs/colour/heldout")
    parser.add_argument("--top", type=int, default=12)
    parser.add_argument("--saturate", type=float, default=1.8)
    args = parser.parse_args()
    held = list_images(args.data)[-HELD_OUT:]
    ranked = sorted(((score(p), p) for p in held), reverse=True)
    out = Path(args.out)
    for sub, chosen in (("colourful", ranked[: args.top]), ("heldout", ranked)):
        (out / sub).mkdir(parents=True, exist_ok=True)
        for _, path in chosen:
            shutil.copyfile(path, out / sub / path.name)
    (out / "half").mkdir(parents=True, exist_ok=True)
    for _, path in ranked:
        pixels = decode_image(path).transpose(2, 0, 1)
        small = downscale(np.ascontiguousarray(pixels), 0.5).transpose(1, 2, 0)
        Image.fromarray(np.ascontiguousarray(small)).save(out / "half" / f"{path.stem}.png")
    (out / "saturated").mkdir(parents=True, exist_ok=True)
    saturated = []
    for _, path in ranked:
        rgb = torch.from_numpy(read_image(path)).permute(2, 0, 1)[None]
        one = torch.ones(1)
        pushed = augment_chroma(rgb, 0 * one, args.saturate * one, torch.zeros(1, dtype=torch.long))
        saturated.append(colourfulness(pushed[0]))
        pixels = (pushed[0].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
        Image.fromarray(pixels).save(out / "saturated" / f"{path.stem}.png")
    lines = [
        f"# Colourfulness of the {len(held)} held-out training photos",
        "",
        "Hasler and Suesstrunk (2003): about 33 moderately, 45 averagely, 59 quite, 82 highly "
        "colourful.",
        "",
        "| photo | colourfulness | in colourful |",
        "|---|---|---|",
    ]
    lines += [
        f"| {p.stem} | {m:.1f} | {'yes' if i < args.top else ''} |"
        for i, (m, p) in enumerate(ranked)
    ]
    chosen_mean = sum(m for m, _ in ranked[: args.top]) / args.top
    all_mean = sum(m for m, _ in ranked) / len(ranked)
    lines += ["", "| set | photos | mean colourfulness |", "|---|---|---|"]
    lines.append(f"| held-out, all | {len(ranked)} | {all_mean:.1f} |")
    lines.append(f"| held-out, colourful | {args.top} | {chosen_mean:.1f} |")
    sat_mean = sum(saturated) / len(saturated)
    lines.append(f"| held-out, chroma x{args.saturate:g} | {len(saturated)} | {sat_mean:.1f} |")
    for name in ("kodak24", "mcmaster"):
        try:
            paths = list_images(dataset_folder(name))
        except (FileNotFoundError, ValueError):
            continue
        mean = sum(score(p) for p in paths) / len(paths)
        lines.append(f"| {name} (described, not used) | {len(paths)} | {mean:.1f} |")
    (out / "colourfulness.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
