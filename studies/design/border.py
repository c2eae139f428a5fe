"""Where the held-out error of designed patterns comes from: the image borders.

    python studies/design/border.py [FILES...]

On the first 6 of the 32 held-out images, at sigma 0, the closed-form LMMSE of each pattern
reconstructs (1) the raw image as the protocol simulates it (the scene is 0 outside the image
and so is the raw image the LMMSE sees), (2) the raw image of the scene extended by reflection,
cropped to the image (a sensor that sees a scene continuing past the crop), and (3) that
extended raw image uncropped, the reconstruction cropped afterwards (the LMMSE also sees the raw
image past the border). Prints the mean PSNR (whole images) of each.
"""

import sys
from pathlib import Path

import torch
import torch.nn.functional as F

from splitcam import patterns
from splitcam.data.images import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.evaluation.metrics import psnr
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.closed_form import closed_form_lmmse

PAD = 8  # a multiple of every 2x2 period, more than the kernels' and filters' reach
files = sys.argv[1:] or [
    "D",
    "docs/results/design/D-support.toml",
    "A",
    "docs/results/design/A-random-seed0.toml",
]
images = [
    torch.from_numpy(read_image(f)).permute(2, 0, 1)
    for f in list_images(training_folder())[-32:][:6]
]
for f in files:
    pattern = patterns.get(f)
    sensor, method = SplitterSensor(pattern), closed_form_lmmse(pattern)
    res: dict[str, list[float]] = {"protocol": [], "scene continues": [], "raw continues": []}
    for rgb in images:
        rgb = rgb[:, : rgb.shape[1] // 2 * 2, : rgb.shape[2] // 2 * 2]  # whole periods
        with torch.no_grad():
            raw = sensor(rgb[None].double()).float()
            res["protocol"].append(psnr(method.reconstruct(raw, 0.0)[0].clamp(0, 1), rgb))
            big = sensor(F.pad(rgb[None], (PAD,) * 4, mode="reflect").double()).float()
            crop = big[:, :, PAD:-PAD, PAD:-PAD]
            res["scene continues"].append(psnr(method.reconstruct(crop, 0.0)[0].clamp(0, 1), rgb))
            rec = method.reconstruct(big, 0.0)[0, :, PAD:-PAD, PAD:-PAD].clamp(0, 1)
            res["raw continues"].append(psnr(rec, rgb))
    print(f"{Path(f).stem:16s}", " | ".join(f"{k}: {sum(v) / len(v):.2f}" for k, v in res.items()))
