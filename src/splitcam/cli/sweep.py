"""`splitcam sweep`: train a list of experiments, here or on a SLURM cluster."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep",
        help="train a list of experiments, here or on a SLURM cluster (resumable)",
        description="Trains every experiment file (a `train` config; run folder OUT/<file "
        "name>) that is not finished, resuming interrupted ones; finished ones are skipped, so "
        "the same command continues a sweep. Locally --jobs trainings run side by side with the "
        "threads split between them; --executor slurm submits a job array through submitit.",
    )
    p.add_argument("experiments", nargs="+", metavar="FILE", help="experiment config files")
    p.add_argument("--out", default="runs", help="folder of the run folders (default: runs)")
    p.add_argument(
        "--data",
        help="training images for every experiment (replaces data.train): a folder, or a "
        "downloaded dataset's name (train)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="a setting for every experiment, e.g. optim.steps=2000 (repeatable)",
    )
    p.add_argument("--executor", choices=["local", "slurm"], default="local")
    p.add_argument("--jobs", type=int, default=1, help="trainings at a time (default 1)")
    p.add_argument("--threads", type=int, help="CPU threads shared by local jobs (default: all)")
    p.add_argument("--partition", help="slurm partition")
    p.add_argument("--time", type=int, help="slurm time limit per job, minutes (default 60)")
    p.add_argument("--gpus", type=int, help="slurm GPUs per job")
    p.add_argument("--cpus", type=int, help="slurm CPUs per job")
    p.add_argument("--no-wait", action="store_true", help="slurm: submit and return")
    p.add_argument(
        "--snapshots",
        metavar="DIR",
        help="weights snapshots: when the sweep stops (Ctrl-C included), each unfinished run is "
        "exported to DIR/<name> (float16, small enough for git); a run with no folder continues "
        "from its snapshot on the schedule of one straight run",
    )
    p.add_argument(
        "--retrain-shipped",
        action="store_true",
        help="train experiments whose shipped model (same name) already has their budget; "
        "without it they are skipped unless their run folder or snapshot is there",
    )
    p.add_argument("--dry-run", action="store_true", help="show what each experiment needs")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..training.config import read_config_value
    from ..training.sweep import (
        continue_from_snapshots,
        load_experiments,
        run_sweep,
        status,
        without_shipped,
    )

    overrides = {}
    for item in args.set or ():
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set expects KEY=VALUE (e.g. optim.steps=2000), got {item!r}")
        overrides[key.strip()] = read_config_value(value)
    experiments = load_experiments(args.experiments, args.out, data=args.data, overrides=overrides)
    if not args.retrain_shipped:
        experiments = without_shipped(experiments, args.snapshots)
    if args.dry_run:
        if args.snapshots:
            experiments = continue_from_snapshots(experiments, args.snapshots)
        for e in experiments:
            print(f"{e.name}: {status(e)} ({e.run_dir})")
        return 0
    slurm = {
        "partition": args.partition,
        "time": args.time,
        "gpus": args.gpus,
        "cpus": args.cpus,
        "wait": not args.no_wait,
    }
    result = run_sweep(
        experiments,
        executor=args.executor,
        jobs=args.jobs,
        threads=args.threads,
        slurm=slurm,
        snapshots=args.snapshots,
    )
    print("; ".join(f"{k}: {v}" for k, v in result.items()))
    return 0 if all(v in ("done", "partial") for v in result.values()) else 1
