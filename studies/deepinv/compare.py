"""A deepinv solver on splitcam's sensor, beside splitcam's LMMSE and a shipped network.

The solver is deepinv's FISTA (accelerated proximal gradient) with its total-variation prior,
``min_x 1/2 ||A x - y||^2 + lambda TV(x)``, on :class:`splitcam.integrations.deepinv.
SplitterPhysics`; it needs no trained weights. It starts from ``A^T y`` (deepinv's default), takes
the step ``0.99 / ||A||^2`` (``||A||^2`` from the physics' ``compute_sqnorm``) and runs a fixed
number of iterations, each with a fixed number of iterations of deepinv's TV proximal solver.

The LMMSE comes twice: in closed form from the shipped image statistics (docs/model.md §10) and
as the shipped fit that ``build_method("lmmse", pattern=...)`` loads.

Images: the training folder's images sorted by name (the last 32 are held out of the networks'
training and of the image statistics; the shipped LMMSE fit used all of them). The TV weight
``lambda`` is chosen per noise level on the 8 images before the last 4 (the sweep), then every
method is scored on the last 4 (centre crops) through splitcam's evaluation protocol: the same
scenes, the same seeded noise, scores on 8-bit images.

Run from the repository root (about 3 CPU-minutes on one thread)::

    OMP_NUM_THREADS=1 python studies/deepinv/compare.py --out docs/results/deepinv.md
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import torch

import splitcam
from splitcam import patterns
from splitcam.data.images import read_image
from splitcam.data.patches import list_images
from splitcam.data.registry import training_folder
from splitcam.data.testsets import centre_crop
from splitcam.evaluation.protocol import score, simulate_and_reconstruct
from splitcam.integrations.deepinv import DeepinvReconstructor, SplitterPhysics, dinv
from splitcam.physics.system import simulate
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.recon.registry import build_method

REPO = Path(__file__).resolve().parents[2]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--data",
        default=str(training_folder()),
        help="training photos (default: $SPLITCAM_DATA/train, docs/commands.md)",
    )
    p.add_argument("--pattern", default="D")
    p.add_argument("--network", default="D", help="shipped model name")
    p.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 15.0])
    p.add_argument("--crop", type=int, default=128)
    p.add_argument("--test", type=int, default=4, help="the last N images: scored")
    p.add_argument("--sweep", type=int, default=8, help="the N images before them: sweep")
    p.add_argument("--lambdas", type=float, nargs="+", default=[0.003, 0.01, 0.03, 0.1])
    p.add_argument("--iters", type=int, default=100, help="FISTA iterations")
    p.add_argument("--tv-iters", type=int, default=10, help="TV prox iterations per FISTA step")
    p.add_argument("--long-iters", type=int, default=400, help="also this many iterations (0: not)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", help="write the results page here (markdown)")
    return p.parse_args(argv)


def load(paths: list[Path], crop: int) -> list[tuple[str, torch.Tensor]]:
    images = []
    for path in paths:
        rgb = torch.from_numpy(read_image(path)).permute(2, 0, 1).contiguous()
        images.append((path.stem, centre_crop(rgb, crop)))
    return images


def tv_solver(lam: float, stepsize: float, iters: int, tv_iters: int) -> torch.nn.Module:
    """A fresh solver (no warm-restart state carried over from another image)."""
    return dinv.optim.FISTA(
        data_fidelity=dinv.optim.L2(),
        prior=dinv.optim.TVPrior(n_it_max=tv_iters),
        lambda_reg=lam,
        stepsize=stepsize,
        max_iter=iters,
    )


def sweep(args, physics, images, stepsize) -> tuple[dict[float, float], list[str]]:
    """The TV weight of best mean PSNR at each sigma on the sweep images (one batch)."""
    truth = torch.stack([rgb for _, rgb in images])
    best, lines = {}, []
    for sigma in args.sigmas:
        raw = torch.cat([simulate(physics.splitter, rgb[None], n, sigma) for n, rgb in images])
        scores = {}
        for lam in args.lambdas:
            with torch.no_grad():
                est = tv_solver(lam, stepsize, args.iters, args.tv_iters)(raw, physics)
            psnrs = [score(e.clamp(0, 1), t)["psnr"] for e, t in zip(est, truth, strict=True)]
            scores[lam] = sum(psnrs) / len(psnrs)
            print(f"sweep sigma={sigma:g} lambda={lam:g}: {scores[lam]:.2f} dB", flush=True)
        best[sigma] = max(scores, key=scores.get)
        cells = " | ".join(
            f"**{v:.2f}**" if lam == best[sigma] else f"{v:.2f}" for lam, v in scores.items()
        )
        lines.append(f"| {sigma:g} | {cells} |")
    return best, lines


def evaluate(args, methods, sensor, images) -> dict[str, dict[float, dict[str, float]]]:
    """Mean scores and seconds per image of each method at each sigma (the protocol)."""
    results: dict[str, dict[float, dict[str, float]]] = {}
    for method in methods:
        results[method.name] = {}
        for sigma in args.sigmas:
            rows, start = [], time.perf_counter()
            for name, rgb in images:
                pred = simulate_and_reconstruct(method, sensor, name, rgb, sigma)
                rows.append(score(pred, rgb))
            seconds = (time.perf_counter() - start) / len(images)
            mean = {k: sum(r[k] for r in rows) / len(rows) for k in rows[0]}
            results[method.name][sigma] = {**mean, "seconds": seconds}
            print(f"{method.name} sigma={sigma:g}: {mean['psnr']:.2f} dB", flush=True)
    return results


def splitcam_source() -> str:
    """Where splitcam was imported from, and the git commit there (with local changes or not)."""
    folder = Path(splitcam.__file__).resolve().parents[2]

    def git(*cmd: str) -> str:
        return subprocess.run(
            ["git", "-C", str(folder), *cmd], capture_output=True, text=True, check=True
        ).stdout.strip()

    try:
        commit = git("rev-parse", "--short", "HEAD")
        dirty = bool(git("status", "--porcelain", "--", "src"))
    except (OSError, subprocess.CalledProcessError):
        return "not a git checkout"
    return f"commit {commit}" + (" with uncommitted changes under src/" if dirty else "")


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine()


def cpu_load() -> str:
    """The load averages (1, 5, 15 minutes, as ``uptime`` shows them) and whether the machine
    is busy: the 1-minute load at or above the core count (other jobs share the CPU)."""
    values = os.getloadavg()
    state = "busy" if values[0] >= (os.cpu_count() or 1) else "not busy"
    return f"load average {', '.join(f'{v:.2f}' for v in values)} ({state})"


def reading(args, results: dict, names: dict[str, str]) -> list[str]:
    """One line per sigma: each method's PSNR against the closed-form LMMSE's."""
    lines = []
    for sigma in args.sigmas:
        base = results[names["lmmse"]][sigma]["psnr"]
        parts = [
            f"{label} {results[names[key]][sigma]['psnr'] - base:+.2f} dB"
            for key, label in (
                ("tv", f"TV-FISTA at {args.iters} iterations"),
                ("tv_long", f"at {args.long_iters}"),
                ("lmmse_fit", "the shipped LMMSE fit"),
                ("network", "the network"),
            )
            if key in names
        ]
        lines.append(f"- σ={sigma:g}, against the closed-form LMMSE: {', '.join(parts)}.")
    return lines


def page(args, run: dict) -> str:
    sig = args.sigmas
    results, best = run["results"], run["best"]
    head = " | ".join(f"σ={s:g} PSNR / SSIM" for s in sig)
    rows = []
    for name, by_sigma in results.items():
        cells = " | ".join(f"{by_sigma[s]['psnr']:.2f} / {by_sigma[s]['ssim']:.4f}" for s in sig)
        secs = " / ".join(f"{by_sigma[s]['seconds']:.2f}" for s in sig)
        rows.append(f"| {name} | {cells} | {secs} |")
    lam_head = " | ".join(f"λ={lam:g}" for lam in args.lambdas)
    command = "OMP_NUM_THREADS=1 python " + " ".join(
        [str(Path(sys.argv[0]).as_posix())] + sys.argv[1:]
    )
    test, sweep_names = run["test"], run["sweep"]
    long = (
        f" The same solver with {args.long_iters} iterations (same λ) shows what the budget costs."
        if args.long_iters
        else ""
    )
    return f"""# A deepinv solver on splitcam's sensor

`splitcam.integrations.deepinv.SplitterPhysics` makes a splitter sensor a deepinv
`LinearPhysics` (`pip install 'splitcam[deepinv]'`). Here deepinv's FISTA with its TV prior, a
solver that needs no trained weights, reconstructs pattern {args.pattern} beside splitcam's
LMMSE and the shipped network (`build_method("{args.network}")`), all through splitcam's
evaluation protocol (same scenes, same seeded Gaussian noise, PSNR/SSIM on 8-bit images). The
LMMSE comes twice: in closed form from the shipped image statistics (docs/model.md §10,
`closed_form_lmmse(patterns.get("{args.pattern}"))`; statistics of the 400 training images
that precede the held-out 32) and as the shipped fit that
`build_method("lmmse", pattern="{args.pattern}")` loads (fitted on patches of all 432 training
images, so these test images took part in its fit).

## Result

{len(test)} held-out images ({", ".join(test)}: the last {len(test)} of the training photos
by name; the network's training and the image statistics left them out), centre crops
{args.crop}x{args.crop}, pattern {args.pattern}.
Mean over the images; seconds per image at σ={" / ".join(f"{s:g}" for s in sig)}.{long}

| method | {head} | s / image |
| --- | {" | ".join("---" for _ in sig)} | --- |
{chr(10).join(rows)}

{chr(10).join(reading(args, results, run["names"]))}

The TV prior is deepinv's isotropic TV of each colour channel on its own: colours are tied
together only through the measurements, while the LMMSE uses the colour statistics of natural
images and the network learned them. TV is one of deepinv's priors that need no trained
weights (wavelet sparsity, with `ptwt`, is another); its denoiser priors (plug-and-play) run on
the same `SplitterPhysics` but need downloaded weights.

## Settings

- Solver: `deepinv.optim.FISTA(data_fidelity=L2(), prior=TVPrior(n_it_max={args.tv_iters}),
  lambda_reg=λ, stepsize=0.99/‖A‖², max_iter={args.iters})` on
  `SplitterPhysics("{args.pattern}")`, started from `A^T y` (deepinv's default): {args.iters}
  FISTA iterations, each with {args.tv_iters} iterations of the TV proximal solver; a fresh
  solver per image. ‖A‖² = {run["norm"]:.4f} (`physics.compute_sqnorm` on a
  {args.crop}x{args.crop} image).
- TV weight λ per σ: {", ".join(f"σ={s:g}: λ={best[s]:g}" for s in sig)}, the best mean PSNR of
  a sweep over {{{", ".join(f"{lam:g}" for lam in args.lambdas)}}} at {args.iters} iterations on
  {len(sweep_names)} other held-out images (the {len(sweep_names)} before those above:
  {", ".join(sweep_names)}; same crops and protocol). Mean PSNR (dB) of the sweep:

| σ | {lam_head} |
| --- | {" | ".join("---" for _ in args.lambdas)} |
{chr(10).join(run["sweep_lines"])}

- Machine: {cpu_model()}, {os.cpu_count()} cores; {run["load_before"]} at the start,
  {run["load_after"]} at the end (1, 5 and 15 minutes, as `uptime` shows them; busy: the
  1-minute load at or above the core count, so other jobs shared the CPU and wall-clock
  seconds are inflated). {args.threads} torch thread. Whole script (sweep and table):
  {run["cpu"]:.0f} CPU-seconds, {run["wall"]:.0f} seconds wall-clock.
- Software: splitcam at {run["source"]}, torch {torch.__version__}, deepinv
  {dinv.__version__}.

Command (from the repository root):

```
{command}
```
"""


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    run: dict = {"load_before": cpu_load(), "source": splitcam_source()}
    cpu0, wall0 = time.process_time(), time.perf_counter()
    files = list_images(args.data)
    test = load(files[-args.test :], args.crop)
    sweep_images = load(files[-args.test - args.sweep : -args.test], args.crop)
    run["test"] = [n for n, _ in test]
    run["sweep"] = [n for n, _ in sweep_images]

    physics = SplitterPhysics(args.pattern)
    x0 = torch.zeros(1, 3, args.crop, args.crop)
    torch.manual_seed(0)  # the power iteration starts from torch.randn_like(x0)
    run["norm"] = float(physics.compute_sqnorm(x0, max_iter=500, tol=1e-5, verbose=False))
    stepsize = 0.99 / run["norm"]
    run["best"], run["sweep_lines"] = sweep(args, physics, sweep_images, stepsize)

    def tv(iters: int):
        def model(y: torch.Tensor, physics: SplitterPhysics) -> torch.Tensor:
            lam = run["best"][physics.noise_model.sigma_8bit]
            return tv_solver(lam, stepsize, iters, args.tv_iters)(y, physics)

        return model

    names = {
        "tv": f"TV-FISTA (deepinv), {args.iters} it.",
        "tv_long": f"TV-FISTA (deepinv), {args.long_iters} it.",
        "lmmse": f"LMMSE ({args.pattern}, closed form)",
        "lmmse_fit": f"LMMSE ({args.pattern}, shipped fit)",
        "network": f"network {args.network} (shipped)",
    }
    methods = [DeepinvReconstructor(tv(args.iters), physics, name=names["tv"])]
    if args.long_iters:
        methods.append(DeepinvReconstructor(tv(args.long_iters), physics, name=names["tv_long"]))
    else:
        del names["tv_long"]
    methods += [
        closed_form_lmmse(patterns.get(args.pattern)),
        build_method("lmmse", pattern=args.pattern),
        build_method(args.network),
    ]
    for method, key in zip(methods[-3:], ("lmmse", "lmmse_fit", "network"), strict=True):
        method.name = names[key]
    run["names"] = names
    run["results"] = evaluate(args, methods, physics.splitter, test)
    run["cpu"], run["wall"] = time.process_time() - cpu0, time.perf_counter() - wall0
    run["load_after"] = cpu_load()
    text = page(args, run)
    print(text)
    if args.out:
        Path(args.out).write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
