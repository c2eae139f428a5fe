"""The noise interface (splitcam.physics.noise.NoiseModel): a model defined here, in the test
suite, runs through the sensor's simulation, the LMMSE, the networks' noise-level input and
``evaluate`` without touching anything else in the library.

The toy model is uniform noise of half-width ``w`` (8-bit units): variance ``(w / 255)^2 / 3``.
The LMMSE knows noise only by its variance, so it must build exactly the filters of Gaussian
noise of that variance: an independent computation to compare against.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import pytest
import torch

from splitcam import patterns
from splitcam.evaluation import evaluate
from splitcam.evaluation.tables import append_rows, read_rows
from splitcam.physics.noise import (
    Exposure,
    Gaussian,
    NoiseModel,
    as_noise,
    level_heading,
    level_key,
)
from splitcam.physics.sensor import SplitterSensor, pattern_pixel_kernels
from splitcam.physics.system import simulate
from splitcam.recon.closed_form import lmmse_estimate, shipped_image_statistics
from splitcam.recon.networks import noise_level_map
from splitcam.recon.registry import build_method


@dataclass(frozen=True)
class UniformNoise(NoiseModel):
    """Uniform noise on ``[-w, w]`` (8-bit units)."""

    width: float

    def apply(self, raw: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        u = torch.rand(tuple(raw.shape), generator=generator, dtype=torch.float64)
        return raw + ((2 * u - 1) * self.width / 255.0).to(raw.dtype)

    def variance_coefficients(self) -> tuple[float, float]:
        return 0.0, (self.width / 255.0) ** 2 / 3.0

    def label(self) -> str:
        return f"U{self.width:g}"


def _scene(h: int = 37, w: int = 41) -> torch.Tensor:
    gen = torch.Generator().manual_seed(3)
    small = torch.rand(1, 3, 5, 6, generator=gen)
    return torch.nn.functional.interpolate(small, size=(h, w), mode="bilinear")


def test_simulate_draws_the_toy_noise_deterministically_per_image():
    sensor = SplitterSensor("D")
    rgb = _scene()
    clean = simulate(sensor, rgb, "im", 0.0)
    toy = UniformNoise(20.0)
    noisy = simulate(sensor, rgb, "im", toy)
    assert torch.equal(noisy, simulate(sensor, rgb, "im", toy))
    assert not torch.equal(noisy, simulate(sensor, rgb, "other", toy))
    diff = (noisy - clean).double() * 255
    assert float(diff.abs().max()) <= 20.0 + 1e-3  # uniform on [-20, 20]
    assert abs(float(diff.var()) - 20.0**2 / 3) < 0.15 * 20.0**2 / 3


def test_the_lmmse_of_the_toy_is_the_lmmse_of_gaussian_noise_of_equal_variance():
    toy = UniformNoise(12.0)
    equal = Gaussian(12.0 / math.sqrt(3.0))
    raw = simulate(SplitterSensor("bayer"), _scene(), "im", toy)
    lmmse = build_method("lmmse", pattern="bayer")
    ours, gaussian = lmmse.reconstruct(raw, toy), lmmse.reconstruct(raw, equal)
    assert torch.allclose(ours, gaussian, atol=1e-6)
    assert not torch.allclose(ours, lmmse.reconstruct(raw, 12.0), atol=1e-3)
    # The closed form from any kernels (model.md §6) likewise.
    kernels, statistics = pattern_pixel_kernels(patterns.get("bayer")), shipped_image_statistics()
    ours = lmmse_estimate(raw, kernels, toy, statistics)
    assert torch.allclose(ours, lmmse_estimate(raw, kernels, equal, statistics), atol=1e-6)


def test_networks_are_told_the_toys_standard_deviation():
    raw = torch.rand(2, 1, 8, 8)
    toy = UniformNoise(9.0)
    level = noise_level_map(raw, toy, (2, 2))
    assert level.shape == (2, 1, 4, 4)
    assert torch.allclose(level, torch.full_like(level, 9.0 / math.sqrt(3.0)))
    mixed = noise_level_map(raw, [toy, Gaussian(4.0)], (2, 2))
    assert torch.allclose(mixed[0], level[0]) and bool((mixed[1] == 4.0).all())


def test_evaluate_scores_and_labels_the_toy_level(tmp_path):
    images = [("s", [("odd", _scene(19, 23)[0]), ("even", _scene(16, 16)[0])])]
    method = build_method("lmmse", pattern="D")
    equal = 10.0 / math.sqrt(3.0)  # the Gaussian sigma of the toy's variance
    levels = [equal, UniformNoise(10.0)]
    rows = evaluate([method], images, levels, tmp_path, progress=False)
    assert sorted({r.level for r in rows}) == [f"{equal:g}", "U10"]
    # Same variance, same LMMSE: scores close to the Gaussian's on each image, not equal.
    by = {(r.image, r.level): r.psnr for r in rows}
    for image in ("odd", "even"):
        assert by[image, "U10"] != by[image, f"{equal:g}"]
        assert abs(by[image, "U10"] - by[image, f"{equal:g}"]) < 0.3
    # Written and read back with its label; resuming finds the rows done.
    assert sorted(r.level for r in read_rows(tmp_path / "per_image.csv")) == sorted(
        r.level for r in rows
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert "U10" in next(iter(summary.values()))["all"]
    assert "U10" in (tmp_path / "table.md").read_text()
    again = evaluate([method], images, levels, tmp_path, progress=False)
    assert [r.psnr for r in again] == [r.psnr for r in rows]


def test_labels_of_other_models_sort_after_the_built_in_ones():
    labels = ["U10", "N100", "15", "0"]
    assert sorted(labels, key=level_key) == ["0", "15", "N100", "U10"]
    assert level_heading("U10") == "U10"


def test_a_number_is_the_gaussian_model_and_bad_levels_are_refused():
    assert as_noise(15) == Gaussian(15.0) and as_noise(Gaussian(3.0)) == Gaussian(3.0)
    with pytest.raises(ValueError, match="sigma >= 0"):
        as_noise(-1.0)
    with pytest.raises(TypeError, match="expected sigma as a number"):
        as_noise("loud")


def test_a_results_file_from_before_the_noise_column_is_extended_not_corrupted(tmp_path):
    path = tmp_path / "per_image.csv"
    path.write_text(
        "method,pattern,dataset,image,sigma,psnr,ssim,ciede2000,photons,domain\n"
        "m,D,s,a,5,30.0,0.9,2.0,0,srgb\n",
        encoding="utf-8",
    )
    (row,) = read_rows(path)
    append_rows(path, [row.__class__("m", "D", "s", "b", 0.0, 31.0, 0.9, 2.0, noise="U3")])
    rows = read_rows(path)
    assert [(r.image, r.level) for r in rows] == [("a", "5"), ("b", "U3")]


def test_one_level_for_the_batch_gives_the_maps_of_one_per_image():
    """What training hands on (one level object per image, often all the same) gives the maps
    the levels give image by image, and Gaussian levels the map of their sigmas as a tensor."""
    raw = torch.rand(3, 1, 8, 12)
    same = [Exposure(50.0)] * 3
    per_image = torch.cat([noise_level_map(raw[i : i + 1], e, (2, 2)) for i, e in enumerate(same)])
    assert torch.equal(noise_level_map(raw, same, (2, 2)), per_image)
    sigmas = [Gaussian(3.0), Gaussian(17.0), Gaussian(3.0)]
    as_tensor = noise_level_map(raw, torch.tensor([3.0, 17.0, 3.0]), (2, 2))
    assert torch.equal(noise_level_map(raw, sigmas, (2, 2)), as_tensor)
    with pytest.raises(ValueError, match="expected 1 or 3 noise levels, got 2"):
        noise_level_map(raw, [Exposure(50.0)] * 2, (2, 2))


def test_a_batchs_levels_are_one_object_read_from_any_form():
    """NoiseLevels.of reads numbers, noise models, tensors and lists alike; what the LMMSE and
    the networks ask of a batch equals asking each level on its own."""
    from splitcam.physics.noise import Exposure, Gaussian, NoiseLevels

    assert NoiseLevels.of(5) == [Gaussian(5.0)]
    assert NoiseLevels.of(torch.tensor([3.0, 7.0])) == [Gaussian(3.0), Gaussian(7.0)]
    mixed = NoiseLevels.of([4.0, Exposure(50.0, read_noise=1.0)])
    assert NoiseLevels.of(mixed) is mixed and mixed.shared is None
    assert NoiseLevels.of([Gaussian(2.0)] * 3).shared == Gaussian(2.0)
    naive = [level.variance_coefficients() for level in mixed]
    assert mixed.variance_coefficients().tolist() == [list(c) for c in naive]
    cells = torch.rand(2, 4, 5, 6, generator=torch.Generator().manual_seed(0))
    per_image = torch.cat([lv.level_map(cells[i : i + 1]) for i, lv in enumerate(mixed)])
    torch.testing.assert_close(mixed.level_map(cells), per_image, rtol=0, atol=0)
    sigmas = NoiseLevels.of([1.0, 9.0])
    torch.testing.assert_close(
        sigmas.level_map(cells),
        torch.cat([Gaussian(s).level_map(cells[i : i + 1]) for i, s in enumerate((1.0, 9.0))]),
        rtol=0,
        atol=0,
    )
    with pytest.raises(ValueError, match="expected 1 or 3 noise levels, got 2"):
        mixed.for_batch(3)
    with pytest.raises(ValueError, match="one or more noise levels"):
        NoiseLevels.of([])
