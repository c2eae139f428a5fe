"""What several commands share: option groups and argument checks."""

from __future__ import annotations

import argparse
import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path


def table(rows: list[dict[str, str]]) -> str:
    """A listing as an aligned Markdown table (:func:`splitcam.evaluation.tables.aligned_table`,
    imported here only when a command prints one: parsing a command imports no torch)."""
    from ..evaluation.tables import aligned_table

    return aligned_table(rows)


def pattern_or_model(spec: str):
    """A pattern by name or file, or the pattern of a shipped model of one pattern (``A-opt``:
    its learned kernels)."""
    from .. import patterns
    from ..recon.loading import load_model, model_names
    from ..recon.networks import serves_any_pattern

    try:
        return patterns.get(spec)
    except patterns.PatternError:
        if spec not in model_names():
            raise
        system = load_model(spec)
        if serves_any_pattern(system.network):
            raise ValueError(f"model {spec} serves any pattern; it has none to show") from None
        return dataclasses.replace(system.pattern, name=spec)


def check_distinct(inputs: dict[str, str | None], outputs: dict[str, str | None]) -> None:
    """Refuse an output file that is one of the command's inputs or another of its outputs
    (the same file by any path): writing it would destroy what the user gave or just wrote."""

    def same(a: Path, b: Path) -> bool:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()

    seen: list[tuple[str, Path]] = []
    given = [(flag, Path(p)) for flag, p in inputs.items() if p]
    for flag, path in ((f, Path(p)) for f, p in outputs.items() if p):
        for other, known in given:
            if same(path, known):
                raise ValueError(
                    f"{flag} {path} is the file given as {other}: it would be overwritten; "
                    f"choose another output file"
                )
        for other, known in seen:
            if same(path, known):
                raise ValueError(f"{flag} and {other} name the same file {path}; choose two files")
        seen.append((flag, path))


def check_writable(path: str | os.PathLike[str], flag: str = "--out") -> None:
    """Refuse an output path that cannot be written, before any work and without making
    anything: the nearest folder that exists on the way to it must be a writable folder."""
    probe = Path(path).expanduser().resolve().parent
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ValueError(f"{flag} {path}: cannot write there ({probe} is a file, not a folder)")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {path}: cannot write there ({probe} is not writable)")


def warn_failed_runs(specs) -> None:
    """One line on stderr for each run folder or latest checkpoint among ``specs`` whose run
    ended in failure (diverged, or far below where it began), and for each run folder which of
    its checkpoints is used (its best validation, where kept)."""
    import sys
    from pathlib import Path

    from ..io import checkpoints as ckpt_io
    from ..training.models import run_failure

    for spec in specs:
        path = Path(str(spec))
        if not (path.is_dir() or path.name == ckpt_io.CHECKPOINT_NAME):
            continue
        latest = ckpt_io.resolve(path)
        if latest.is_file() and (failure := run_failure(latest)):
            used = ckpt_io.network_checkpoint(path)
            hint = f"; its best weights ({used}) are used" if used.name == ckpt_io.BEST_NAME else ""
            print(f"warning: {path} ended in failure ({failure}){hint}", file=sys.stderr)
        if (note := ckpt_io.which_checkpoint(path, best=True)) is not None:
            print(note)


def add_method_options(p: argparse.ArgumentParser) -> None:
    """Options of how methods are built and run, shared by `evaluate` and `reconstruct`."""
    p.add_argument(
        "--lmmse-train",
        metavar="DIR",
        help="fit LMMSE on these training images (default: the shipped fits)",
    )
    p.add_argument("--tile", type=int, default=512, help="tile size in pixels (default 512)")
    add_precision(p, "auto")
    add_flips(p)


def add_flips(p: argparse.ArgumentParser) -> None:
    """``--flips [exact|all]``: networks averaged over the flips and transpositions their
    sensor is symmetric under, or, ``all``, a network of any pattern over all eight
    (:class:`~splitcam.recon.ensemble.SelfEnsemble`)."""
    p.add_argument(
        "--flips",
        nargs="?",
        const="exact",
        choices=["exact", "all"],
        help="average each network over the flips and transpositions of the image that its "
        "pattern's sensor is exactly symmetric under at the image's size (1 to 8 of them); "
        "'--flips all': a network of any pattern (universal) over all 8, each look told the "
        "flipped pattern (better only on patterns it was not trained on; "
        "docs/results/flips/); the time grows with the looks; labelled <method>+flips "
        "(+all-flips)",
    )


def with_flips(methods: list, flips: str | None) -> list:
    """:func:`splitcam.recon.ensemble.with_flips`, imported when used (the CLI starts
    without torch)."""
    from ..recon.ensemble import with_flips as wrap

    return wrap(methods, flips)


def add_precision(p: argparse.ArgumentParser, default: str) -> None:
    """``--precision`` of network inference (``--fast``: the same as ``--precision bf16``)."""
    p.add_argument(
        "--precision",
        choices=["auto", "fp32", "bf16"],
        default=default,
        help=f"network inference: auto = bfloat16 + channels-last where the hardware has it "
        f"natively (about 3x faster there), fp32 = bit-exact float32 (default {default})",
    )
    p.add_argument(
        "--fast",
        dest="precision",
        action="store_const",
        const="bf16",
        help="the same as --precision bf16",
    )


def add_sensor_options(p: argparse.ArgumentParser) -> None:
    """The photon model's sensor besides the exposure (splitcam.physics.noise.Exposure), shared
    by `evaluate` and `study exposure`."""
    p.add_argument("--read-noise", type=float, help="photon model: electrons (default 2)")
    p.add_argument(
        "--full-well", type=float, help="photon model: saturation, electrons (default: none)"
    )
    p.add_argument(
        "--gain", type=float, help="photon model: ADC electrons per DN (default: no ADC)"
    )
    p.add_argument("--bits", type=int, help="photon model: ADC bits (default 12)")
    p.add_argument(
        "--dark",
        type=float,
        help="photon model: dark electrons per exposure (dark current x time; its mean is "
        "subtracted, its noise stays; default 0)",
    )
    p.add_argument(
        "--black-level",
        type=int,
        dest="black",
        help="photon model: the ADC's black level in DN, a pedestal that keeps read noise below "
        "0 e- (default 0: dark pixels clip at 0 DN); needs --gain",
    )


def sensor_settings(args: argparse.Namespace) -> dict:
    """The keyword arguments of :class:`~splitcam.physics.noise.Exposure` from the options of
    :func:`_add_sensor_options`."""
    settings = {
        "read_noise": 2.0 if args.read_noise is None else args.read_noise,
        "full_well": args.full_well,
        "gain": args.gain,
        "bits": 12 if args.bits is None else args.bits,
    }
    for name in ("dark", "black"):  # absent otherwise: the settings recorded before them
        if getattr(args, name, None):
            settings[name] = getattr(args, name)
    return settings


def sensor_flags_given(args: argparse.Namespace) -> list[str]:
    """The photon-model sensor flags given on the command line."""
    names = {"read_noise": "--read-noise", "full_well": "--full-well", "gain": "--gain"}
    names["bits"] = "--bits"
    names["dark"] = "--dark"
    names["black"] = "--black-level"
    return [flag for name, flag in names.items() if getattr(args, name, None) is not None]


def model_methods(
    models: Sequence[str], pattern_specs: Sequence, *, main_job: bool, options: dict
) -> list:
    """The methods of ``--model`` names: a model of one pattern as itself, a model for any
    pattern (``universal``) once per pattern of ``--patterns`` (names, files, or patterns read
    already: :class:`splitcam.patterns.Given`). In the main job the universal model
    reconstructs only the patterns that no shipped network serves, and says so."""
    from .. import patterns
    from ..recon.loading import model_serves_any_pattern
    from ..recon.registry import build_model

    universal = [spec for spec in models if model_serves_any_pattern(spec)]
    single = [build_model(spec, **options) for spec in models if spec not in universal]
    given = [patterns.read(p) for p in pattern_specs] if universal else []
    for spec in universal:
        wanted = list(given)
        if main_job:
            served = [m.pattern for m in single]
            wanted = [g for g in wanted if not any(g.pattern.equals(s) for s in served)]
            for g in wanted:
                print(f"pattern {g} has no shipped network: reconstructed by the {spec} network")
        single += [build_model(spec, pattern=g, **options) for g in wanted]
    return single
