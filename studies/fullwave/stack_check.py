"""The cone designs' gain behind the exposure study's optical stack, against the bare-pixel loss
they descend: the closed-form LMMSE PSNR at each design's target exposure, of the leaderboard
design they start from and of each design's current continuous densities (its saved state),
without and with silicon and the D5100's IR cut in front of every pixel.

    OMP_NUM_THREADS=1 python studies/fullwave/stack_check.py [best-n30-f2 best-n300-f2]

fmmax Jones-direct at 357 terms, the f/2 cone's seven directions, six wavelengths: the designs'
own setting (docs/results/fullwave/README.md, "The cone in the loss"). 126 solves, about 20
minutes of one thread.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import torch

from splitcam.design.fullwave import FullwaveDesign, beta_at
from splitcam.io.tensorfiles import load_pair
from splitcam.physics.fullwave import read_design
from splitcam.physics.stack import stack_of

ROOT = Path(__file__).resolve().parents[2]
DESIGNS = ROOT / "docs" / "results" / "fullwave" / "design"
START = ROOT / "experiments" / "fullwave" / "designs" / "best-240325.csv"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="*", default=["best-n30-f2", "best-n300-f2"])
    args = parser.parse_args()
    optics = stack_of(["silicon", "ir-cut"])
    grid = read_design(START)
    with torch.no_grad():
        t_start = None
        for name in args.runs:
            state = DESIGNS / name / "state"
            tensors, meta, _ = load_pair(state, "splitcam-fullwave-design", 1, name, ValueError)
            s = meta["settings"]
            bare = FullwaveDesign.from_settings(grid, s)
            behind = dataclasses.replace(bare, optics=optics)
            if t_start is None:  # the same solves for every run of this setting
                t_start = bare.transmission(torch.from_numpy(grid))[0].clamp_min(0)
            step = len(meta["history"])
            steps, (b0, b1) = s["steps"], s["beta"]
            beta = beta_at(min(step, steps - 1), steps, b0, b1)
            t = bare.transmission(bare.densities(tensors["theta"], beta))[0].clamp_min(0)
            for label, design in (("bare pixel", bare), ("behind the stack", behind)):
                a = -10 * math.log10(float(design.image_error(t_start)))
                b = -10 * math.log10(float(design.image_error(t)))
                print(
                    json.dumps(
                        {
                            "run": name,
                            "step": step,
                            "pixel": label,
                            "start": round(a, 3),
                            "design": round(b, 3),
                            "gain": round(b - a, 3),
                        }
                    ),
                    flush=True,
                )


if __name__ == "__main__":
    main()
