"""`splitcam simulate`: the raw image a splitter sensor records of a picture."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..io.domains import DEFAULT_DOMAIN, DOMAINS, SRGB
from ._common import check_distinct


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate the raw image a splitter sensor records of a picture",
        description="Writes the raw image (16-bit PNG with its scale recorded, or .npy) and a "
        "false-colour preview PNG beside it.",
    )
    p.add_argument("image", help="colour image (PNG, JPEG, TIFF, BMP; 8 or 16 bit)")
    p.add_argument("--pattern", default="D", help="pattern name or file (default: D)")
    p.add_argument(
        "--sigma", type=float, default=0.0, help="Gaussian noise sigma in 8-bit units (default: 0)"
    )
    p.add_argument(
        "--domain",
        choices=DOMAINS,
        default=DEFAULT_DOMAIN,
        help="light domain: srgb (default: the 8-bit values are the light) or linear (the image "
        "is decoded to linear radiance first); recorded in the raw file",
    )
    p.add_argument("--out", required=True, help="raw output, .png or .npy")
    p.add_argument("--preview", help="preview PNG (default: <out>_preview.png)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from .. import patterns
    from ..data.imageio import read_image, write_image, write_raw
    from ..physics.light import decode_scene
    from ..physics.sensor import SplitterSensor
    from ..physics.system import simulate
    from ..viz.raw import false_colour

    image = Path(args.image)
    pattern = patterns.get(args.pattern)
    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".npy"):
        raise ValueError(f"--out must end in .png or .npy, got {out.name!r}")
    preview = Path(args.preview) if args.preview else out.with_name(out.stem + "_preview.png")
    check_distinct({"IMAGE": str(image)}, {"--out": str(out), "--preview": str(preview)})
    rgb = torch.from_numpy(read_image(image)).permute(2, 0, 1)[None]
    # The evaluation protocol's simulation: float64 sensor, noise seeded from the image name and
    # sigma, so a simulation is reproducible and matches what `splitcam evaluate` feeds methods.
    # In the linear domain the sensor sees the radiance the display values decode to.
    scene = decode_scene(rgb, args.domain)
    raw = simulate(SplitterSensor(pattern), scene, image.stem, args.sigma)[0, 0].numpy()
    out.parent.mkdir(parents=True, exist_ok=True)
    made = {
        "pattern": pattern.to_dict(),
        "noise": "gaussian",
        "sigma": float(args.sigma),
        "domain": args.domain,
    }
    scale = write_raw(out, raw, meta=made)
    write_image(preview, false_colour(raw, pattern))
    stored = f"16-bit PNG, full scale {scale:g}" if out.suffix.lower() == ".png" else "float32"
    where = "" if args.domain == SRGB else f", {args.domain} domain"
    print(
        f"pattern {pattern.name}, sigma {args.sigma:g}{where}: "
        f"raw {raw.shape[1]}x{raw.shape[0]}, values {raw.min():.3f}..{raw.max():.3f}"
    )
    print(f"wrote {out} ({stored}) and {preview} (false-colour preview)")
    return 0
