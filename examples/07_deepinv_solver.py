"""splitcam from deepinv: a splitter sensor as a deepinv physics operator, solved with TV.

``splitcam.integrations.deepinv.SplitterPhysics`` is a ``deepinv.physics.LinearPhysics`` whose
``A`` / ``A_adjoint`` are the splitter sensor of any pattern and whose noise is splitcam's. Any
deepinv solver runs on it; here a total-variation regularised proximal gradient descent
(``deepinv.optim.PGD`` with ``TVPrior``, no downloaded weights), wrapped as a splitcam method by
``DeepinvReconstructor`` so the paper's protocol scores it beside the closed-form LMMSE and the
shipped network of pattern D. Writes ``deepinv.png`` (a zoomed crop of each reconstruction).

Needs deepinv (``pip install 'splitcam[deepinv]'``); without it, or where its torchvision
cannot load beside this torch, the script says why in one line, with the command that fixes
it, and exits with status 1.

    python examples/07_deepinv_solver.py [--out DIR] [--tiny]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from splitcam.data.testsets import centre_crop, default_images
from splitcam.evaluation.protocol import score_images
from splitcam.recon import build_method
from splitcam.viz.zoom import zoom_figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples-out/07", help="output folder")
    parser.add_argument("--tiny", action="store_true", help="1 small image, 10 iterations")
    args = parser.parse_args()
    try:
        # splitcam's module first: where deepinv is missing, or torchvision was built for another
        # torch, it says so in one line, with the command that fixes it
        from splitcam.integrations.deepinv import DeepinvReconstructor, SplitterPhysics  # noqa: I001

        import deepinv as dinv
    except ImportError as exc:
        print(f"07_deepinv_solver.py cannot run here: {exc}", file=sys.stderr)
        sys.exit(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    size, count, iterations = (48, 1, 10) if args.tiny else (256, 3, 100)
    images = [(n, centre_crop(im, size)) for n, im in default_images()[:count]]
    sigma = 5.0

    physics = SplitterPhysics("D")
    probe = torch.zeros(1, 3, 32, 32)
    norm = float(physics.compute_sqnorm(probe, verbose=False))
    print(f"deepinv adjointness test: {float(physics.adjointness_test(probe)):.1e}")
    print(f"‖A‖² = {norm:.3f} (deepinv's power iteration)")
    solver = dinv.optim.PGD(
        data_fidelity=dinv.optim.L2(),
        prior=dinv.optim.TVPrior(n_it_max=20),
        lambda_reg=0.02,
        stepsize=1.0 / norm,
        max_iter=iterations,
    )
    methods = [
        DeepinvReconstructor(solver, physics, name=f"deepinv TV-PGD ({iterations} it.)"),
        build_method("lmmse", pattern="D"),
        build_method("D"),
    ]
    first = images[0][1]
    panels = {}
    for method in methods:
        rows = list(score_images(method, images, [sigma]))
        psnr = sum(r[3]["psnr"] for r in rows) / len(rows)
        print(f"{method.name:<28} PSNR {psnr:6.2f} dB on {len(rows)} photo(s), σ = {sigma:g}")
        panels[method.name] = (rows[0][2], rows[0][3])
    region = None if size >= 96 else (0, 0, size)  # None: the most detailed 96x96 region
    path = zoom_figure(
        first, panels, out / "deepinv.png", title=f"pattern D, σ = {sigma:g}", region=region
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
