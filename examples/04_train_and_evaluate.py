"""Train a network for a pattern and evaluate it against the LMMSE on held-out photos.

A small ``physics`` network (it corrects the closed-form LMMSE estimate) is trained for pattern
D with ``splitcam.training.train`` on a folder of images: ``--data DIR``, or else the sample
photographs that ship inside scikit-image, written as PNG files into the output folder. The last
two images (sorted by name) are held out for validation and scored at the end. The run folder
is what ``build_method`` loads, like any run of ``splitcam train``. Writes ``curves.png`` (loss
and validation PSNR against step) and ``run/`` (checkpoint, metrics, config).

Half a minute of one CPU thread trains a small network that edges past the LMMSE (0.2-0.5 dB);
the shipped networks (``splitcam models``) are larger and trained for hours.

    python examples/04_train_and_evaluate.py [--out DIR] [--tiny] [--data DIR] [--steps N]
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from splitcam.data.imageio import write_image
from splitcam.data.testsets import centre_crop, default_images, load_images
from splitcam.evaluation.protocol import mean_psnr
from splitcam.recon import build_method
from splitcam.training import TrainConfig, train
from splitcam.viz.curves import plot_run

#: Seconds of CPU, for CI: 16-pixel patches, an 8-feature one-block network, 6 steps.
TINY = {
    "data.patch_size": 16,
    "data.batch_size": 4,
    "data.val_crop": 32,
    "network.features": 8,
    "network.blocks": 1,
    "optim.steps": 6,
    "optim.warmup_steps": 5,
    "run.log_every": 1,
    "run.val_every": 3,
    "run.checkpoint_every": 3,
}
#: About 35 s on one thread of a busy 2-core CPU.
FULL = {
    "data.patch_size": 48,
    "data.batch_size": 8,
    "data.val_crop": 128,
    "network.features": 16,
    "network.blocks": 2,
    "optim.steps": 1000,
    "optim.warmup_steps": 20,
    "run.log_every": 10,
    "run.val_every": 250,
    "run.checkpoint_every": 250,
}


def sample_folder(folder: Path, size: int) -> Path:
    """The sample photographs as PNG files (centre crops of ``size``) in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, rgb in default_images():
        write_image(folder / f"{name.removeprefix('skimage/')}.png", centre_crop(rgb, size))
    return folder


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples-out/04", help="output folder")
    parser.add_argument("--tiny", action="store_true", help="a 6-step run: seconds, for CI")
    parser.add_argument("--data", help="folder of training images (default: sample photos)")
    parser.add_argument("--steps", type=int, help="training steps (default 1000, tiny 6)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    settings = dict(TINY if args.tiny else FULL)
    if args.steps:
        settings["optim.steps"] = args.steps
    data = Path(args.data) if args.data else sample_folder(out / "data", 64 if args.tiny else 256)
    run = out / "run"
    shutil.rmtree(run, ignore_errors=True)  # a fresh run each time (train --resume continues)
    config = TrainConfig().override(
        {
            **settings,
            "pattern.name": "D",
            "network.arch": "physics",
            "data.train": str(data),
            "data.val_split": 2,
            "data.val_sigmas": [0.0, 15.0],
            "run.out": str(run),
            "run.threads": 1,
        }
    )
    result = train(config, progress=False)
    print(f"trained {result.step} steps into {result.run_dir}")

    images = load_images(data)[-2:]  # sorted by name, as the held-out split
    sigmas = [0.0, 15.0]
    for spec, method in (("LMMSE", build_method("lmmse", pattern="D")), ("network", None)):
        method = method or build_method(run)
        psnr = mean_psnr(method, images, sigmas)
        cells = "   ".join(f"σ={s:g}: {psnr[s]:.2f} dB" for s in sigmas)
        print(f"{spec:<8} on {len(images)} held-out images   {cells}")
    path = plot_run(run, out / "curves.png")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
