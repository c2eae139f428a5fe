"""Record every stage's settings in the shipped models' provenance, so each model is its own
recipe (``splitcam train --recipe MODEL``; splitcam.training.recipe).

    python scripts/record_stage_settings.py [--check]

Models exported since segments record their settings need nothing. An older segment gets the
settings of the configuration file it names (``config_file``, resolved with its ``extends``),
with the values the segment itself recorded put over them wherever the two differ (the record
is what ran: a learning rate or batch given on the command line); each such difference is
printed. Only the JSON header changes (its ``meta_sha256`` is recomputed); the weights and their
checksum do not, so every score of the model stays what it was. ``--check`` changes nothing and
exits 1 if a model would change.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from splitcam.io.tensorfiles import meta_checksum
from splitcam.io.weights import MODELS_DIR
from splitcam.training import TrainConfig
from splitcam.training.recipe import replayable

ROOT = Path(__file__).resolve().parents[1]


def recorded(segment: dict[str, Any]) -> dict[str, Any]:
    """The settings a segment's own record states, as dotted keys."""
    recipe = segment.get("recipe") or {}
    sigma = recipe.get("sigma") or [None, None]
    values = {
        "data.batch_size": segment.get("batch_size"),
        "data.patch_size": segment.get("patch_size"),
        "network.arch": recipe.get("arch"),
        "optim.lr": recipe.get("lr"),
        "optim.schedule": recipe.get("schedule"),
        "optim.warmup_steps": recipe.get("warmup_steps"),
        "optim.sigma_min": sigma[0],
        "optim.sigma_max": sigma[1],
        "optim.divergence_factor": recipe.get("divergence_factor"),
        "pattern.learn": recipe.get("learn_pattern"),
        "pattern.init": recipe.get("pattern_init"),
        "pattern.design_steps": recipe.get("design_steps"),
        "run.time_limit": recipe.get("time_limit_min"),
    }
    if "loss" in recipe:
        values["optim.loss"] = recipe["loss"]
        values["optim.ema"] = recipe.get("ema")
    optional = ("run.time_limit", "optim.ema")  # None is a value of these
    return {k: v for k, v in values.items() if v is not None or k in optional}


def settings_of(segment: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """A segment's settings from its file with its record over them, and the differences."""
    config = TrainConfig.from_file(ROOT / segment["config_file"])
    current = {f"{s}.{k}": v for s, values in config.to_dict().items() for k, v in values.items()}
    record = recorded(segment)
    differ = {k: v for k, v in record.items() if current[k] != v}
    notes = [f"{k} {current[k]} -> {v}" for k, v in differ.items()]
    return replayable(config.override(differ).to_dict()), notes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="change nothing; exit 1 if needed")
    args = parser.parse_args(argv)
    changed = []
    for path in sorted(MODELS_DIR.glob("*.json")):
        meta = json.loads(path.read_text(encoding="utf-8"))
        new = json.loads(json.dumps(meta))
        for index, segment in enumerate(new["provenance"]["segments"]):
            if segment.get("settings"):
                continue
            segment["settings"], notes = settings_of(segment)
            for note in notes:
                print(f"{path.stem} segment {index + 1} ({segment['config_file']}): {note}")
        if new != meta:
            new["meta_sha256"] = meta_checksum(new)
            changed.append(path.stem)
            if not args.check:
                path.write_text(json.dumps(new, indent=1) + "\n", encoding="utf-8")
    done = "would record" if args.check else "recorded"
    print(f"{done} settings in: {', '.join(changed) or 'none'}")
    return 1 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
