"""``data.colour_mined``: training windows mined where the starting network errs most in colour.

Gharbi et al. (*Deep joint demosaicking and denoising*, SIGGRAPH Asia 2016) trained demosaicnet
on patches mined from a large photo collection where a baseline network's error was largest,
because the artefacts that matter (moiré, zippering, false colour) live in a small share of
patches that uniform sampling rarely shows. Here the score is the error in colour: of
``data.mine_candidates`` windows drawn at random from the training images, each is reconstructed
by the run's starting network at σ 0 and scored by the mean squared error of its two colour
differences (BT.601 Cb and Cr of the display values, a few pixels of border left out), or with
``data.mine_score = "rgb"`` by that of all three channels (fine structure as well as colour); the
``data.mine_keep`` share with the largest scores is kept, and each training patch is one of them
with probability ``data.colour_mined`` (:class:`~splitcam.data.patches.MinedWindows`).

The windows are mined once, at the run's first step, from the network it starts from, and saved
in the run folder (``mined.safetensors``), so that a resumed run draws from the same ones.
"""

from __future__ import annotations

import logging
from pathlib import Path

import torch
from safetensors.torch import load_file, save_file
from tqdm.auto import tqdm

from ..data.colour import rgb_to_opponent
from ..data.patches import MinedWindows, PatchSampler
from ..physics.light import decode_scene, encode_estimate
from .seeds import mining_seed

__all__ = ["MINED_NAME", "SCORES", "chroma_error", "mine_colour", "mined_windows", "rgb_error"]

logger = logging.getLogger(__name__)

#: File of the mined windows in a run folder.
MINED_NAME = "mined.safetensors"
#: Pixels of each window's border left out of its score (the network sees no context there).
BORDER = 4
#: Windows reconstructed at once while mining.
CHUNK = 32


def _inside(images: torch.Tensor, border: int) -> torch.Tensor:
    """``images`` without ``border`` pixels on every side, in float32."""
    return images[..., border : -border or None, border : -border or None].float()


def chroma_error(estimate: torch.Tensor, truth: torch.Tensor, border: int = BORDER) -> torch.Tensor:
    """Mean squared error of the colour differences (Cb, Cr) per image, ``border`` pixels left
    out on every side.

    Shape:
        estimate, truth: ``(B, 3, H, W)`` display values; output: ``(B,)``.
    """
    diff = rgb_to_opponent(_inside(estimate, border)) - rgb_to_opponent(_inside(truth, border))
    return diff[:, 1:].square().mean((1, 2, 3))


def rgb_error(estimate: torch.Tensor, truth: torch.Tensor, border: int = BORDER) -> torch.Tensor:
    """Mean squared error of the three channels per image, ``border`` pixels left out on every
    side (shapes as :func:`chroma_error`)."""
    return (_inside(estimate, border) - _inside(truth, border)).square().mean((1, 2, 3))


#: The window scores, by ``data.mine_score``
SCORES = {"chroma": chroma_error, "rgb": rgb_error}


@torch.no_grad()
def mine_colour(
    system: torch.nn.Module,
    sampler: PatchSampler,
    *,
    candidates: int,
    keep: float,
    share: float,
    domain: str,
    seed: int,
    device: torch.device | str = "cpu",
    progress: bool = False,
    score: str = "chroma",
) -> MinedWindows:
    """The ``keep`` share of ``candidates`` random windows of ``sampler``'s images (cut to
    whole periods as it cuts them) whose estimates by ``system`` (noise-free) have the largest
    error, :func:`chroma_error` or (``score="rgb"``) :func:`rgb_error`. The draws use a
    generator of their own (``seed``), so the sampler's sequence is untouched."""
    error = SCORES[score]
    scout = PatchSampler(
        sampler.cache, patch_size=sampler.patch_size, seed=seed, period=sampler.period
    )
    rows, cols = sampler.whole_periods
    was_training = system.training
    system.eval()
    drawn, scores = [], []
    bar = tqdm(total=candidates, desc=f"mining {score} errors", unit="window", disable=not progress)
    try:
        left = candidates
        while left > 0:
            n = min(CHUNK, left)
            choice = scout.draw(n)
            scene = decode_scene(scout.assemble(*choice)[..., :rows, :cols].to(device), domain)
            estimate = encode_estimate(system(scene), domain)
            truth = encode_estimate(scene, domain)
            scores.append(error(estimate.clamp(0, 1), truth).cpu())
            drawn.append(choice)
            left -= n
            bar.update(n)
    finally:
        bar.close()
        system.train(was_training)
    score = torch.cat(scores)
    top = score.topk(max(1, round(keep * candidates))).indices
    index, corner, code = (torch.cat([d[i] for d in drawn])[top] for i in range(3))
    return MinedWindows(index, corner, code, score[top], sampler.patch_size, share)


def mined_windows(
    run_dir: Path,
    system: torch.nn.Module,
    sampler: PatchSampler,
    config,
    *,
    device: torch.device | str = "cpu",
    progress: bool = False,
    save: bool = True,
) -> MinedWindows:
    """The run's mined windows: read from the run folder, or mined now from ``system`` (the
    network the run starts from) and (``save``: the main process) saved there."""
    data = config.data
    path = Path(run_dir) / MINED_NAME
    if path.exists():
        return MinedWindows.from_tensors(load_file(path), data.patch_size, data.colour_mined)
    mined = mine_colour(
        system,
        sampler,
        candidates=data.mine_candidates,
        keep=data.mine_keep,
        share=data.colour_mined,
        domain=data.domain,
        seed=mining_seed(config),
        device=device,
        progress=progress,
        score=data.mine_score,
    )
    if save:
        save_file(mined.tensors(), path)
    logger.info(
        "mined %d windows of %d by %s error (kept scores %.2e .. %.2e) into %s",
        len(mined.index),
        data.mine_candidates,
        data.mine_score,
        float(mined.score.min()),
        float(mined.score.max()),
        path,
    )
    return mined
