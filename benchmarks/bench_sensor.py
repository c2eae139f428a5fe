"""Speed of the sensor model against the paper's literal per-splitter algorithm, in one run.

For every pattern, at 1x3x512x768 and 80x3x64x64, times the forward pass and forward+backward
(gradient to the image and the kernels) of splitcam's strided-convolution Eq. 1 and of the naive
per-site reference (mask the image per splitter, transposed convolution, crop, sum), and prints
the ratios. Target on a 2-core CPU: >= 30x for pattern A's forward at 512x768, > 1x everywhere.

    python benchmarks/bench_sensor.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import sys

import torch
from common import ROOT, machine, timeit

sys.path.insert(0, str(ROOT / "tests"))
from naive_reference import naive_splitter_forward  # noqa: E402

from splitcam import patterns  # noqa: E402
from splitcam.physics.sensor import splitter_forward  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(machine())
    print(f"{'pattern':8} {'shape':12} {'pass':9} {'naive ms':>9} {'fast ms':>8} {'ratio':>7}")
    gen = torch.Generator().manual_seed(0)
    worst = float("inf")
    for name in patterns.names():
        p = patterns.get(name)
        for shape in [(1, 3, 512, 768), (80, 3, 64, 64)]:
            f = torch.rand(shape, generator=gen)
            w = torch.tensor(p.kernels, dtype=torch.float32)
            for kind in ["forward", "fwd+bwd"]:
                results = {}
                for label, fn in [("naive", naive_splitter_forward), ("fast", splitter_forward)]:
                    if kind == "forward":

                        def run(fn=fn, f=f, w=w, layout=p.layout):
                            with torch.no_grad():
                                fn(f, w, layout)
                    else:
                        fg = f.clone().requires_grad_(True)
                        wg = w.clone().requires_grad_(True)

                        def run(fn=fn, fg=fg, wg=wg, layout=p.layout):
                            fn(fg, wg, layout).square().sum().backward()

                    results[label] = timeit(run, repeat=args.repeat)
                ratio = results["naive"] / results["fast"]
                worst = min(worst, ratio)
                size = "x".join(map(str, shape))
                print(
                    f"{name:8} {size:12} {kind:9} {results['naive'] * 1e3:9.2f} "
                    f"{results['fast'] * 1e3:8.2f} {ratio:6.1f}x"
                )
    print(f"smallest ratio over all patterns and sizes: {worst:.1f}x")


if __name__ == "__main__":
    main()
