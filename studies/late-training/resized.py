"""The validation photos of a training run on the defaults (its held-out split, the first
``data.val_max_images`` of it: 8 BSDS photos) as PNG files at full size and at half size (and
quarter size with ``--quarter``), for `splitcam evaluate --datasets`.

    python studies/late-training/resized.py $SPLITCAM_DATA/train runs/val
    # writes runs/val/full/*.png and runs/val/half/*.png (and runs/val/quarter/*.png)
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
parser.add_argument("--quarter", action="store_true", help="also quarter/, at a quarter size")
args = parser.parse_args()
folders = {1.0: "full", 0.5: "half", 0.25: "quarter"}
scales = (1.0, 0.5, 0.25) if args.quarter else (1.0, 0.5)

config = TrainConfig().override({"data.train": args.train})
photos = held_out(config)[: config.data.val_max_images]
# The cache keeps each photo at each size, named stem and stem@0.5 (splitcam.data.downscale).
cache = ImageCache(photos, min_size=1, scales=scales, progress=False)
for name, image in zip(cache.names, cache.arrays, strict=True):
    stem, _, factor = name.partition("@")
    folder = Path(args.out) / folders[float(factor or 1)]
    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(image.transpose(1, 2, 0))).save(folder / f"{stem}.png")
print(f"{cache.files} photos at {len(scales)} sizes in {args.out}")
