"""A network for every sensor of the exposure study, trained under photon noise in linear light,
against the closed-form linear LMMSE of each sensor.

    python studies/exposure/universal_photon.py NETWORK [--images 6] [--photons 10 30 100 300 1000]
        [--sensors bayer,rgbw,...] [--out FILE.md]

NETWORK is a shipped model, a run folder or a model file trained with ``data.domain = "linear"``
and the photon model (``experiments/exposure/universal-photon.toml``), or one trained on a single
sensor (``experiments/exposure/A-photon.toml``: name it with ``--sensors A``). The photos are the
last ``--images`` of the training photos (``$SPLITCAM_DATA/train``, ``splitcam data download
train``; sorted by name; no run trains or selects on the last 24), whole (481x321: odd
sides). Read noise 2 e⁻, no ADC; PSNR (dB) of the 8-bit sRGB encoding.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from splitcam.data.images import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.evaluation.protocol import mean_psnr
from splitcam.physics.noise import Exposure
from splitcam.recon.registry import build_method

SENSORS = ["bayer", "rgbw", "quad", "A", "D", "router-zou", "router-best"]
DATA = training_folder()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("network")
    parser.add_argument("--images", type=int, default=6)
    parser.add_argument("--photons", type=float, nargs="+", default=[10, 30, 100, 300, 1000])
    parser.add_argument("--sensors", default=",".join(SENSORS), help="comma-separated")
    parser.add_argument("--out")
    args = parser.parse_args()
    torch.set_num_threads(1)
    images = [
        (p.name, torch.from_numpy(read_image(p)).permute(2, 0, 1).contiguous())
        for p in list_images(DATA)[-args.images :]
    ]
    levels = [Exposure(n) for n in args.photons]
    head = " | ".join(f"N={n:g}" for n in args.photons)
    lines = [
        f"{len(images)} held-out photos (whole), linear light, read noise 2 e-: PSNR (dB) of the "
        f"network / of the closed-form linear LMMSE / the difference; network: {args.network}",
        "",
        f"| sensor | {head} |",
        "|---|" + "---|" * len(levels),
    ]
    print("\n".join(lines), flush=True)
    for sensor in args.sensors.split(","):
        net = build_method(args.network, pattern=sensor, domain="linear")
        lmmse = build_method("lmmse", pattern=sensor, domain="linear")
        ours = mean_psnr(net, images, levels, domain="linear")
        base = mean_psnr(lmmse, images, levels, domain="linear")
        cells = [f"{ours[lv]:.2f} / {base[lv]:.2f} / {ours[lv] - base[lv]:+.2f}" for lv in levels]
        lines.append(f"| {sensor} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
