"""`splitcam design`: design a pattern in seconds."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import table


def _network_objective(args: argparse.Namespace) -> dict:
    """What ``design --objective network`` needs: the frozen network of ``--model`` and the
    patches of ``--data`` (:func:`splitcam.design.training_patches`)."""
    from ..design import training_patches
    from ..recon.loading import load_model
    from ..recon.networks import serves_any_pattern

    if not args.data:
        raise ValueError("--objective network needs training images: --data DIR")
    system = load_model(args.model)
    if not serves_any_pattern(system.network):
        raise ValueError(f"--model {args.model} serves one pattern; give a network for any pattern")
    patches, held_out = training_patches(args.data, seed=args.seed)
    return {
        "network": system.network,
        "patches": patches,
        "batch_size": args.batch_size,
        "held_out": held_out,
    }


def register(sub: argparse._SubParsersAction) -> None:
    from ..design.defaults import DEFAULT_LR, DEFAULT_SIGMAS, DEFAULT_STEPS, OBJECTIVES

    p = sub.add_parser(
        "design",
        help="design a pattern in seconds for the closed-form LMMSE",
        description="Optimises the kernels of a pattern (same layout and kernel size; softmax "
        "kernels, so non-negative and light-conserving) by gradient descent on the closed-form "
        "LMMSE error averaged over --sigmas, with no images. Writes the pattern file and a "
        "figure beside it (same name, .png: the start next to the designed pattern) and prints "
        "the closed-form PSNR per sigma before and after.",
    )
    p.add_argument("--pattern", default="D", help="start pattern, name or file (default: D)")
    p.add_argument("--out", required=True, help="pattern file to write (.toml or .json)")
    p.add_argument(
        "--init",
        choices=["support", "exact", "random"],
        default="support",
        help="start from the pattern's support (default), exactly, or at random",
    )
    p.add_argument(
        "--sigmas",
        type=float,
        nargs="+",
        default=list(DEFAULT_SIGMAS),
        metavar="SIGMA",
        help="noise levels of the objective, 8-bit units (default: "
        + " ".join(f"{s:g}" for s in DEFAULT_SIGMAS)
        + ")",
    )
    p.add_argument(
        "--steps", type=int, default=DEFAULT_STEPS, help=f"Adam steps (default {DEFAULT_STEPS})"
    )
    p.add_argument(
        "--lr", type=float, default=DEFAULT_LR, help=f"Adam learning rate (default {DEFAULT_LR})"
    )
    p.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default="mse",
        help="mse: the mean closed-form MSE over the sigmas (default); psnr: the mean PSNR; "
        "network: the PSNR of a frozen network for any pattern (--model) on training patches "
        "(--data), one sigma per step in turn",
    )
    p.add_argument(
        "--model",
        default="universal",
        help="with --objective network: the network (default universal)",
    )
    p.add_argument("--data", help="with --objective network: folder of training images")
    p.add_argument(
        "--batch-size", type=int, default=8, help="with --objective network: patches per step"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of --init random (default 0)")
    p.add_argument("--name", help="name of the designed pattern (default: START-designed)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from .. import patterns
    from ..design import design_pattern
    from ..viz.patterns import draw_design

    out = Path(args.out)
    if out.suffix.lower() not in (".toml", ".json"):
        raise ValueError(f"--out must end in .toml or .json, got {out.name!r}")
    in_loop = _network_objective(args) if args.objective == "network" else {}
    result = design_pattern(
        args.pattern,
        init=args.init,
        sigmas=args.sigmas,
        steps=args.steps,
        lr=args.lr,
        seed=args.seed,
        objective=args.objective,
        name=args.name,
        progress=not args.quiet,
        **{k: v for k, v in in_loop.items() if k != "held_out"},
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    patterns.save(result.pattern, out)

    figure = draw_design(result.start, result.pattern, out.with_suffix(".png"))
    before, after = result.psnr_before, result.psnr_after
    rows = [
        {
            "sigma": f"{s:g}",
            result.start.name: f"{before[s]:.2f}",
            result.pattern.name: f"{after[s]:.2f}",
            "gain": f"{after[s] - before[s]:+.2f}",
        }
        for s in result.sigmas
    ]
    print(
        f"closed-form LMMSE PSNR (dB) from {result.start.name} ({args.init} start), "
        f"{args.steps} steps in {result.seconds:.1f} s:"
    )
    print(table(rows))
    if in_loop:
        from ..design import network_psnr

        held_out, net = in_loop["held_out"], in_loop["network"]
        before = network_psnr(result.start, net, held_out, result.sigmas)
        after = network_psnr(result.pattern, net, held_out, result.sigmas)
        print(f"{args.model} network PSNR (dB) on {len(held_out)} held-out patches:")
        print(
            table(
                [
                    {
                        "sigma": f"{s:g}",
                        result.start.name: f"{before[s]:.2f}",
                        result.pattern.name: f"{after[s]:.2f}",
                        "gain": f"{after[s] - before[s]:+.2f}",
                    }
                    for s in result.sigmas
                ]
            )
        )
    print(f"wrote {out} and {figure}")
    return 0
