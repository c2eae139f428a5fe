"""Name the configuration file of every stage in the shipped models' provenance.

    python scripts/name_stage_files.py [--check]

Segments exported before segments recorded their file (``config_file``) get the file of their
model's recipe stage (``experiments/recipes/<model>.toml``): one segment per stage, or, for a
recipe of one stage, every segment (a run continued on another machine). Only the JSON header
changes (its ``meta_sha256`` is recomputed); the weights and their checksum do not, so every
score of the model stays what it was. A segment that already names its file is left as it is;
a model whose segments do not match its recipe is reported, not changed. ``--check`` changes
nothing and exits 1 if a model would change.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from splitcam.io.tensorfiles import meta_checksum
from splitcam.io.weights import MODELS_DIR
from splitcam.training.recipe import read_recipe

ROOT = Path(__file__).resolve().parents[1]


def named(meta: dict, stages: list[str]) -> dict | None:
    """``meta`` with every segment's ``config_file`` filled from ``stages``, or None if the
    segments cannot be matched to the stages."""
    segments = meta["provenance"]["segments"]
    if len(stages) == 1:
        files = stages * len(segments)
    elif len(stages) == len(segments):
        files = stages
    else:
        return None
    out = json.loads(json.dumps(meta))
    for segment, file in zip(out["provenance"]["segments"], files, strict=True):
        if not segment.get("config_file"):
            segment["config_file"] = file
    out["meta_sha256"] = meta_checksum(out)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="change nothing; exit 1 if needed")
    args = parser.parse_args(argv)
    changed, unmatched = [], []
    for path in sorted(MODELS_DIR.glob("*.json")):
        meta = json.loads(path.read_text(encoding="utf-8"))
        stages = [str(p.relative_to(ROOT)) for p in read_recipe(path.stem).stages]
        new = named(meta, stages)
        if new is None:
            unmatched.append(path.stem)
            continue
        if new != meta:
            changed.append(path.stem)
            if not args.check:
                path.write_text(json.dumps(new, indent=1) + "\n", encoding="utf-8")
    for name in unmatched:
        print(f"{name}: its segments do not match its recipe's stages; left as it is")
    print(
        ("would name" if args.check else "named")
        + f" stage files in: {', '.join(changed) or 'none'}"
    )
    return 1 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
