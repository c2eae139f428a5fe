"""The 8 validation photos of every training run (the first 8 of the 32 held out by name) as
PNG files at full size and at half size, for `splitcam evaluate --datasets`.

    python docs/results/late-training/resized.py ../shared/data/train runs/val
    # writes runs/val/full/*.png and runs/val/half/*.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image

from splitcam.data.images import decode_image
from splitcam.data.patches import downscale, list_images

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("train", help="the training folder")
parser.add_argument("out", help="folder for full/ and half/")
args = parser.parse_args()


photos = list_images(args.train)[-32:-24]
for name, factor in (("full", 1.0), ("half", 0.5)):
    folder = Path(args.out) / name
    folder.mkdir(parents=True, exist_ok=True)
    for path in photos:
        image = np.ascontiguousarray(decode_image(path).transpose(2, 0, 1))
        small = downscale(image, factor).transpose(1, 2, 0)
        Image.fromarray(np.ascontiguousarray(small)).save(folder / f"{path.stem}.png")
print(f"{len(photos)} photos at full and half size in {args.out}")
