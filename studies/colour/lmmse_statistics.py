"""The closed-form LMMSE's prior with colour the photos never show: its image statistics
estimated on the training photos and on chroma-moved copies of them, mixed, or on the photos at
a smaller size, scored on held-out photos (and described on the test sets).

    python studies/colour/lmmse_statistics.py [--weights 0 0.25 0.5] [--patterns bayer D A B E]
        [--sizes 1 0.5] [--sigmas 0 15] [--testsets] [--out docs/results/colour/lmmse-statistics.md]

The LMMSE is the one reconstruction whose prior is written down: the mean and autocovariance of
the photos (``src/splitcam/weights/image_statistics``, estimated on the 400 training photos no
run holds out). Here a copy of each of those photos has its chroma moved as the networks'
colour lever moves patches (``splitcam.data.colour.chroma_moved_copies``: channels reordered,
hue turned, chroma scaled 1-2.2x in the BT.601 opponent space, seed 0), the copies'
statistics are estimated the same way, and the prior becomes the mixture
``(1 - w) photos + w copies`` (``ImageStatistics.mixed``: the moments of a mixture are the
mixed moments; ``w = 0.5`` is about the networks' ``data.colour_statistics``). With ``--sizes``, the
photos' own statistics are estimated again on the same photos at each of those sizes (``0.5``:
half, where their JPEG chroma, stored at half resolution, is as fine as their luma; the
training's ``data.scales``), the offsets as many pixels as before; ``1+0.5`` is the photos at
both sizes, their moments mixed half and half. Every prior is scored,
closed-form, on:

- the 32 held-out training photos, whole (the rule of every shipped model: these must not fall),
  and at half size as the gate scores photos (:func:`splitcam.training.gate.gate_size`);
- the 12 most colourful of them (Hasler and Suesstrunk's measure);
- the six colour photographs inside scikit-image (the held-out set that ranked the networks'
  colour levers as McMaster did);
- with ``--testsets``, Kodak24 and McMaster, described (they choose nothing).

With ``--networks`` the rows are the shipped networks of those names (all of them solve an
LMMSE inside, :class:`splitcam.recon.networks.PhysicsReconNet`), the LMMSE solved from the
mixture and nothing trained: what the prior alone does to a network trained on the other.

PSNR of 8-bit whole images, mean over images, σ in 8-bit units (the paper's protocol). The
copies' statistics are kept in ``runs/colour/lmmse-statistics/moved``, those at a smaller size
in ``.../size-<s>``, and reused.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import torch

from splitcam.data.colour import chroma_moved_copies, colourfulness
from splitcam.data.imageio import decode_image, read_image
from splitcam.data.patches import ImageCache, list_images
from splitcam.data.registry import training_folder
from splitcam.data.testsets import default_images, load_images
from splitcam.evaluation.protocol import mean_psnr
from splitcam.io.tensorfiles import paired_paths
from splitcam.patterns import get
from splitcam.recon.base import Reconstructor
from splitcam.recon.closed_form import (
    ImageStatistics,
    closed_form_lmmse,
    estimate_image_statistics,
    shipped_image_statistics,
)
from splitcam.recon.registry import build_method
from splitcam.training.gate import gate_size

HELD_OUT = 32
COLOURFUL = 12


def moved_statistics(data: str, cache: Path, seed: int = 0) -> ImageStatistics:
    """The statistics of a chroma-moved copy of each photo the shipped statistics were
    estimated on (the same list, offsets and domain); read from ``cache`` when there."""
    if paired_paths(cache)[1].exists():
        return ImageStatistics.load(cache)
    shipped = shipped_image_statistics()
    photos = _estimated_on(data, shipped)
    images = [torch.from_numpy(read_image(p)).permute(2, 0, 1).float() for p in photos]
    moved = chroma_moved_copies(images, torch.Generator().manual_seed(seed))
    stats = estimate_image_statistics(moved, max_offset=shipped.max_offset, progress=True)
    stats.info.update({"moved": "chroma_moved_copies", "seed": seed})
    cache.parent.mkdir(parents=True, exist_ok=True)
    stats.save(cache)
    return stats


def sized_statistics(data: str, size: float, cache: Path) -> ImageStatistics:
    """The statistics of the photos the shipped statistics were estimated on, each at ``size``
    of its own (:class:`ImageCache`'s ``scales``, as training keeps them), the same offsets; the
    shipped ones at size 1. Read from ``cache`` when there."""
    shipped = shipped_image_statistics()
    if size == 1:
        return shipped
    if paired_paths(cache)[1].exists():  # (a dot in the name, size-0.5, is no suffix)
        return ImageStatistics.load(cache)
    photos = _estimated_on(data, shipped)
    lo = shipped.max_offset
    images = ImageCache(photos, min_size=2 * lo + 2, scales=[size], progress=True)
    stats = estimate_image_statistics(images, max_offset=lo, progress=True)
    stats.info.update({"size": size})
    cache.parent.mkdir(parents=True, exist_ok=True)
    stats.save(cache)
    return stats


def _estimated_on(data: str, shipped: ImageStatistics) -> list[Path]:
    """The photos the shipped statistics were estimated on: all but the held-out last."""
    photos = list_images(data)[:-HELD_OUT]
    if len(photos) != shipped.info.get("images"):
        raise SystemExit(
            f"{data} has {len(photos)} photos outside the held-out {HELD_OUT}; the shipped "
            f"statistics were estimated on {shipped.info.get('images')}"
        )
    return photos


def reconstructor(name: str, statistics: ImageStatistics, network: bool) -> Reconstructor:
    """The closed-form LMMSE of pattern ``name`` from ``statistics``, or (``network``) the
    shipped network ``name`` with the LMMSE inside it solved from them."""
    if not network:
        return closed_form_lmmse(get(name), statistics)
    method = build_method(name, precision="fp32")
    method.network.use_statistics(statistics)
    return method


def held_out_sets(data: str) -> dict[str, list[tuple[str, torch.Tensor]]]:
    paths = list_images(data)[-HELD_OUT:]
    held = [(p.stem, torch.from_numpy(read_image(p)).permute(2, 0, 1).float()) for p in paths]
    ranked = sorted(held, key=lambda item: colourfulness(item[1]), reverse=True)
    return {
        f"held-out BSD ({HELD_OUT})": held,
        f"held-out BSD, half size ({HELD_OUT})": [
            (p.stem, gate_size(decode_image(p))) for p in paths
        ],
        f"colourful BSD ({COLOURFUL})": ranked[:COLOURFUL],
        "skimage (6)": default_images(),
    }


def _sizes(text: str) -> tuple[float, ...]:
    """``--sizes``' value: one size, or several joined by ``+`` (their moments mixed equally)."""
    try:
        sizes = tuple(float(part) for part in text.split("+"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected sizes such as 0.5 or 1+0.5, got {text!r}"
        ) from None
    if not all(0 < s <= 1 for s in sizes):
        raise argparse.ArgumentTypeError(f"each size a fraction in (0, 1], got {text!r}")
    return sizes


def _argv() -> list[str]:
    """The command's own arguments but where it writes, as the table's heading gives them."""
    argv, skip = [], False
    for arg in sys.argv[1:]:
        if skip or arg.startswith("--out"):
            skip = arg == "--out"
            continue
        argv.append(arg)
    return argv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(training_folder()))
    parser.add_argument("--weights", type=float, nargs="+", default=[0.0, 0.25, 0.5])
    parser.add_argument("--patterns", nargs="+", default=["bayer", "D", "A", "B", "E"])
    parser.add_argument(
        "--sizes",
        type=_sizes,
        nargs="+",
        default=[(1.0,)],
        help="the sizes the photos' own statistics are estimated at (1: the shipped ones; "
        "1+0.5: the two mixed half and half)",
    )
    parser.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 15.0])
    parser.add_argument(
        "--networks",
        action="store_true",
        help="the shipped networks of these names instead, with the LMMSE inside them solved "
        "from the mixture (no training: what the prior alone does to a trained network)",
    )
    parser.add_argument("--testsets", action="store_true", help="describe Kodak24 and McMaster")
    parser.add_argument("--cache", default="runs/colour/lmmse-statistics/moved")
    parser.add_argument("--out", default="docs/results/colour/lmmse-statistics.md")
    args = parser.parse_args()
    if any(not 0 <= w <= 1 for w in args.weights):
        parser.error("--weights: each a fraction in [0, 1]")
    start = time.time()
    cache = Path(args.cache)
    priors = {}
    for sizes in args.sizes:
        parts = [sized_statistics(args.data, s, cache.parent / f"size-{s:g}") for s in sizes]
        prior = parts[0]
        for k, part in enumerate(parts[1:], start=2):  # the k-th of k equal shares
            prior = prior.mixed(part, 1 / k)
        priors["+".join(f"{s:g}" for s in sizes)] = prior
    moved = moved_statistics(args.data, cache) if any(args.weights) else None
    sets = held_out_sets(args.data)
    if args.testsets:
        sets |= {"Kodak24 (described)": load_images("kodak24")}
        sets |= {"McMaster (described)": load_images("mcmaster")}
    names = list(sets)
    levels = " / ".join(f"σ {s:g}" for s in args.sigmas)
    lines = [
        "# The LMMSE's prior: chroma-moved photos mixed in, the photos at other sizes",
        "",
        ("Shipped networks, the LMMSE inside them from" if args.networks else "Closed-form LMMSE,")
        + " image statistics `(1 - w) photos + w chroma-moved copies`, the photos' estimated "
        f"at a size of their own, PSNR dB at {levels}, whole images "
        f"(`python studies/colour/lmmse_statistics.py {' '.join(_argv())}`).",
        "",
        "| pattern | size | w | " + " | ".join(names) + " |",
        "|---|---|---|" + "---|" * len(names),
    ]
    for name in args.patterns:
        for (size, photos), weight in itertools.product(priors.items(), args.weights):
            prior = photos.mixed(moved, weight) if weight else photos
            method = reconstructor(name, prior, args.networks)
            cells = []
            for images in sets.values():
                psnr = mean_psnr(method, images, args.sigmas)
                cells.append(" / ".join(f"{psnr[s]:.2f}" for s in args.sigmas))
            label = f"network `{name}`" if args.networks else name
            lines.append(f"| {label} | {size} | {weight:g} | " + " | ".join(cells) + " |")
            print(lines[-1], flush=True)
    lines += ["", f"{time.time() - start:.0f} s, one process.", ""]
    Path(args.out).write_text("\n".join(lines))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
