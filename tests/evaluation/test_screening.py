"""LMMSE screening of patterns (splitcam.evaluation.screening)."""

from __future__ import annotations

import torch

from splitcam import patterns
from splitcam.data.patches import ImageCache
from splitcam.evaluation.screening import evaluate_method, screen_patterns
from splitcam.recon.lmmse import LMMSE


def _smooth_images(n: int, h: int, w: int, seed: int) -> torch.Tensor:
    """Random images with some spatial correlation (a 3x3 box blur of uniform noise)."""
    gen = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, h + 2, w + 2, generator=gen, dtype=torch.float64)
    return torch.nn.functional.avg_pool2d(x, 3, stride=1)


def test_screen_patterns_on_a_few_training_images(shared_data):
    cache = ImageCache(shared_data / "train", min_size=32, max_images=3, progress=False)
    tests = [(f"synthetic{i}", img.float()) for i, img in enumerate(_smooth_images(2, 24, 30, 12))]
    result = screen_patterns(
        [patterns.get("D"), patterns.get("bayer")],
        cache,
        tests,
        sigmas=(0, 10),
        radius=2,
        patches=16,
        patch_size=32,
    )
    assert len(result.rows) == 4 and len(result.per_image) == 8
    for sigma, order in result.ranking.items():
        assert sorted(order) == ["D", "bayer"]
        ranked = sorted((r for r in result.rows if r["sigma"] == sigma), key=lambda r: r["rank"])
        assert [r["pattern"] for r in ranked] == order
        assert ranked[0]["psnr"] >= ranked[1]["psnr"]
    for row in result.rows:
        assert row["fit_seconds"] > 0 and row["eval_seconds"] > 0
        assert 0 < row["ssim"] <= 1 and row["ciede2000"] >= 0
    # The screen scores exactly what evaluate_method gives for the same fit.
    again = evaluate_method(LMMSE(result.statistics["D"]), tests, [10])
    mine = [r for r in result.per_image if r["pattern"] == "D" and r["sigma"] == 10]
    assert [r["psnr"] for r in again] == [r["psnr"] for r in mine]
