"""Test-time flips (splitcam.recon.ensemble.SelfEnsemble) against the plain networks on
held-out training photos: PSNR (dB) at each sigma, plain / with flips / gain.

    python studies/flips/measure.py [--models A B bayer] [--sigmas 0 15] [--odd]

The photos are the 8 training photos 25th to 32nd from the end by name (held out of every
shipped network's training; the last 24 are never used for choices), cut to even sides (as
Kodak24 and McMaster have) or, with --odd, whole (481x321).
"""

from __future__ import annotations

import argparse

import torch

from splitcam.data.images import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.evaluation.protocol import mean_psnr
from splitcam.recon.ensemble import SelfEnsemble, symmetries
from splitcam.recon.registry import build_method

DATA = training_folder()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["A", "B", "bayer", "A-opt"])
    parser.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 15.0])
    parser.add_argument("--odd", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(1)
    images = []
    for path in list_images(DATA)[-32:-24]:
        rgb = torch.from_numpy(read_image(path)).permute(2, 0, 1).contiguous()
        if not args.odd:
            rgb = rgb[:, : rgb.shape[1] // 2 * 2, : rgb.shape[2] // 2 * 2]
        images.append((path.name, rgb))
    shape = images[0][1].shape[-2:]
    sides = "whole" if args.odd else "even sides"
    print(f"{len(images)} photos, {sides}; PSNR plain / flips / gain")
    print("| model | symmetries | " + " | ".join(f"σ={s:g}" for s in args.sigmas) + " |")
    print("|---|---|" + "---|" * len(args.sigmas))
    for name in args.models:
        plain = build_method(name)
        flips = SelfEnsemble(plain)
        found = [g.label for g in symmetries(plain.pattern, *shape)]
        a = mean_psnr(plain, images, args.sigmas)
        b = mean_psnr(flips, images, args.sigmas) if len(found) > 1 else a
        cells = [f"{a[s]:.2f} / {b[s]:.2f} / {b[s] - a[s]:+.2f}" for s in args.sigmas]
        print(f"| {name} | {', '.join(found)} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
