"""`splitcam study exposure`: filters and splitters at equal light."""

from __future__ import annotations

import argparse
import sys

from ..io.domains import DOMAINS
from ..io.paper import PAPER_PATTERNS
from ._common import add_sensor_options, model_methods, sensor_settings


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "study",
        help="studies beyond the paper: `study exposure` (filters and splitters at equal light)",
        description="`splitcam study exposure`: PSNR and CIEDE2000 of the closed-form LMMSE of "
        "every pattern against exposure under the photon model (shot and read noise, the same "
        "photon flux for every pattern), the exposure below which each splitter beats the Bayer "
        "filter, and the raw SNR of each pattern against the filter next to theory; in linear "
        "light by default.",
    )
    p.add_argument("study", choices=["exposure"])
    p.add_argument("--datasets", default="default")
    p.add_argument("--max-images", type=int, help="at most this many images per dataset")
    p.add_argument(
        "--patterns",
        type=lambda s: [x for x in s.split(",") if x],
        default=list(PAPER_PATTERNS),
    )
    p.add_argument(
        "--photons", type=float, nargs="+", help="exposures (default: log-spaced from 1 to 10^4)"
    )
    p.add_argument("--points", type=int, default=9, help="default exposures: how many")
    add_sensor_options(p)
    p.add_argument(
        "--domain",
        choices=DOMAINS,
        default="linear",
        help="light domain: linear (default: scenes decoded to linear radiance before the sensor "
        "and the photon noise, reconstructions encoded back to 8-bit sRGB before scoring) or "
        "srgb (8-bit values taken as light, the paper's protocol)",
    )
    p.add_argument("--model", action="append", default=[], help="a shipped model too")
    p.add_argument(
        "--checkpoint",
        action="append",
        default=[],
        help="a trained run too (e.g. one trained with --noise photon)",
    )
    p.add_argument("--out", default="results/exposure")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..data.testsets import load_datasets
    from ..evaluation.exposure import (
        default_exposures,
        exposure_study,
        raw_snr_check,
        write_study,
    )

    if args.points < 1:
        raise ValueError(f"--points must be at least 1, got {args.points}")
    photons = args.photons or default_exposures(args.points)
    datasets = load_datasets(args.datasets, args.max_images)
    images = [img for _, imgs in datasets for img in imgs]
    names = ", ".join(f"{d} ({len(i)})" for d, i in datasets)
    from ..recon.registry import build_method

    options = {"domain": args.domain}
    methods = model_methods(args.model, args.patterns, main_job=False, options=options)
    methods += [build_method(c, domain=args.domain) for c in args.checkpoint]
    results = exposure_study(
        images,
        patterns=args.patterns,
        photons=photons,
        methods=methods,
        **sensor_settings(args),
        progress=not args.quiet,
        domain=args.domain,
    )
    snr = (
        raw_snr_check(images, patterns=args.patterns, domain=args.domain)
        if "bayer" in args.patterns
        else None
    )
    sensor = sensor_settings(args)
    note = (
        f"Images: {names}. Read noise {sensor['read_noise']:g} e-, "
        + (f"full well {args.full_well:g} e-, " if args.full_well else "no saturation, ")
        + (f"ADC {sensor['bits']} bits at {args.gain:g} e-/DN. " if args.gain else "no ADC. ")
        + "Command: "
        f"`splitcam study exposure {' '.join(sys.argv[3:])}`"
    )
    path = write_study(results, snr, args.out, note=note, domain=args.domain)
    print(path.read_text(encoding="utf-8"))
    print(f"wrote {path}, exposure.json and exposure.png")
    return 0
