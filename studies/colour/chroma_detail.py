"""How fine the colour of each image set is: the training photos' chroma at half resolution.

    python studies/colour/chroma_detail.py [--data DIR] [--out docs/results/colour/chroma-detail.md]

For every image, :func:`splitcam.data.colour.chroma_detail` (the chroma's detail energy at the
scale of two pixels over the luma's), and the median and mean over each set: the training photos
whole and at half size (as ``data.scales`` and ``runs/colour/heldout/half`` make them), the
scikit-image photos, and the two test sets, described (they choose nothing). For the training
photos, which are JPEGs, also how their chroma is stored (Pillow's sampling code: 0 is 4:4:4,
1 is 4:2:2, 2 is 4:2:0).
"""

from __future__ import annotations

import argparse
import statistics
from collections import Counter
from pathlib import Path

import torch
from PIL import Image, JpegImagePlugin

from splitcam.data.colour import chroma_detail
from splitcam.data.imageio import decode_image
from splitcam.data.patches import downscaled, list_images
from splitcam.data.registry import training_folder
from splitcam.data.testsets import load_datasets

SAMPLING = {0: "4:4:4", 1: "4:2:2", 2: "4:2:0"}


def _photo(path: Path, factor: float) -> torch.Tensor:
    return downscaled(decode_image(path), factor).double()


def _row(name: str, values: list[float]) -> str:
    median, mean = statistics.median(values), statistics.fmean(values)
    return f"| {name} | {len(values)} | {median:.4f} | {mean:.4f} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="the training photos (the registry's)")
    parser.add_argument("--out", default="docs/results/colour/chroma-detail.md")
    args = parser.parse_args()
    photos = list_images(args.data or training_folder())
    sampling = Counter()
    for path in photos:
        with Image.open(path) as image:
            code = JpegImagePlugin.get_sampling(image) if image.format == "JPEG" else -1
        sampling[SAMPLING.get(code, "not a JPEG")] += 1
    rows = [
        _row("training photos, whole", [chroma_detail(_photo(p, 1.0)) for p in photos]),
        _row("training photos, half size", [chroma_detail(_photo(p, 0.5)) for p in photos]),
    ]
    for name, images in load_datasets("default") + load_datasets("kodak24,mcmaster"):
        rows.append(_row(f"{name} (described)", [chroma_detail(rgb) for _, rgb in images]))
    stored = ", ".join(f"{n} {kind}" for kind, n in sorted(sampling.items()))
    lines = [
        "# How fine each image set's colour is",
        "",
        "`python studies/colour/chroma_detail.py`: the chroma's detail energy at the scale of two "
        "pixels over the luma's (`splitcam.data.colour.chroma_detail`), per image, in the BT.601 "
        "opponent space.",
        "",
        f"Training photos' chroma as stored: {stored}.",
        "",
        "| images | count | median | mean |",
        "|---|---|---|---|",
        *rows,
    ]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
