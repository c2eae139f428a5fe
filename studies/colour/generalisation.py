"""How much better a network does on the photos it trained on than on photos no run trains on.

    python studies/colour/generalisation.py bayer D [--photos 32] [--sizes 0.5 1] [--data DIR]
        [--out docs/results/colour/generalisation.md]

A network that has learned its photos by heart scores higher on them than on photos it never
saw. Two sets of photos also differ in how hard they are, so each set is scored twice: by the
network, and by the LMMSE of the network's pattern (:mod:`splitcam.recon.lmmse`), whose few
statistics cannot learn a photo. The **generalisation gap** is the network's gain over the LMMSE
on the photos it trained on minus its gain on the held-out photos: near 0 when the network does
on unseen photos what it does on its own; as large as the memorised share where it does not.

The sets: the held-out photos of the model's own recipe (the last 32 of the folder,
:func:`splitcam.training.validation.held_out`) and as many of its training photos, spaced
evenly through them (:func:`splitcam.training.validation.train_source`), each scored whole at
each of ``--sizes`` (0.5: the size the half-size stages train at and the gate scores), at σ 0, in
float32. The gap's 90 % interval is a bootstrap over the photos of each set (2000 draws, the 5th
and 95th percentiles).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

#: Bootstrap draws, and the interval's percentiles.
DRAWS, LEVEL = 2000, (5.0, 95.0)


def photo_sets(config: dict, data: Path, count: int) -> dict[str, list[Path]]:
    """``{"held out": ..., "trained on": ...}``: the recipe's held-out photos (at most
    ``count``) and as many of the photos it trains on, spaced evenly through them."""
    from splitcam.training.config import TrainConfig
    from splitcam.training.validation import held_out, train_source

    settings = TrainConfig.from_saved(config).override({"data.train": str(data), "data.val": None})
    held = held_out(settings)[:count]
    trained = list(train_source(settings))
    step = max(1, len(trained) // len(held))
    return {"held out": held, "trained on": trained[::step][: len(held)]}


def gap(trained: np.ndarray, held: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """The generalisation gap from per-photo gains (network minus LMMSE, dB): the mean gain on
    the photos trained on minus that on the held-out ones, and its bootstrap interval (each set
    resampled on its own)."""
    trained, held = np.asarray(trained, float), np.asarray(held, float)
    rng = np.random.default_rng(seed)
    a = trained[rng.integers(0, len(trained), (DRAWS, len(trained)))].mean(axis=1)
    b = held[rng.integers(0, len(held), (DRAWS, len(held)))].mean(axis=1)
    low, high = np.percentile(a - b, LEVEL)
    return float(trained.mean() - held.mean()), float(low), float(high)


def per_photo(spec: str, pattern, photos) -> np.ndarray:
    """PSNR (dB) at σ 0 of each photo, by a method (a model, or ``lmmse`` with ``pattern``)."""
    from splitcam.evaluation.protocol import score_images
    from splitcam.recon.registry import build_method

    method = build_method(spec, pattern=pattern, precision="fp32", domain="srgb")
    return np.array([s["psnr"] for *_, s in score_images(method, photos, [0.0])])


def main(argv: list[str] | None = None) -> None:
    from splitcam.data.imageio import decode_image
    from splitcam.data.patches import downscaled
    from splitcam.data.registry import training_folder
    from splitcam.patterns import Pattern
    from splitcam.recon.loading import load_model

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+", help="shipped networks of one pattern (or files)")
    parser.add_argument("--photos", type=int, default=32, help="photos in each set")
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.5, 1.0])
    parser.add_argument("--data", default=None, help="the training photos (the registry's)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", default="docs/results/colour/generalisation.md")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    data = Path(args.data or training_folder())
    rows = []
    for name in args.models:
        meta = load_model(name).meta
        sets = photo_sets(meta["config"], data, args.photos)
        for size in args.sizes:
            gains, cells = {}, []
            for label, paths in sets.items():
                photos = [(p.stem, downscaled(decode_image(p), size)) for p in paths]
                net = per_photo(name, None, photos)
                lmmse = per_photo("lmmse", Pattern.from_dict(meta["pattern"]), photos)
                gains[label] = net - lmmse
                cells += [f"{net.mean():.2f}", f"{lmmse.mean():.2f}", f"{gains[label].mean():.2f}"]
            mean, low, high = gap(gains["trained on"], gains["held out"])
            interval = f"{mean:+.2f} [{low:+.2f}, {high:+.2f}]"
            rows.append(f"| {name} | {size:g} | {' | '.join(cells)} | {interval} |")
            print(rows[-1], flush=True)
    n = args.photos
    lines = [
        "# How much of each network's gain is its own training photos",
        "",
        f"PSNR (dB) at σ 0, whole photos at each size, float32: {n} held-out photos and {n} of",
        "the photos each network trained on. Gain: the network minus the LMMSE of its pattern.",
        "Gap: the gain on its own photos minus the gain on the held-out ones, with its 90 %",
        "bootstrap interval over the photos.",
        "",
        "```bash",
        f"python studies/colour/generalisation.py {' '.join(args.models)} --photos {n} "
        f"--sizes {' '.join(f'{s:g}' for s in args.sizes)}",
        "```",
        "",
        "| network | size | held out: network | LMMSE | gain | trained on: network | LMMSE | gain "
        "| gap |",
        "|---|---|---|---|---|---|---|---|---|",
        *rows,
    ]
    Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
