"""Spectral patterns (splitcam.patterns.spectral): the reduction to RGB kernels against a
simulation wavelength by wavelength, light conservation, and refusals."""

from __future__ import annotations

import numpy as np
import pytest
import tomllib
import torch

from splitcam import patterns
from splitcam.patterns import PatternError
from splitcam.patterns.spectral import SpectralPattern, scene_basis
from splitcam.physics.sensor import SplitterSensor

GRID = np.arange(400.0, 701.0, 10.0)


def _scatter(layout: np.ndarray, kernels: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Naive Eq. 1 for one band: every pixel ``q`` sends ``light[q] * kernels[s(q)][a, b]`` to
    ``q + (a - kh // 2, b - kw // 2)``; light sent off the image is dropped."""
    h, w = light.shape
    ph, pw = layout.shape
    _, kh, kw = kernels.shape
    raw = np.zeros((h, w))
    for y in range(h):
        for x in range(w):
            k = kernels[layout[y % ph, x % pw]]
            for a in range(kh):
                for b in range(kw):
                    ty, tx = y + a - kh // 2, x + b - kw // 2
                    if 0 <= ty < h and 0 <= tx < w:
                        raw[ty, tx] += light[y, x] * k[a, b]
    return raw


def _spectral_raw(sp: SpectralPattern, rgb: np.ndarray) -> np.ndarray:
    """The scene as spectra (S = sum_c rgb_c E_c), simulated wavelength by wavelength."""
    cube = np.einsum("lc,chw->lhw", scene_basis(sp.wavelengths), rgb)
    return sum(_scatter(sp.layout, sp.kernels[:, i], cube[i]) for i in range(len(cube)))


def test_the_reduction_is_exact_for_scenes_linear_in_srgb():
    rng = np.random.default_rng(0)
    layout = np.array([[0, 1, 2], [2, 0, 1]])
    kernels = rng.random((3, len(GRID), 3, 5))
    kernels /= kernels.sum(axis=(2, 3), keepdims=True) * rng.uniform(1.0, 1.5, (3, len(GRID), 1, 1))
    sp = SpectralPattern("mine", layout, GRID, kernels)
    rgb = rng.random((3, 13, 17))
    expect = _spectral_raw(sp, rgb)
    sensor = SplitterSensor(sp.to_pattern())
    got = sensor(torch.from_numpy(rgb)[None])[0, 0].numpy()
    r = 2  # the sensor's border convention aside: compare where every source is inside
    np.testing.assert_allclose(got[r:-r, r:-r], expect[r:-r, r:-r], rtol=0, atol=1e-6)
    assert np.abs(expect).max() > 0.5


def test_the_basis_is_one_unit_of_light_per_colour():
    e = scene_basis(GRID)
    np.testing.assert_allclose(e.sum(axis=0), 1.0)
    # Blue light lies at short wavelengths, red at long ones.
    peaks = GRID[e.argmax(axis=0)]
    assert peaks[2] < peaks[1] < peaks[0]
    # A bare pixel (all light of every wavelength kept) is a pixel with no filter.
    bare = SpectralPattern("bare", [[0]], GRID, np.ones((1, len(GRID), 1, 1))).to_pattern()
    np.testing.assert_allclose(bare.kernels.ravel(), [1.0, 1.0, 1.0])


def test_period_totals_conserve_light_under_uniform_illumination():
    rng = np.random.default_rng(1)
    for period in [(2, 2), (3, 3), (1, 4)]:
        t = rng.random((*period, len(GRID)))
        t *= 0.9 / t.sum(axis=(0, 1))  # 90 % of each wavelength reaches the pixels
        sp = SpectralPattern.from_transmission("router", GRID, t)
        ph, pw = period
        my, mx = 2 * ph, 2 * pw  # margins of whole periods, wider than the kernels' reach
        light = np.ones((4 * ph + 2 * my, 4 * pw + 2 * mx))
        for i in (0, 15, 30):
            raw = _scatter(sp.layout, sp.kernels[:, i], light)
            inner = raw[my : my + 4 * ph, mx : mx + 4 * pw]
            expect = np.tile(t[:, :, i] * ph * pw, (4, 4))
            np.testing.assert_allclose(inner, expect, atol=1e-12)


def test_an_ideal_filter_array_reduces_to_colour_shares():
    """Box filters passing 600-700, 500-590 and 400-490 nm on an RGGB array: under uniform
    light of one colour, the red pixel records that colour's photons in the red band, whether
    the array is given filter by filter (1x1 kernels) or by the period's totals."""
    e = scene_basis(GRID)
    bands = [GRID >= 600, (GRID >= 500) & (GRID < 600), GRID < 500]  # R, G, B passbands
    colour_of = {(0, 0): 0, (0, 1): 1, (1, 0): 1, (1, 1): 2}
    filters = np.zeros((4, len(GRID), 1, 1))
    t = np.zeros((2, 2, len(GRID)))
    for (i, j), c in colour_of.items():
        filters[2 * i + j, bands[c]] = 1.0
        t[i, j, bands[c]] = 0.25  # a filter keeps its own pixel's light: 1/4 of the period's
    layout = np.arange(4).reshape(2, 2)
    for sp in (
        SpectralPattern("filters", layout, GRID, filters),
        SpectralPattern.from_transmission("totals", GRID, t),
    ):
        sensor = SplitterSensor(sp.to_pattern())
        for c in range(3):
            light = torch.zeros(1, 3, 8, 8, dtype=torch.float64)
            light[:, c] = 1.0
            raw = sensor(light)[0, 0]
            assert float(raw[4, 4]) == pytest.approx(e[bands[0], c].sum(), abs=1e-12)
    assert e[bands[0], 0].sum() > 0.8 and e[bands[0], 2].sum() < 0.1


def test_pattern_files_with_wavelengths_are_spectral(tmp_path):
    path = tmp_path / "spec.toml"
    t = np.full((2, 2, 3), 0.2)
    rows = ", ".join(
        "[" + ", ".join(f"[{', '.join(map(str, px))}]" for px in row) + "]" for row in t
    )
    path.write_text(f'name = "s"\nwavelengths = [450, 550, 650]\ntransmission = [{rows}]\n')
    pattern = patterns.load(path)
    assert pattern.period == (2, 2) and pattern.metadata["spectral"]["wavelengths"][0] == 450


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"wavelengths": [350, 450, 550]}, "outside 380-780"),
        ({"wavelengths": [450, 450, 550]}, "increase"),
        ({"transmission": np.full((2, 2, 3), 0.3).tolist()}, "1.2 of the light at 450 nm"),
        ({"transmission": np.full((2, 2, 2), 0.1).tolist()}, "3 wavelengths"),
        ({"layout": [[0]]}, "either transmission"),
    ],
)
def test_bad_spectral_patterns_are_refused(change, message):
    data = {
        "name": "s",
        "wavelengths": [450, 550, 650],
        "transmission": np.full((2, 2, 3), 0.2).tolist(),
    }
    data.update(change)
    with pytest.raises(PatternError, match=message):
        SpectralPattern.from_dict(data)


def test_a_router_s_spectra_written_as_a_file_read_back_as_the_same_pattern(tmp_path):
    """save_transmission: the file reads back as from_transmission's pattern (to the file's 6
    decimals); spectra that create light are refused and nothing is written; spectra that
    carry all the light but for a millionth are written so that rounding creates none (to six
    significant digits, 0.33333351 + 0.33333351 + 0.2 + 0.13333297 read back as 1.000001)."""
    from splitcam.patterns.files import save_transmission

    lams = np.arange(400.0, 701.0, 20.0)
    rng = np.random.default_rng(2)
    t = rng.uniform(0.0, 1.0, (2, 2, lams.size))
    t *= 0.97 / t.sum(axis=(0, 1), keepdims=True)  # 3 % reflected at every wavelength
    path = save_transmission(tmp_path / "mine.toml", "mine", lams, t, provenance="test")
    read = patterns.get(str(path))
    direct = SpectralPattern.from_transmission("mine", lams, t).to_pattern()
    assert read.name == "mine" and read.provenance == "test"
    assert np.allclose(read.kernels, direct.kernels, atol=1e-5)
    with pytest.raises(PatternError):
        save_transmission(tmp_path / "bright.toml", "bright", lams, t * 1.1)
    assert not (tmp_path / "bright.toml").exists()
    full = np.zeros((2, 2, 1))
    full[:, :, 0] = [[0.33333351, 0.33333351], [0.2, 0.13333297]]  # 0.99999999 in all
    path = save_transmission(tmp_path / "full.toml", "full", [550.0], full)
    written = np.asarray(tomllib.loads(path.read_text())["transmission"])
    assert written.sum() <= 1.0 and written.sum() == pytest.approx(1.0, abs=4e-6)


def test_a_sensor_s_kernels_written_as_a_file_read_back_as_the_same_pattern(tmp_path):
    """save_spectral_kernels: the file reads back as the pattern written (to its 6 decimals),
    kernels that sum to exactly 1 are not pushed above it by rounding, and kernels that create
    light are refused with nothing written."""
    from splitcam.patterns.files import save_spectral_kernels

    lams = np.arange(410.0, 691.0, 40.0)
    rng = np.random.default_rng(5)
    k = rng.uniform(0.0, 1.0, (4, lams.size, 5, 5)) ** 3
    k /= k.sum(axis=(-2, -1), keepdims=True)  # every kernel sums to 1 (lossless)
    k[1] *= 0.9
    path = save_spectral_kernels(
        tmp_path / "mine.json", "mine", lams, [[0, 1], [2, 3]], k, provenance="test"
    )
    read = patterns.get(str(path))
    direct = SpectralPattern("mine", [[0, 1], [2, 3]], lams, k).to_pattern()
    assert read.name == "mine" and read.provenance == "test"
    assert np.allclose(read.kernels, direct.kernels, atol=1e-5)
    with pytest.raises(PatternError, match="cannot create light"):
        save_spectral_kernels(tmp_path / "bright.json", "b", lams, [[0, 1], [2, 3]], k * 1.01)
    assert not (tmp_path / "bright.json").exists()


def test_band_efficiencies_as_the_leaderboard_scores_them():
    """Each band's mean share into its own pixels, the quadrants found by where the ends peak."""
    from splitcam.physics.fullwave import band_efficiencies

    lams = np.array([433.0, 467.0, 533.0, 567.0, 633.0, 667.0])
    t = np.full((2, 2, 6), 0.1)
    t[0, 0, :2] = [0.7, 0.6]  # blue pixel, row 0 column 0
    t[1, 1, 4:] = [0.5, 0.6]  # red pixel, row 1 column 1
    t[0, 1, 2:4] = [0.3, 0.25]
    t[1, 0, 2:4] = [0.3, 0.35]
    eff = band_efficiencies(t, lams)
    assert eff["quadrants"] == {"blue": 0, "red": 3}
    assert eff["blue"] == pytest.approx(0.65)
    assert eff["green"] == pytest.approx((0.6 + 0.6) / 2)
    assert eff["red"] == pytest.approx(0.55)
