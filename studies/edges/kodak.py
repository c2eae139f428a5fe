"""Networks of 1x3-period patterns on Kodak24: the whole images against the same images one or
two columns narrower, so that every row ends one column into a period (width = 1 mod 3) or on a
whole period (docs/results/edges/README.md). From the repository root:

    SPLITCAM_DATA=DIR python studies/edges/kodak.py [MODEL...]   # default: C E

with Kodak24 under ``DIR/kodak24`` (``splitcam data download kodak24 --to DIR``).
"""

import sys

import torch

from splitcam.data.testsets import load_images
from splitcam.evaluation.protocol import mean_psnr
from splitcam.recon.registry import build_method

torch.set_num_threads(1)
images = load_images("kodak24")


def narrow(x: torch.Tensor, rem: int) -> torch.Tensor:
    w = x.shape[-1]
    return x[..., : w - (w - rem) % 3].contiguous()


variants = {
    "whole": lambda x: x,
    "w=1 mod 3": lambda x: narrow(x, 1),
    "w=0 mod 3": lambda x: narrow(x, 0),
}
for name in sys.argv[1:] or ["C", "E"]:
    net = build_method(name, precision="fp32")
    for label, cut in variants.items():
        psnr = mean_psnr(net, [(n, cut(x)) for n, x in images], [0.0, 15.0])
        print(name, label, {s: round(v, 3) for s, v in psnr.items()}, flush=True)
