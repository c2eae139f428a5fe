"""`splitcam data`: download the test datasets (Kodak24, McMaster) or list them."""

from __future__ import annotations

import argparse

from ..data import registry


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "data",
        help="download the test datasets (Kodak24, McMaster) or list them",
        description="`splitcam data download kodak24 mcmaster --to DIR` downloads the datasets "
        "into DIR/<name>, verifying every file; use them by name with SPLITCAM_DATA=DIR. "
        "`splitcam data list` shows which are present.",
    )
    actions = parser.add_subparsers(dest="data_action", metavar="ACTION", required=True)
    p = actions.add_parser(
        "download",
        help="download and verify datasets",
        description="Downloads from the public sources pinned to a commit (or from a mirror) and "
        "checks every file against the hashes in the package's dataset registry. Files already "
        "present and verified are skipped; a file whose download was interrupted is downloaded "
        "again when the command is run again.",
    )
    p.add_argument(
        "names",
        nargs="*",
        metavar="DATASET",
        help=f"datasets to download (default: all of {', '.join(registry.dataset_names())})",
    )
    p.add_argument(
        "--to",
        metavar="DIR",
        help=f"data root; each dataset goes to DIR/<name> (default: ${registry.DATA_ENV} or "
        f"{registry.DEFAULT_ROOT})",
    )
    p.add_argument(
        "--mirror",
        metavar="URL",
        help="download <URL>/<dataset>/<file> instead of the public sources; also "
        f"a local folder (default: ${registry.MIRROR_ENV} if set)",
    )
    p.add_argument(
        "--timeout", type=float, default=30.0, help="network timeout in seconds (default: 30)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p = actions.add_parser(
        "list",
        help="list the datasets and whether they are present",
        description="Counts the files of each dataset under the data root.",
    )
    p.add_argument(
        "--root",
        metavar="DIR",
        help=f"data root (default: ${registry.DATA_ENV} or {registry.DEFAULT_ROOT})",
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from ..data.download import dataset_state, download

    if args.data_action == "download":
        names = args.names or registry.dataset_names()
        paths = download(
            names, args.to, mirror=args.mirror, progress=not args.quiet, timeout=args.timeout
        )
        root = registry.data_root(args.to)
        for name in dict.fromkeys(names):
            count = sum(1 for p in paths if p.parent.name == name)
            print(f"{name}: {count} images in {root / name}")
        if root.resolve() != registry.data_root().resolve():
            print(f"use them by name with {registry.DATA_ENV}={root}")
        return 0
    root = registry.data_root(args.root)
    print(f"data root: {root}")
    for dataset in registry.datasets().values():
        # Every file's content is checked: a damaged file is not "complete" (download repairs).
        state = dataset_state(root / dataset.name, dataset.files)
        print(f"  {dataset.name:10s} {state:16s} {dataset.description}")
    return 0
