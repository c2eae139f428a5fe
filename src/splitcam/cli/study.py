"""`splitcam study exposure`: filters and splitters at equal light; `splitcam study breakeven`:
where a lossy router ties a filter array."""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import replace
from pathlib import Path

from ..io.domains import DOMAINS, LINEAR
from ..io.paper import PAPER_PATTERNS
from ._common import add_sensor_options, model_methods, sensor_settings

#: The patterns `study exposure` states crossovers against (those among --patterns).
REFERENCES = ("bayer", "rgbw")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "study",
        help="studies beyond the paper: `study exposure` (filters and splitters at equal light), "
        "`study breakeven` (where a lossy router ties RGBW)",
        description="`splitcam study exposure`: PSNR and CIEDE2000 of the closed-form LMMSE of "
        "every pattern against exposure under the photon model (shot and read noise, the same "
        "photon flux for every pattern), the exposure below which each splitter beats the Bayer "
        "filter and the RGBW array (where they are among --patterns), and the raw SNR of each "
        "pattern against the filter next to theory; with --model or --checkpoint, networks "
        "beside the LMMSE, each compared with the reference's network. Each image's scores are "
        "written to OUT/evaluation as they come: the same command again continues an interrupted "
        "run. "
        "`splitcam study breakeven`: over a grid of "
        "router efficiency and crosstalk (router(eta=E;chi=X)), the exposure where the router's "
        "LMMSE ties the reference's (default rgbw) as a map (breakeven.md, .json, .png); one "
        "pass, no resume (about 25 ms per grid point, exposure and 128x128 image on one CPU "
        "thread). In linear light by default.",
    )
    p.add_argument("study", choices=["exposure", "breakeven"])
    _add_sensor_choice(p)
    _add_map_options(p)
    _add_camera_options(p)
    p.add_argument("--out", help="default results/exposure or results/breakeven")
    p.add_argument(
        "--restart",
        action="store_true",
        help="exposure: discard the scores OUT/evaluation holds (a study of other weights) "
        "instead of continuing them",
    )
    p.add_argument(
        "--update",
        action="store_true",
        help="exposure: score again the methods whose weights or pattern changed since the "
        "scores OUT/evaluation holds (a model shipped since), keeping every other method's",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(handler=run)


def _add_sensor_choice(p: argparse.ArgumentParser) -> None:
    """The images, the sensors, the exposures, the light domain and the reconstructions."""
    p.add_argument(
        "--datasets",
        default="default",
        help="test sets or image folders, comma-separated (default: the colour photos that "
        "ship in scikit-image)",
    )
    p.add_argument("--max-images", type=int, help="at most this many images per dataset")
    p.add_argument("--crop", type=int, help="centre crops of at most this many pixels a side")
    p.add_argument(
        "--patterns",
        type=lambda s: [x for x in s.split(",") if x],
        default=list(PAPER_PATTERNS),
        help=f"exposure: the sensors, comma-separated (default {','.join(PAPER_PATTERNS)})",
    )
    p.add_argument(
        "--photons", type=float, nargs="+", help="exposures (default: log-spaced from 1 to 10^4)"
    )
    p.add_argument("--points", type=int, default=9, help="default exposures: how many")
    add_sensor_options(p)
    p.add_argument(
        "--domain",
        choices=DOMAINS,
        default=LINEAR,
        help="light domain: linear (default: scenes decoded to linear radiance before the sensor "
        "and the photon noise, reconstructions encoded back to 8-bit sRGB before scoring) or "
        "srgb (8-bit values taken as light, the paper's protocol)",
    )
    p.add_argument(
        "--model",
        action="append",
        default=[],
        help="a shipped model too (exposure); breakeven: the model for any pattern that "
        "reconstructs every sensor of the map instead of the LMMSE",
    )
    p.add_argument(
        "--checkpoint",
        action="append",
        default=[],
        help="a trained run too (e.g. one trained with --noise photon)",
    )


def _add_map_options(p: argparse.ArgumentParser) -> None:
    """The break-even map's grid, and what both studies compare with."""
    p.add_argument(
        "--eta", type=float, nargs="+", help="breakeven: efficiencies (default 0.3 to 1, 8 steps)"
    )
    p.add_argument(
        "--chi", type=float, nargs="+", help="breakeven: crosstalks (default 0 to 0.35, 8 steps)"
    )
    p.add_argument(
        "--reference",
        help="the patterns compared with, comma-separated: breakeven: the pattern to tie "
        "(default rgbw; several each get a map in OUT/NAME/, the routers reconstructed once); "
        "exposure: the crossover columns (default bayer,rgbw, those among --patterns)",
    )
    p.add_argument(
        "--metric",
        choices=["psnr", "ssim", "ciede2000"],
        default="psnr",
        help="breakeven: the score compared (default psnr)",
    )
    p.add_argument(
        "--tol", type=float, default=0.0, help="breakeven: differences within this count as ties"
    )


def _command(args: argparse.Namespace) -> str:
    return f"`splitcam study {' '.join(sys.argv[2:])}`"


def _add_camera_options(p: argparse.ArgumentParser) -> None:
    """The camera of ``study exposure``: what turns N into lux, and the optical stack."""
    lux = p.add_argument_group(
        "exposure: the crossovers in lux (splitcam.physics.radiometry: the camera equation, "
        "a white scene, a lossless pixel)"
    )
    lux.add_argument("--pitch", type=float, default=1.0, help="pixel pitch, µm (default 1)")
    lux.add_argument("--f-number", type=float, default=2.0, help="the lens (default 2)")
    lux.add_argument("--exposure-time", type=float, default=1 / 30, help="seconds (default 1/30)")
    lux.add_argument(
        "--illuminant",
        default="D65",
        help="exposure: the light on the scenes, D65 (default), A (tungsten) or LED (white LED): "
        "every sensor sees the scenes lit by it, and the lux are its lux "
        "(splitcam.physics.stack.SceneLight)",
    )
    lux.add_argument(
        "--silicon-depth",
        type=float,
        help="µm: the pixel's QE is silicon's absorption within this depth (Green 2008); "
        "default a lossless pixel",
    )
    p.add_argument(
        "--stack",
        help="exposure: one optical stack in front of every pixel of every sensor, "
        "comma-separated: silicon (QE of 3 µm of silicon), ir-cut (the D5100's UV/IR cut, "
        "estimated), lens (ISO 7589 lens), or CSV files of wavelength_nm,transmission "
        "(splitcam.physics.stack); default none: a bare, lossless pixel",
    )


def run(args: argparse.Namespace) -> int:
    from ..data.testsets import load_datasets
    from ..evaluation.exposure import default_exposures
    from ..physics.radiometry import Camera, SiliconQE

    if args.points < 1:
        raise ValueError(f"--points must be at least 1, got {args.points}")
    if args.stack and args.silicon_depth is not None:
        raise ValueError(
            "--stack puts the pixel's QE in front of every sensor already; with it, the lux "
            "are those of a lossless pixel: leave --silicon-depth out"
        )
    if args.stack and args.study == "breakeven":
        raise ValueError("--stack is for study exposure; study breakeven takes none")
    for flag in ("restart", "update"):
        if getattr(args, flag) and args.study == "breakeven":
            raise ValueError(f"--{flag} is for study exposure; study breakeven keeps no scores")
    stack = args.optical_stack = _stack(args.stack, args.illuminant, args.study)
    white = stack.light.white_share() if stack is not None and stack.light else 1.0
    qe = SiliconQE(args.silicon_depth) if args.silicon_depth is not None else None
    args.camera = Camera(
        args.pitch, args.f_number, args.exposure_time, args.illuminant, qe=qe, white=white
    )
    photons = args.photons or default_exposures(args.points)
    datasets = load_datasets(args.datasets, args.max_images, args.crop)
    images = [img for _, imgs in datasets for img in imgs]
    names = ", ".join(f"{d} ({len(i)})" for d, i in datasets)
    # Each image's scene set (the dataset, without its crop), for crossovers per set.
    args.scene_sets = {name: re.sub(r"-\d+px$", "", d) for d, imgs in datasets for name, _ in imgs}
    if len(args.scene_sets) < len(images):  # one name in two sets: pooled only
        args.scene_sets = None
    if args.study == "breakeven":
        return _run_breakeven(args, images, names, photons)
    return _run_exposure(args, images, names, photons)


def _stack(text: str | None, illuminant: str, study: str):
    """The optical stack of ``--stack`` with the scene light of ``--illuminant`` (checked before
    any image is read), or None for neither."""
    from ..physics.stack import OpticalStack, SceneLight, stack_of

    stack = stack_of(text) if text else None
    if illuminant == "D65":
        return stack
    light = SceneLight(illuminant)
    if study == "breakeven":
        raise ValueError(
            "study breakeven's scenes are lit by D65; --illuminant relights them in study "
            "exposure only"
        )
    return OpticalStack(stack.elements if stack else (), light)


def _run_breakeven(args: argparse.Namespace, images: list, names: str, photons: list) -> int:
    from ..evaluation.breakeven import (
        DEFAULT_CHIS,
        DEFAULT_ETAS,
        against,
        break_even,
        write_break_even,
    )
    from ..patterns import get as get_pattern

    sensor = sensor_settings(args)
    method = None
    if args.checkpoint or len(args.model) > 1:
        raise ValueError(
            "study breakeven reconstructs every sensor of its map with one method: at most one "
            "--model (a model for any pattern), no --checkpoint"
        )
    if args.model:
        from ..recon.loading import model_serves_any_pattern
        from ..recon.registry import build_model

        spec = args.model[0]
        if not model_serves_any_pattern(spec):
            raise ValueError(
                f"study breakeven --model {spec}: the map needs a model for any pattern (such as "
                f"universal-photon); {spec} was trained on one pattern"
            )
        method = lambda pattern: build_model(spec, pattern=pattern, domain=args.domain)  # noqa: E731
    references = _references(args.reference, ["rgbw"])
    # Read once: an unknown reference fails before the map is computed.
    reference_patterns = [get_pattern(name) for name in references]
    result = break_even(
        images,
        method=method,
        etas=args.eta or DEFAULT_ETAS,
        chis=args.chi or DEFAULT_CHIS,
        photons=photons,
        reference=reference_patterns[0],
        metric=args.metric,
        domain=args.domain,
        tol=args.tol,
        progress=not args.quiet,
        **sensor,
    )
    note = f"Images: {names}. Command: {_command(args)}"
    out = Path(args.out or "results/breakeven")
    for i, (name, reference) in enumerate(zip(references, reference_patterns, strict=True)):
        if i:
            result = against(result, reference, images, method=method, **sensor)
        folder = out if len(references) == 1 else out / name
        path = write_break_even(result, folder, note=note)
        print(path.read_text(encoding="utf-8"))
        print(f"wrote {path}, breakeven.json and breakeven.png")
    return 0


def _run_exposure(args: argparse.Namespace, images: list, names: str, photons: list) -> int:
    from .. import patterns
    from ..evaluation.exposure import exposure_study, raw_snr_check, write_study
    from ..patterns import read as get_pattern
    from ..recon.registry import build_method

    options = {"domain": args.domain}
    # Each pattern read once, behind the optical stack if one is given.
    given = [get_pattern(p) for p in args.patterns]
    stack = args.optical_stack
    if stack is not None:
        given = [patterns.Given(stack.apply(g.pattern), g.label) for g in given]
    methods = model_methods(args.model, given, main_job=False, options=options)
    methods += [build_method(c, domain=args.domain) for c in args.checkpoint]
    _check_networks_behind(methods, stack)
    out = args.out or "results/exposure"
    loaded = [g.pattern for g in given]
    results = exposure_study(
        images,
        patterns=loaded,
        photons=photons,
        methods=methods,
        **sensor_settings(args),
        progress=not args.quiet,
        domain=args.domain,
        out=Path(out) / "evaluation",
        scene_sets=args.scene_sets,
        restart=args.restart,
        rescore_changed=args.update,
    )
    snr = (
        raw_snr_check(images, patterns=loaded, domain=args.domain)
        if "bayer" in args.patterns
        else None
    )
    sensor = sensor_settings(args)
    note = (
        f"Images: {names}. Read noise {sensor['read_noise']:g} e-, "
        + (f"dark {sensor['dark']:g} e- per exposure, " if sensor.get("dark") else "")
        + (f"full well {args.full_well:g} e-, " if args.full_well else "no saturation, ")
        + (f"ADC {sensor['bits']} bits at {args.gain:g} e-/DN. " if args.gain else "no ADC. ")
        + _stack_note(stack, args.camera)
        + f"Command: {_command(args)}"
    )
    networks = {m.name: m.pattern.name for m in methods}
    path = write_study(
        results,
        snr,
        out,
        note=note,
        domain=args.domain,
        references=_references(args.reference, list(REFERENCES)),
        networks=networks,
        camera=args.camera,
    )
    print(path.read_text(encoding="utf-8"))
    print(f"wrote {path}, exposure.json and exposure.png")
    return 0


def _stack_note(stack, camera) -> str:
    """The stack and the scene light, as the study's note states them."""
    if stack is None:
        return ""
    note = f"Every pixel behind: {replace(stack, light=None)}. " if stack.elements else ""
    if stack.light is not None:
        note += (
            f"Scenes lit by {stack.light.illuminant} "
            f"(white gives a bare pixel {camera.white:.3g} N). "
        )
    return note


def _check_networks_behind(methods: list, stack) -> None:
    """Every network must reconstruct its sensor behind the study's stack: one trained on one
    sensor knows that sensor behind the stack its run recorded (``splitcam train --stack``), and
    would otherwise be scored on another sensor than the study's."""
    from ..physics.stack import NO_STACK, recorded_stack

    want = str(stack) if stack is not None else NO_STACK
    wrong = [m for m in methods if recorded_stack(m.pattern) != want]
    if wrong:
        m = wrong[0]
        raise ValueError(
            f"{m.name} reconstructs {m.pattern.name} behind {recorded_stack(m.pattern)}, the "
            f"study puts every sensor behind {want}: train it with the study's --stack, or use "
            "a model for any pattern (universal-photon)"
        )


def _references(text: str | None, default: list[str]) -> list[str]:
    """The patterns of ``--reference`` (comma-separated), or ``default``."""
    if text is None:
        return default
    names = [r.strip() for r in text.split(",") if r.strip()]
    if not names:
        raise ValueError("--reference names no pattern")
    return names
