"""``data.colour_mined`` (splitcam.training.mining): the colour error is the Cb/Cr error written
out per pixel, mining keeps the windows a network errs on most in colour, a sampler draws mined
windows with the stated probability, and a run mines once, keeps the windows in its folder and
resumes exactly."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from conftest import tiny_config
from PIL import Image

from splitcam.data.patches import ImageCache, MinedWindows, PatchSampler
from splitcam.training import train
from splitcam.training.mining import MINED_NAME, SCORES, chroma_error, mine_colour, rgb_error


def _pairs(border: int):
    """Two random batches, each score of them, and each pair's difference inside ``border``."""
    gen = torch.Generator().manual_seed(0)
    a, b = torch.rand((2, 3, 12, 10), generator=gen), torch.rand((2, 3, 12, 10), generator=gen)
    inner = (a - b)[:, :, border:-border, border:-border].double().numpy()
    return a, b, {name: score(a, b, border=border) for name, score in SCORES.items()}, inner


def test_each_mining_score_is_its_error_written_out() -> None:
    from splitcam.training.config import MINE_SCORES

    assert set(SCORES) == set(MINE_SCORES)
    a, _, got, inner = _pairs(2)
    for i, d in enumerate(inner):
        y = 0.299 * d[0] + 0.587 * d[1] + 0.114 * d[2]
        cb, cr = (d[2] - y) / 1.772, (d[0] - y) / 1.402
        chroma = np.mean(np.concatenate([cb, cr]) ** 2)
        assert float(got["chroma"][i]) == pytest.approx(chroma, rel=1e-5)
        assert float(got["rgb"][i]) == pytest.approx(np.mean(d**2), rel=1e-5)
    grey = a.mean(1, keepdim=True).expand(-1, 3, -1, -1)
    # A luma-only error is no colour error, and all of it an rgb error.
    assert torch.allclose(chroma_error(grey + 0.1, grey), torch.zeros(2), atol=1e-10)
    assert torch.allclose(rgb_error(grey + 0.1, grey), torch.full((2,), 0.01), atol=1e-7)


class Greyer(torch.nn.Module):
    """A "network" that loses all colour: its colour error is the window's own chroma."""

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        return rgb.mean(1, keepdim=True).expand_as(rgb)


@pytest.fixture
def grey_and_colour(tmp_path) -> ImageCache:
    """Image 0 grey, image 1 grey on the left half and saturated on the right."""
    rng = np.random.default_rng(0)
    grey = np.repeat(rng.integers(0, 256, (48, 64, 1)), 3, axis=2).astype(np.uint8)
    half = grey.copy()
    half[:, 32:] = rng.integers(0, 256, (48, 32, 3))
    Image.fromarray(grey).save(tmp_path / "a.png")
    Image.fromarray(half).save(tmp_path / "b.png")
    return ImageCache(tmp_path, min_size=16, progress=False)


def test_mining_keeps_the_windows_the_network_errs_on_in_colour(grey_and_colour) -> None:
    sampler = PatchSampler(grey_and_colour, patch_size=16, seed=0, period=(2, 2))
    mined = mine_colour(
        Greyer(), sampler, candidates=200, keep=0.1, share=0.5, domain="srgb", seed=3
    )
    assert len(mined.index) == 20 and mined.share == 0.5
    # Every kept window is in the colourful image, its scored interior (all but a 4-pixel
    # border) wholly in the colourful half; the scores are each window's own chroma energy,
    # largest first.
    assert bool((mined.index == 1).all()) and bool((mined.corner[:, 1] >= 32 - 4).all())
    for corner, code, score in zip(mined.corner, mined.code, mined.score, strict=True):
        patch = sampler.assemble(torch.tensor([1]), corner[None], code[None])
        assert float(score) == pytest.approx(float(chroma_error(Greyer()(patch), patch)), rel=1e-5)
    assert torch.equal(mined.score, mined.score.sort(descending=True).values)
    # The sampler's own sequence is untouched by mining.
    again = PatchSampler(grey_and_colour, patch_size=16, seed=0, period=(2, 2))
    assert torch.equal(sampler.sample(4), again.sample(4))


class Flattener(torch.nn.Module):
    """A "network" that keeps each window's mean colour and loses all its structure."""

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        return rgb.mean((2, 3), keepdim=True).expand_as(rgb)


def test_mining_by_rgb_error_finds_structure_that_chroma_error_misses(grey_and_colour) -> None:
    """A network that loses structure errs on the grey image too: only in its channels, not in
    colour. Mined by chroma error, every kept window is in the colourful half; by rgb error,
    the grey image's windows are kept as well, each scored by its own rgb error."""
    sampler = PatchSampler(grey_and_colour, patch_size=16, seed=0, period=(2, 2))
    kept = {
        score: mine_colour(
            Flattener(),
            sampler,
            candidates=200,
            keep=0.3,
            share=0.5,
            domain="srgb",
            seed=3,
            score=score,
        )
        for score in ("chroma", "rgb")
    }
    assert bool((kept["chroma"].index == 1).all())
    assert bool((kept["rgb"].index == 0).any())
    for corner, index, code, score in zip(
        kept["rgb"].corner, kept["rgb"].index, kept["rgb"].code, kept["rgb"].score, strict=True
    ):
        patch = sampler.assemble(index[None], corner[None], code[None])
        assert float(score) == pytest.approx(float(rgb_error(Flattener()(patch), patch)), rel=1e-5)


def test_a_sampler_draws_mined_windows_with_the_stated_probability(grey_and_colour) -> None:
    windows = MinedWindows(
        torch.tensor([1, 1]),
        torch.tensor([[0, 40], [30, 44]]),
        torch.tensor([0, 5]),
        torch.tensor([2.0, 1.0]),
        patch_size=16,
        share=0.3,
    )
    sampler = PatchSampler(grey_and_colour, patch_size=16, seed=1, mined=windows)
    known = [
        sampler.assemble(windows.index[i, None], windows.corner[i, None], windows.code[i, None])[0]
        for i in range(2)
    ]
    batch = sampler.sample(2000)
    hits = sum(any(torch.equal(p, k) for k in known) for p in batch)
    # Binomial(2000, 0.3): 600 +- 20.5; 5 standard deviations either side (random windows
    # equal to a mined one are as good as impossible).
    assert 497 < hits < 703
    with pytest.raises(ValueError, match="mined windows"):
        PatchSampler(grey_and_colour, patch_size=20, seed=1, mined=windows)
    with pytest.raises(ValueError, match="share"):
        MinedWindows(*(windows.tensors()[k] for k in ("index", "corner", "code", "score")), 16, 2.0)


def test_a_run_mines_once_keeps_its_windows_and_resumes_exactly(image_folder, tmp_path) -> None:
    changes = {
        "optim.schedule": "constant",
        "network.arch": "physics",
        "data.colour_mined": 0.5,
        "data.mine_candidates": 64,
        "data.mine_keep": 0.25,
    }
    train(tiny_config(image_folder, tmp_path / "full", **changes), progress=False)
    mined = tmp_path / "full" / MINED_NAME
    assert mined.exists()
    train(
        tiny_config(image_folder, tmp_path / "split", **{**changes, "optim.steps": 3}),
        progress=False,
    )
    first = (tmp_path / "split" / MINED_NAME).read_bytes()
    assert first == mined.read_bytes()
    train(tiny_config(image_folder, tmp_path / "split", **changes), resume=True, progress=False)
    assert (tmp_path / "split" / MINED_NAME).read_bytes() == first

    def losses(run):
        rows = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
        return [r["loss"] for r in rows if "loss" in r]

    assert losses(tmp_path / "split") == losses(tmp_path / "full")
    # Without mining the same seed trains on other patches.
    train(
        tiny_config(image_folder, tmp_path / "plain", **{**changes, "data.colour_mined": 0.0}),
        progress=False,
    )
    assert losses(tmp_path / "plain") != losses(tmp_path / "full")
    assert not (tmp_path / "plain" / MINED_NAME).exists()


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (
            {"pattern.name": "random", "network.arch": "universal", "data.colour_mined": 0.5},
            "one pattern's network",
        ),
        ({"data.colour_mined": 1.5}, "colour_mined must be a probability"),
        ({"data.colour_mined": 0.5, "data.mine_keep": 0.0}, "mine_keep a share"),
        ({"data.mine_candidates": 0}, "mine_candidates must be >= 1"),
        ({"data.colour_mined": 0.5, "data.mine_score": "luma"}, "mine_score must be one of"),
    ],
)
def test_settings_mining_cannot_serve_are_refused(image_folder, tmp_path, changes, message):
    from splitcam.training import ConfigError

    with pytest.raises(ConfigError, match=message):
        tiny_config(image_folder, tmp_path / "r", **changes).validate()
    assert not (tmp_path / "r").exists()
