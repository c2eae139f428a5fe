"""How long `splitcam --help` and `splitcam train --help` take, against a bare interpreter.

    python benchmarks/bench_cli_help.py [--repeats 5]

Runs each command ``--repeats`` times in fresh processes and prints the median wall time, with
the median of ``python -c pass`` (the interpreter's own start-up) measured in the same run and
the difference. Parsing imports no torch, so the difference is the CLI's own cost.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

COMMANDS = {
    "python -c pass (baseline)": [sys.executable, "-c", "pass"],
    "splitcam --help": [sys.executable, "-m", "splitcam", "--help"],
    "splitcam train --help": [sys.executable, "-m", "splitcam", "train", "--help"],
    "splitcam evaluate --help": [sys.executable, "-m", "splitcam", "evaluate", "--help"],
}


def median_seconds(argv: list[str], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        times.append(time.perf_counter() - began)
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    results = {name: median_seconds(argv, args.repeats) for name, argv in COMMANDS.items()}
    base = results["python -c pass (baseline)"]
    for name, seconds in results.items():
        print(f"{name:28s} {seconds:6.3f} s   (+{seconds - base:.3f} s over the baseline)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
