"""Shipped networks against their LMMSE on held-out crops whose sides end on a whole period or
part-way through one (docs/results/edges/README.md). From the repository root:

    python studies/edges/crops.py [MODEL...]      # default: C E B D
"""

import json
import sys

import torch

from splitcam.data.images import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.data.testsets import centre_crop
from splitcam.evaluation.protocol import mean_psnr
from splitcam.io.weights import MODELS_DIR
from splitcam.patterns import Pattern
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.registry import build_method

SIGMAS = [0.0, 15.0]
torch.set_num_threads(2)
paths = list_images(training_folder())[-16:]  # held out of every shipped run
images = [(p.name, torch.from_numpy(read_image(p)).permute(2, 0, 1).contiguous()) for p in paths]
for name in sys.argv[1:] or ["C", "E", "B", "D"]:
    net = build_method(name, precision="fp32")
    stored = json.loads((MODELS_DIR / f"{name}.json").read_text())
    lmmse = closed_form_lmmse(Pattern.from_dict(stored["pattern"]))
    for size in (126, 127, 128):
        crops = [(n, centre_crop(x, size, multiple=1)) for n, x in images]
        ours, closed = mean_psnr(net, crops, SIGMAS), mean_psnr(lmmse, crops, SIGMAS)
        print(
            name,
            size,
            f"(= {size % 3} mod 3)",
            "net",
            {s: round(ours[s], 2) for s in SIGMAS},
            "lmmse",
            {s: round(closed[s], 2) for s in SIGMAS},
            flush=True,
        )
