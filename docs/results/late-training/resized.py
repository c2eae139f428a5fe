"""The validation photos of a training run on the defaults (its held-out split, the first
``data.val_max_images`` of it: 8 BSDS photos) as PNG files at full size and at half size, for
`splitcam evaluate --datasets`.

    python docs/results/late-training/resized.py ../shared/data/train runs/val
    # writes runs/val/full/*.png and runs/val/half/*.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image

from splitcam.data.patches import ImageCache
from splitcam.training import TrainConfig
from splitcam.training.validation import held_out

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("train", help="the training folder")
parser.add_argument("out", help="folder for full/ and half/")
args = parser.parse_args()

config = TrainConfig().override({"data.train": args.train})
photos = held_out(config)[: config.data.val_max_images]
# The cache keeps each photo at each size, named stem and stem@0.5 (splitcam.data.downscale).
cache = ImageCache(photos, min_size=1, scales=(1.0, 0.5), progress=False)
for name, image in zip(cache.names, cache.arrays, strict=True):
    stem, half = name.split("@")[0], "@" in name
    folder = Path(args.out) / ("half" if half else "full")
    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(image.transpose(1, 2, 0))).save(folder / f"{stem}.png")
print(f"{cache.files} photos at full and half size in {args.out}")
