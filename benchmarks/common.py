"""Shared helpers for the benchmark scripts: timing and a description of the machine."""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

from splitcam.data.registry import data_root

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = data_root()  # the data root: $SPLITCAM_DATA (splitcam.data.registry)


def machine() -> str:
    """One line: CPU model, cores, torch version and threads, Python and OS."""
    import torch

    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} logical cores; torch {torch.__version__} "
        f"({torch.get_num_threads()} threads); Python {sys.version.split()[0]}; "
        f"{platform.system()} {platform.release()}"
    )


def timeit(
    fn: Callable[[], object], *, repeat: int = 5, warmup: int = 1, min_time: float = 0.0
) -> float:
    """Median seconds per call over ``repeat`` calls (more if ``min_time`` is not reached)."""
    for _ in range(warmup):
        fn()
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < repeat or time.perf_counter() - start < min_time:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)
