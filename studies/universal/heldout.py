"""Universal network against each shipped network and the LMMSE, on held-out whole photos.

    python studies/universal/heldout.py UNIVERSAL [--patterns A,B,C,D,E,bayer]
        [--extra NAME=MODEL_OR_RUN ...] [--images 12] [--threads 2] [--flips exact|all]
        [--out FILE.md]

UNIVERSAL is a model name or file, or a run folder. The photos are the last ``--images`` of
the training photos (``splitcam.data.registry.training_folder``: ``$SPLITCAM_DATA/train``,
sorted by name): every run holds out the last 32 and validates on the
first 8 of those, so the last 24 are used neither for training nor for selection. They are scored
whole (481x321 or 321x481: odd sides, ending part-way through every period above 1) by the
evaluation protocol (:func:`splitcam.evaluation.protocol.mean_psnr`) at sigma 0 and 15. A pattern
without a shipped network (a file) gets the universal network and the LMMSE only. ``--extra``
adds columns, e.g. fine-tuned runs (``--extra ft=runs/ft-{pattern}``; ``{pattern}`` is replaced).
``--flips exact`` averages every network over its sensor's exact symmetries
(:class:`splitcam.recon.ensemble.SelfEnsemble`); ``--flips all`` gives the universal network all
eight looks, each told the flipped pattern.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from splitcam import patterns
from splitcam.data.imageio import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.evaluation.protocol import mean_psnr
from splitcam.recon.ensemble import with_flips
from splitcam.recon.loading import load_model, model_names
from splitcam.recon.networks import serves_any_pattern
from splitcam.recon.registry import build_method, model_domain

SIGMAS = [0.0, 15.0]
DATA = training_folder()


def shipped_for(pattern: patterns.Pattern) -> str | None:
    """The shipped single-pattern model of sRGB light (these photos' domain) whose pattern is
    this one, if any (``router-zou-photon`` serves router-zou in linear light only)."""
    for name in model_names():
        if model_domain(name) != "srgb":
            continue
        system = load_model(name)
        if not serves_any_pattern(system.network) and system.pattern.equals(pattern):
            return name
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("universal")
    parser.add_argument("--patterns", default="A,B,C,D,E,bayer")
    parser.add_argument("--extra", action="append", default=[])
    parser.add_argument("--images", type=int, default=12)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--precision", default="auto")
    parser.add_argument("--flips", choices=["exact", "all"])
    parser.add_argument("--out")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    paths = list_images(DATA)[-args.images :]
    images = [
        (p.name, torch.from_numpy(read_image(p)).permute(2, 0, 1).contiguous()) for p in paths
    ]
    extras = [e.split("=", 1) for e in args.extra]
    head = ["pattern", "LMMSE", "shipped net", "universal", *(n for n, _ in extras)]
    lines = [
        f"{len(images)} held-out photos (whole, {images[0][1].shape[-1]}x{images[0][1].shape[-2]} "
        f"and rotated), PSNR dB at sigma 0 / 15; universal: {args.universal}"
        + (f"; every network averaged over its flips (--flips {args.flips})" if args.flips else ""),
        "",
        "| " + " | ".join(head) + " | universal - LMMSE | universal - shipped |",
        "|" + "---|" * (len(head) + 2),
    ]
    print("\n".join(lines), flush=True)

    def score(method) -> dict[float, float]:
        return mean_psnr(with_flips([method], args.flips)[0], images, SIGMAS)

    for spec in args.patterns.split(","):
        pattern = patterns.get(spec)
        lmmse = score(build_method("lmmse", pattern=spec))
        shipped_name = shipped_for(pattern)
        shipped = (
            score(build_method(shipped_name, precision=args.precision)) if shipped_name else None
        )
        uni = score(build_method(args.universal, pattern=spec, precision=args.precision))
        cols = [lmmse, shipped, uni]
        for _, target in extras:
            cols.append(
                score(
                    build_method(
                        target.format(pattern=spec), pattern=spec, precision=args.precision
                    )
                )
            )

        def cell(s):
            return "–" if s is None else f"{s[0.0]:.2f} / {s[15.0]:.2f}"

        def diff(a, b):
            return (
                "–"
                if a is None or b is None
                else f"{a[0.0] - b[0.0]:+.2f} / {a[15.0] - b[15.0]:+.2f}"
            )

        row = [spec, *map(cell, cols), diff(uni, lmmse), diff(uni, shipped)]
        line = "| " + " | ".join(row) + " |"
        lines.append(line)
        print(line, flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
