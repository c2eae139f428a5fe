"""Learning rate and steps of `design_pattern`: the objective along 600 steps from five starts.

    python studies/design/sweep.py mse,psnr 0.05,0.1,0.02 > docs/results/design/sweep.txt

Each line: objective, lr, start, init, seed, wall time of the 600 steps, the objective (dB) at
steps 0, 50, 100, 200, 300, 400 and 599, and the closed-form PSNR at sigma 0 and 15 at the end.
"""

import sys

from splitcam import patterns
from splitcam.design import design_pattern

STEPS = 600
STARTS = [("D", "support", 0), ("A", "support", 0), ("D", "exact", 0), ("A", "random", 0),
          ("D", "random", 1)]  # fmt: skip

for objective in sys.argv[1].split(","):
    for lr in [float(x) for x in sys.argv[2].split(",")]:
        for start, init, seed in STARTS:
            r = design_pattern(
                patterns.get(start), init=init, seed=seed, steps=STEPS, lr=lr, objective=objective
            )
            at = " ".join(f"{r.history[i]:.3f}" for i in (0, 50, 100, 200, 300, 400, STEPS - 1))
            after = r.psnr_after
            print(
                f"{objective} {lr} {start} {init} {seed} {r.seconds:.1f}s {at} "
                f"| after s0 {after[0.0]:.2f} s15 {after[15.0]:.2f}",
                flush=True,
            )
