"""`splitcam reconstruct`: a colour image from a raw image (or a simulated one)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..io.domains import DOMAINS, SRGB
from ._common import (
    add_method_options,
    check_distinct,
    check_writable,
    warn_failed_runs,
    with_flips,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reconstruct",
        help="reconstruct a colour image with a trained run or a baseline",
        description="--image: simulate the sensor on a colour image (with --sigma noise), then "
        "reconstruct; --raw: reconstruct a raw image (.png written by `simulate`, or .npy). "
        "Large images are processed in overlapping tiles.",
    )
    p.add_argument(
        "--method", help="lmmse, bilinear, malvar2004, menon2007, or a run folder / checkpoint file"
    )
    p.add_argument("--checkpoint", help="run folder or checkpoint file (same as --method RUN)")
    p.add_argument("--model", help="a shipped model (`splitcam models` lists them) or model file")
    p.add_argument(
        "--pattern",
        help="pattern name or file: for --method lmmse and a network for any pattern, and of a "
        "--raw file that does not record it",
    )
    p.add_argument("--image", help="colour image to simulate and reconstruct")
    p.add_argument("--raw", help="raw image to reconstruct")
    p.add_argument(
        "--sigma",
        type=float,
        help="noise sigma: added to --image (default 0); of --raw, needed only if the file does "
        "not record it (raw files from `splitcam simulate` do)",
    )
    p.add_argument(
        "--domain",
        choices=DOMAINS,
        help="light domain of the raw image: srgb (the paper's protocol) or linear (--image is "
        "decoded to linear radiance before the sensor; the estimate is encoded back to sRGB for "
        "the output). Default: what a --raw file records, else the network's own, else srgb",
    )
    add_method_options(p)
    p.add_argument(
        "--out",
        required=True,
        help="output image: .png, .tif/.tiff or .jpg, or .npy (float32 H x W x 3, unclipped); "
        "sRGB display values in either domain",
    )
    p.add_argument(
        "--bits", type=int, choices=[8, 16], default=8, help="bits per channel of PNG/TIFF (8)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from ..data.imageio import read_image, read_raw
    from ..physics.light import decode_scene, encode_estimate
    from ..physics.sensor import SplitterSensor
    from ..physics.system import simulate
    from ..recon.base import method_domain

    spec = _check_request(args)
    sigma, pattern, domain, recorded = _as_recorded(args)
    sigma = 0.0 if sigma is None else sigma
    method = with_flips([_method(args, spec, pattern, domain)], args.flips)[0]
    domain = method_domain(method)  # a network's own where none was asked for
    if pattern is not None and not pattern.pattern.equals(method.pattern):
        name = pattern.label
        where = f"the raw image's pattern {name}" if recorded is not None else f"--pattern {name}"
        raise ValueError(f"{where} differs from the pattern of {spec} ({method.pattern.name})")
    if args.image:
        rgb = torch.from_numpy(read_image(args.image)).permute(2, 0, 1)[None]
        scene = decode_scene(rgb, domain)
        raw = simulate(SplitterSensor(method.pattern), scene, Path(args.image).stem, sigma)
    else:
        raw = torch.from_numpy(read_raw(args.raw))[None, None]
    if hasattr(method, "progress"):
        method.progress = not args.quiet
    with torch.no_grad():
        out = encode_estimate(method.reconstruct(raw, sigma), domain)
    _write(args, out)
    where = "" if domain == SRGB else f" ({domain} domain)"
    print(f"{method.name}{where}: wrote {args.out} ({out.shape[-1]}x{out.shape[-2]})")
    return 0


def _check_request(args: argparse.Namespace) -> str:
    """The inputs, the output and the method asked for, checked before any work; the method's
    spec."""
    if (args.image is None) == (args.raw is None):
        raise ValueError("give exactly one of --image (simulate, then reconstruct) or --raw")
    check_distinct({"--image": args.image, "--raw": args.raw}, {"--out": args.out})
    out_suffix = Path(args.out).suffix.lower()
    if args.bits == 16 and out_suffix not in (".png", ".tif", ".tiff", ".npy"):
        # Refused before minutes of reconstruction, not after.
        raise ValueError(f"--bits 16 writes .png or .tif files, not {out_suffix or 'no suffix'}")
    check_writable(args.out)
    given = [x for x in (args.method, args.checkpoint, args.model) if x]
    if len(given) != 1:
        raise ValueError(
            "give one of --model (a shipped model, e.g. D), --method (lmmse, malvar2004, ...) "
            "or --checkpoint (a run folder)"
        )
    warn_failed_runs([given[0]])
    return given[0]


def _as_recorded(args: argparse.Namespace):
    """``(sigma, pattern, domain, recorded pattern)``: the options, checked against what
    simulate recorded in a raw file (the noise level, the pattern and the light domain, which
    must agree with whatever the command is told)."""
    from .. import patterns
    from ..data.imageio import read_raw_meta

    sigma, domain = args.sigma, args.domain
    # The pattern named, read once: the method is built from it and checked against it.
    pattern = patterns.read(args.pattern) if args.pattern is not None else None
    if not args.raw:
        return sigma, pattern, domain, None
    made = read_raw_meta(args.raw)
    if made is None:
        if sigma is None or pattern is None:
            raise ValueError(
                f"{args.raw} does not record how it was made (not written by `splitcam "
                f"simulate`): give its noise level (--sigma) and its pattern (--pattern)"
            )
        return sigma, pattern, domain, None
    recorded = patterns.Pattern.from_dict(made.get("pattern"), source=str(args.raw))
    if sigma is not None and sigma != made.get("sigma"):
        raise ValueError(
            f"--sigma {sigma:g} contradicts the noise level recorded in {args.raw} "
            f"(sigma {made.get('sigma'):g}); leave --sigma out"
        )
    if pattern is not None and not pattern.pattern.equals(recorded):
        raise ValueError(
            f"--pattern {args.pattern} contradicts the pattern recorded in {args.raw} "
            f"({recorded.name}); leave --pattern out"
        )
    made_in = made.get("domain", SRGB)  # files that do not record it are of srgb
    if domain is not None and domain != made_in:
        raise ValueError(
            f"--domain {domain} contradicts the light domain recorded in {args.raw} "
            f"({made_in}); leave --domain out"
        )
    given = pattern or patterns.Given(recorded, recorded.name)
    return float(made.get("sigma", 0.0)), given, made_in, recorded


def _method(args: argparse.Namespace, spec: str, pattern, domain):
    from ..recon.registry import build_method, build_model

    if args.model:
        return build_model(
            spec, pattern=pattern, tile=args.tile, precision=args.precision, domain=domain
        )
    return build_method(
        spec,
        pattern=pattern,
        lmmse_train=args.lmmse_train,
        tile=args.tile,
        precision=args.precision,
        progress=not args.quiet,
        domain=domain,
    )


def _write(args: argparse.Namespace, out) -> None:
    """The reconstruction as ``--out``: float32 ``.npy`` (unclipped) or an 8/16-bit image."""
    from ..data.imageio import write_image

    if Path(args.out).suffix.lower() == ".npy":  # float32 (H, W, 3), unclipped
        import numpy as np

        from ..io import atomic_path

        with atomic_path(args.out) as tmp:
            np.save(tmp, out[0].permute(1, 2, 0).float().numpy())
    else:
        write_image(args.out, out[0].clamp(0, 1), bits=args.bits)
