"""Chroma augmentation and colour dead leaves (splitcam.data.colour), against per-pixel
references written out here, and their place in the patch sampler's random sequence."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from splitcam.data.colour import (
    COVERAGE,
    PERMUTATIONS,
    ColourMix,
    augment_chroma,
    chroma_detail,
    dead_leaves,
    disc_count,
    opponent_to_rgb,
    power_law_radii,
    rgb_to_opponent,
    swap_chroma,
)
from splitcam.data.patches import ImageCache, PatchSampler
from splitcam.physics.light import linear_to_srgb, srgb_to_linear


def _naive_ycc(r: float, g: float, b: float) -> tuple[float, float, float]:
    """BT.601 luma and colour differences of one pixel, as the standard writes them."""
    y = 0.299 * r + 0.587 * g + 0.114 * b
    return y, (b - y) / 1.772, (r - y) / 1.402


def test_opponent_space_is_bt601_and_inverts() -> None:
    rgb = torch.rand(2, 3, 5, 4, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    ycc = rgb_to_opponent(rgb)
    for b, i, j in [(0, 0, 0), (1, 4, 3), (0, 2, 1)]:
        expected = _naive_ycc(*rgb[b, :, i, j].tolist())
        assert ycc[b, :, i, j].tolist() == pytest.approx(expected, abs=1e-12)
    torch.testing.assert_close(opponent_to_rgb(ycc), rgb, rtol=0, atol=1e-12)


def test_chroma_rotated_and_scaled_luma_kept_per_pixel() -> None:
    """Against the rotation written per pixel, on colours near grey so nothing is clipped."""
    gen = torch.Generator().manual_seed(1)
    rgb = 0.5 + 0.08 * (torch.rand(3, 3, 6, 7, generator=gen, dtype=torch.float64) - 0.5)
    angle = torch.tensor([0.3, 2.0, -1.1], dtype=torch.float64)
    scale = torch.tensor([1.0, 1.7, 2.2], dtype=torch.float64)
    out = augment_chroma(rgb, angle, scale, torch.zeros(3, dtype=torch.long))
    for b in range(3):
        for i, j in [(0, 0), (5, 6), (3, 2)]:
            y, cb, cr = _naive_ycc(*rgb[b, :, i, j].tolist())
            c, s, k = math.cos(angle[b]), math.sin(angle[b]), float(scale[b])
            cb2, cr2 = k * (c * cb - s * cr), k * (s * cb + c * cr)
            r2, b2 = y + 1.402 * cr2, y + 1.772 * cb2
            g2 = (y - 0.299 * r2 - 0.114 * b2) / 0.587
            assert out[b, :, i, j].tolist() == pytest.approx([r2, g2, b2], abs=1e-12)
    torch.testing.assert_close(rgb_to_opponent(out)[:, 0], rgb_to_opponent(rgb)[:, 0])


def test_identity_and_channel_orders() -> None:
    rgb = torch.rand(6, 3, 4, 5, generator=torch.Generator().manual_seed(2))
    zero = torch.zeros(6)
    same = augment_chroma(rgb, zero, torch.ones(6), torch.zeros(6, dtype=torch.long))
    torch.testing.assert_close(same, rgb, rtol=0, atol=2e-6)
    orders = torch.arange(6)
    out = augment_chroma(rgb, zero, torch.ones(6), orders)
    for k, perm in enumerate(PERMUTATIONS):
        torch.testing.assert_close(out[k], rgb[k, list(perm)], rtol=0, atol=2e-6)


def test_swap_keeps_luma_and_takes_the_next_patch_s_chroma() -> None:
    """Per pixel, against the opponent transform written out: a hit patch's luma is its own,
    its colour differences the next patch's times the scale; others are untouched."""
    gen = torch.Generator().manual_seed(4)
    rgb = 0.5 + 0.1 * (torch.rand(3, 3, 5, 6, generator=gen, dtype=torch.float64) - 0.5)
    hit = torch.tensor([True, False, True])
    scale = torch.tensor([1.5, 2.0, 1.2], dtype=torch.float64)
    out = swap_chroma(rgb, hit, scale)
    assert torch.equal(out[1], rgb[1])
    for b, donor in ((0, 1), (2, 0)):
        for i, j in [(0, 0), (4, 5), (2, 3)]:
            y, _, _ = _naive_ycc(*rgb[b, :, i, j].tolist())
            _, cb, cr = _naive_ycc(*rgb[donor, :, i, j].tolist())
            k = float(scale[b])
            r2, b2 = y + 1.402 * k * cr, y + 1.772 * k * cb
            g2 = (y - 0.299 * r2 - 0.114 * b2) / 0.587
            assert out[b, :, i, j].tolist() == pytest.approx([r2, g2, b2], abs=1e-12)


def test_saturation_pushed_out_is_clipped_to_the_gamut() -> None:
    rgb = torch.tensor([0.9, 0.2, 0.1]).view(1, 3, 1, 1).expand(1, 3, 2, 2)
    out = augment_chroma(rgb, torch.zeros(1), torch.tensor([3.0]), torch.zeros(1, dtype=torch.long))
    assert float(out.min()) == 0.0 and float(out.max()) == 1.0
    # Chroma grew: the spread between channels is wider than before.
    assert float(out.amax(1).min() - out.amin(1).max()) > 0.8


def _naive_leaves(colours, centres, radii, h, w) -> np.ndarray:
    """Painter's algorithm pixel by pixel: background, then each disc blended over it by its
    antialiased coverage."""
    image = np.zeros((3, h, w))
    for i in range(h):
        for j in range(w):
            value = np.array(colours[0], dtype=float)
            for k in range(1, len(colours)):
                d = math.hypot(i - centres[k][0], j - centres[k][1])
                cover = min(max(radii[k] - d + 0.5, 0.0), 1.0)
                value = value + cover * (np.array(colours[k]) - value)
            image[:, i, j] = value
    return image


def test_dead_leaves_paints_discs_back_to_front() -> None:
    colours = [[0.1, 0.2, 0.3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5], [0.2, 0.2, 0.9]]
    centres = [[0, 0], [3.0, 4.0], [5.5, 2.0], [4.0, 4.2]]
    radii = [0, 3.0, 2.2, 1.3]
    out = dead_leaves(
        torch.tensor([colours], dtype=torch.float64),
        torch.tensor([centres], dtype=torch.float64),
        torch.tensor([radii], dtype=torch.float64),
        (9, 7),
    )
    np.testing.assert_allclose(out[0].numpy(), _naive_leaves(colours, centres, radii, 9, 7))


def test_radii_follow_r_minus_3_and_discs_cover_the_patch() -> None:
    gen = torch.Generator().manual_seed(3)
    radii = power_law_radii(torch.rand(200_000, generator=gen, dtype=torch.float64), 1.5, 32.0)
    assert float(radii.min()) >= 1.5 and float(radii.max()) <= 32.0
    # Distribution function of density ~ r^-3 on [a, b]: (a^-2 - r^-2) / (a^-2 - b^-2).
    for r in (2.0, 4.0, 10.0):
        expected = (1.5**-2 - r**-2) / (1.5**-2 - 32.0**-2)
        assert float((radii <= r).double().mean()) == pytest.approx(expected, abs=0.005)
    # Areas summing to COVERAGE times the patch leave about exp(-COVERAGE) of it uncovered
    # (discs straddling the edge lose part of their area, so a little more is left).
    h = w = 64
    k = disc_count(h, w)
    centres = torch.rand((40, k, 2), generator=gen) * h
    radii = power_law_radii(torch.rand((40, k), generator=gen), 1.5, h / 2)
    rows = torch.arange(h).view(1, 1, h, 1).float()
    cols = torch.arange(w).view(1, 1, 1, w).float()
    dy, dx = rows - centres[..., 0, None, None], cols - centres[..., 1, None, None]
    d = (dy**2 + dx**2).sqrt()
    uncovered = float((d > radii[..., None, None]).all(1).float().mean())
    assert math.exp(-COVERAGE) * 0.8 < uncovered < math.exp(-COVERAGE) * 2.5


def test_mix_draws_a_fixed_number_per_batch() -> None:
    """How many patches a mix changes does not move the generator: the batches after it are
    the same whatever was hit."""
    batch = torch.rand(8, 3, 16, 16)
    states = []
    for p in (0.01, 0.99):
        gen = torch.Generator().manual_seed(5)
        ColourMix(chroma=p, leaves=p, swap=p)(batch, gen)
        states.append(gen.get_state())
    assert torch.equal(*states)


def test_mix_in_linear_light() -> None:
    batch = torch.rand(4, 3, 8, 8, generator=torch.Generator().manual_seed(6))
    srgb_out = ColourMix(chroma=1.0)(batch, torch.Generator().manual_seed(7))
    linear_out = ColourMix(chroma=1.0, space="linear")(batch, torch.Generator().manual_seed(7))
    # The same draws, applied to the radiance and encoded back.
    gen = torch.Generator().manual_seed(7)
    torch.rand(4, generator=gen)  # which patches (all, at probability 1)
    angle = torch.rand(4, generator=gen) * (2 * math.pi)
    scale = 1 + torch.rand(4, generator=gen) * 1.2
    order = torch.randint(6, (4,), generator=gen)
    expected = linear_to_srgb(augment_chroma(srgb_to_linear(batch), angle, scale, order))
    torch.testing.assert_close(linear_out, expected.clamp(0, 1))
    torch.testing.assert_close(srgb_out, augment_chroma(batch, angle, scale, order))
    assert not torch.allclose(linear_out, srgb_out)
    # Patches no lever touched come back bit for bit (no decode-encode round trip on them).
    partly = ColourMix(chroma=0.5, space="linear")(batch, torch.Generator().manual_seed(8))
    hit = torch.rand(4, generator=torch.Generator().manual_seed(8)) < 0.5
    assert 0 < int(hit.sum()) < 4
    for k in range(4):
        assert torch.equal(partly[k], batch[k]) != bool(hit[k])


def test_bad_settings_refused() -> None:
    for kwargs, message in [
        ({"chroma": 1.5}, "chroma must be a probability"),
        ({"leaves": -0.1}, "leaves must be a probability"),
        ({"swap": 2.0}, "swap must be a probability"),
        ({"chroma_max": 0.5}, "chroma_max must be >= 1"),
        ({"space": "xyz"}, "space must be"),
    ]:
        with pytest.raises(ValueError, match=message):
            ColourMix(**kwargs)


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> ImageCache:
    from PIL import Image

    folder = tmp_path_factory.mktemp("imgs")
    rng = np.random.default_rng(0)
    for i in range(3):
        Image.fromarray(rng.integers(0, 256, (40, 37, 3), dtype=np.uint8)).save(folder / f"{i}.png")
    return ImageCache(folder, min_size=16, progress=False)


def test_sampler_with_colour_resumes_and_inactive_changes_nothing(cache) -> None:
    settings = {"patch_size": 16, "seed": 3, "partial": 0.5, "period": (2, 2)}
    plain = PatchSampler(cache, **settings)
    inactive = PatchSampler(cache, **settings, colour=ColourMix())
    for _ in range(3):
        assert torch.equal(plain.sample(5), inactive.sample(5))
    mixed = PatchSampler(cache, **settings, colour=ColourMix(chroma=0.5, leaves=0.5))
    mixed.sample(5)
    state = mixed.state_dict()
    ahead = [mixed.sample(5) for _ in range(2)]
    again = PatchSampler(cache, **settings, colour=ColourMix(chroma=0.5, leaves=0.5))
    again.load_state_dict(state)
    for expected in ahead:
        assert torch.equal(again.sample(5), expected)
    # The mix changed some patches and kept the batch's shape and range.
    base = PatchSampler(cache, **settings)
    base.load_state_dict(state)
    got = base.sample(5)
    assert got.shape == ahead[0].shape and not torch.equal(got, ahead[0])
    assert float(ahead[0].min()) >= 0 and float(ahead[0].max()) <= 1


def test_chroma_moved_copies_move_colour_not_grey_and_draw_in_order():
    from splitcam.data.colour import chroma_moved_copies

    g = torch.Generator().manual_seed(3)
    grey = torch.rand(1, 9, 11, generator=g).expand(3, 9, 11).clone()
    colour = torch.rand(3, 8, 13, generator=g)
    copies = chroma_moved_copies([grey, colour], torch.Generator().manual_seed(0))
    torch.testing.assert_close(copies[0], grey, rtol=0, atol=1e-6)  # no chroma to move
    assert copies[1].shape == colour.shape and 0 <= copies[1].min() <= copies[1].max() <= 1
    assert (copies[1] - colour).abs().max() > 0.05
    one = torch.Generator().manual_seed(0)  # one image at a time on one generator: the same
    alone = [chroma_moved_copies([x], one)[0] for x in (grey, colour)]
    torch.testing.assert_close(alone[1], copies[1], rtol=0, atol=0)


def _naive_chroma_detail(rgb: np.ndarray) -> float:
    """The detail energies block by block, pixel by pixel, with the standard's colour
    differences (a trailing odd row or column left out)."""
    height, width = rgb.shape[1] // 2 * 2, rgb.shape[2] // 2 * 2
    energy = np.zeros(3)
    for i in range(0, height, 2):
        for j in range(0, width, 2):
            block = [_naive_ycc(*rgb[:, i + a, j + b]) for a in (0, 1) for b in (0, 1)]
            mean = np.mean(block, axis=0)
            energy += np.sum((np.array(block) - mean) ** 2, axis=0)
    return (energy[1] + energy[2]) / energy[0]


def test_chroma_detail_matches_a_block_by_block_reference_on_odd_sides():
    rgb = np.random.default_rng(3).random((3, 9, 7))
    got = chroma_detail(torch.from_numpy(rgb))
    assert got == pytest.approx(_naive_chroma_detail(rgb), rel=1e-10)


def test_chroma_detail_of_grey_flat_and_colour_only_images():
    grey = torch.rand(1, 6, 8, generator=torch.Generator().manual_seed(0)).expand(3, 6, 8)
    assert chroma_detail(grey) == pytest.approx(0.0, abs=1e-20)
    assert chroma_detail(torch.full((3, 4, 4), 0.5)) == 0.0
    stripes = 0.1 * (-1.0) ** torch.arange(4.0)  # Cb alternating along each row, luma flat
    ycc = torch.stack([torch.full((4, 4), 0.5), stripes.expand(4, 4), torch.zeros(4, 4)])
    assert chroma_detail(opponent_to_rgb(ycc)) > 1e10
    with pytest.raises(ValueError, match="at least 2x2"):
        chroma_detail(torch.rand(3, 1, 5))


def test_a_jpeg_with_half_resolution_chroma_loses_its_colour_detail(tmp_path):
    """The property the training photos show: 4:2:0 JPEG keeps the luma's detail and drops the
    chroma's, where 4:4:4 at the same quality keeps both."""
    from PIL import Image

    rng = np.random.default_rng(0)
    colours = rng.integers(0, 256, (12, 12, 3), dtype=np.uint8)
    image = np.kron(colours, np.ones((3, 3, 1), dtype=np.uint8))  # colour edges every 3 pixels
    ratios = {}
    for sampling in (0, 2):
        path = tmp_path / f"s{sampling}.jpg"
        Image.fromarray(image).save(path, quality=95, subsampling=sampling)
        back = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255
        ratios[sampling] = chroma_detail(torch.from_numpy(back).permute(2, 0, 1))
    original = chroma_detail(torch.from_numpy(image / 255.0).permute(2, 0, 1))
    assert ratios[0] == pytest.approx(original, rel=0.1)
    assert ratios[2] < 0.5 * ratios[0]
