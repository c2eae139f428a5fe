"""Scalar wave optics from a metasurface height map to splitter kernels (physics.optics)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from splitcam.cli import main
from splitcam.physics.optics import Optics, flat_profile, kernels_of, lens_profile, pattern_of
from splitcam.physics.sensor import SplitterSensor


def _random_height(shape, seed=0, h=1.0):
    return torch.rand(shape, generator=torch.Generator().manual_seed(seed), dtype=torch.float64) * h


def test_distance_zero_gives_identity_kernels() -> None:
    optics = Optics(distance=0.0)
    k = kernels_of(_random_height((16, 16)), (2, 2), optics)
    expected = torch.zeros_like(k)
    expected[:, :, 1, 1] = 1.0
    torch.testing.assert_close(k, expected, rtol=0, atol=1e-12)


def test_collected_light_never_exceeds_the_incident_and_equals_the_propagating_part() -> None:
    """Over the whole window (no guard, kernel = window) the light collected equals the share of
    the aperture field's angular spectrum that propagates (Parseval), never more than 1."""
    wavelength = 600.0
    optics = Optics(
        distance=3.0, wavelengths=[wavelength], spectra=np.ones((3, 1)), kernel_size=(7, 7), guard=0
    )
    k = kernels_of(flat_profile((1, 1), optics), (1, 1), optics)
    total = float(k[0, 0].sum())
    q, size = optics.samples, 7 * optics.samples
    field = np.zeros((size, size))
    field[3 * q : 4 * q, 3 * q : 4 * q] = 1.0
    spectrum = np.abs(np.fft.fft2(field)) ** 2
    f = np.fft.fftfreq(size, d=optics.pitch / q)
    propagating = (f[:, None] ** 2 + f[None, :] ** 2) < (1 / (wavelength * 1e-3)) ** 2
    assert total == pytest.approx(spectrum[propagating].sum() / spectrum.sum(), abs=5e-3)
    assert total <= 1.0
    for seed in range(3):
        ks = kernels_of(_random_height((16, 16), seed), (2, 2), Optics())
        assert float(ks.sum((2, 3)).max()) <= 1.0 + 1e-12 and float(ks.min()) >= 0


def test_a_lens_focuses_its_light_onto_its_own_pixel() -> None:
    optics = Optics(
        pitch=2.0,
        distance=4.0,
        samples=16,
        wavelengths=[540.0],
        spectra=np.ones((3, 1)),
        guard=3,
    )
    lens = kernels_of(lens_profile((1, 1), optics, 540.0), (1, 1), optics)[0, 1]
    flat = kernels_of(flat_profile((1, 1), optics), (1, 1), optics)[0, 1]
    assert float(lens[1, 1]) > 0.75 and float(lens[1, 1]) > float(flat[1, 1]) + 0.1  # 0.80, 0.66


def test_mirror_symmetric_profiles_give_mirror_symmetric_kernels() -> None:
    h = _random_height((8, 8), 4)
    h = 0.5 * (h + h.flip(-1))
    k = kernels_of(h, (1, 1), Optics())
    torch.testing.assert_close(k, k.flip(-1), rtol=0, atol=1e-12)


def test_gradients_match_finite_differences() -> None:
    optics = Optics(
        pitch=0.5,
        samples=4,
        distance=0.8,
        wavelengths=[450.0, 600.0],
        spectra=np.ones((3, 2)),
        guard=1,
    )
    h = (_random_height((4, 4), 5) * 0.8 + 0.1).requires_grad_(True)
    weights = torch.rand(
        1, 3, 3, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64
    )
    assert torch.autograd.gradcheck(
        lambda x: (kernels_of(x, (1, 1), optics) * weights).sum(), (h,), eps=1e-6, atol=1e-6
    )


def test_the_result_is_a_pattern_the_sensor_uses() -> None:
    pattern = pattern_of(lens_profile((2, 2), Optics()), (2, 2), Optics(), name="lenses")
    assert pattern.period == (2, 2) and pattern.kernels.shape == (4, 3, 3, 3)
    raw = SplitterSensor(pattern)(torch.ones(1, 3, 8, 8))
    assert float(raw.max()) <= 3.0 + 1e-6  # at most all light of a white pixel


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"distance": -1.0}, "distance"),
        ({"pitch": 0.0}, "pitch"),
        ({"index": 0.5}, "indices"),
        ({"samples": 2}, "grid too coarse"),
        ({"kernel_size": (2, 3)}, "odd"),
    ],
)
def test_bad_parameters_get_clear_errors(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        Optics(**kwargs)
    with pytest.raises(ValueError, match="height map of shape"):
        kernels_of(torch.zeros(5, 5, dtype=torch.float64), (1, 1), Optics())


def test_bayer_collection_of_known_patterns() -> None:
    """A colour filter keeps 1/4 of red and blue and 1/2 of green; pattern A routes every colour
    to its pixels (a perfect router)."""
    from splitcam import patterns
    from splitcam.physics.optics import bayer_collection

    assert bayer_collection(patterns.get("bayer")) == pytest.approx([0.25, 0.5, 0.25])
    assert bayer_collection(patterns.get("A")) == pytest.approx([1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="2x2"):
        bayer_collection(patterns.get("E"))


def test_profiles_by_name_or_file_and_their_errors(tmp_path) -> None:
    from splitcam.physics.optics import profile

    optics = Optics()
    rand = profile("random", (2, 2), optics, seed=3)
    assert rand.shape == (16, 16) and 0 <= float(rand.min()) and float(rand.max()) <= 1.2
    assert torch.equal(rand, profile("random", (2, 2), optics, seed=3))
    np.save(tmp_path / "h.npy", rand.numpy())
    assert torch.equal(profile(str(tmp_path / "h.npy"), (2, 2), optics), rand)
    torch.testing.assert_close(profile("lens", (2, 2), optics), lens_profile((2, 2), optics))
    with pytest.raises(ValueError, match="shape"):
        profile(str(tmp_path / "h.npy"), (1, 1), optics)
    with pytest.raises(ValueError, match="cannot read"):
        profile(str(tmp_path / "missing.npy"), (2, 2), optics)


def test_rggb_collection_is_the_sum_over_the_rggb_targets_and_differentiable() -> None:
    """The tensor form equals a direct count on a random 2x2 pattern (every kernel entry whose
    landing pixel has the entry's colour in RGGB, a quarter per site), and its gradient reaches
    exactly those entries."""
    from splitcam.physics.optics import rggb_collection

    gen = torch.Generator().manual_seed(0)
    kernels = torch.rand(4, 3, 3, 3, generator=gen, dtype=torch.float64).requires_grad_(True)
    layout = [[0, 1], [2, 3]]
    colour = [["R", "G"], ["G", "B"]]  # RGGB, R at (0, 0)
    want = [0.0, 0.0, 0.0]
    for i in range(2):
        for j in range(2):
            for a in range(3):
                for b in range(3):
                    target = colour[(i + a - 1) % 2][(j + b - 1) % 2]
                    c = "RGB".index(target)
                    want[c] += float(kernels.detach()[layout[i][j], c, a, b]) / 4
    eff = rggb_collection(kernels, layout)
    np.testing.assert_allclose(eff.detach().numpy(), want, rtol=1e-12)
    eff.sum().backward()
    # each (site, colour, a, b) entry counts once, for its own colour only
    assert torch.all((kernels.grad == 0) | (kernels.grad == 0.25))
    assert int((kernels.grad > 0).sum()) == 4 * 9  # one colour per landing pixel


def test_optics_refuse_a_pillar_index_equal_to_the_spacer_and_negative_heights(tmp_path, capsys):
    from splitcam.physics.optics import Optics

    with pytest.raises(ValueError, match="above the spacer"):
        Optics(index=1.0)  # was a ZeroDivisionError in the lens profile
    height = tmp_path / "h.npy"
    np.save(height, -np.ones((2 * 8, 2 * 8)))
    args = ["optics", "--profile", str(height), "--samples", "8", "--out", str(tmp_path / "p.toml")]
    assert main(args) == 1
    assert "heights must lie in [0," in capsys.readouterr().err
