"""Lux and the photon model's exposure N (splitcam.physics.radiometry): the definition of the
lumen at 555 nm, the camera equation's scaling, the quantum efficiency, and refusals."""

from __future__ import annotations

import pytest

from splitcam.physics.radiometry import Camera, photons_per_lux

H, C = 6.62607015e-34, 2.99792458e8


def test_one_lux_of_555_nm_light_is_the_lumens_definition():
    """1 lx of 555 nm light is 1/683 W/m², i.e. (1/683) / (h c / 555 nm) photons/(s m²)."""
    spike = ([554.0, 555.0, 556.0], [0.0, 1.0, 0.0])
    assert photons_per_lux(spike) == pytest.approx(555e-9 / (H * C) / 683.0, rel=1e-4)
    # outside the band the sensor model counts, the same light gives no photo-electrons
    assert photons_per_lux(spike, band=(600.0, 700.0)) == 0.0


def test_the_camera_equation_scales_as_it_should():
    base = Camera(pitch_um=1.0, f_number=2.0, exposure_s=1 / 30)
    n = base.electrons_per_lux
    assert n == pytest.approx(photons_per_lux("D65") / 16 * 1e-12 / 30)
    assert Camera(pitch_um=2.0).electrons_per_lux == pytest.approx(4 * n)
    assert Camera(f_number=4.0).electrons_per_lux == pytest.approx(n / 4)
    assert Camera(exposure_s=1 / 60).electrons_per_lux == pytest.approx(n / 2)
    assert Camera(reflectance=0.18).electrons_per_lux == pytest.approx(0.18 * n)
    assert base.lux(base.photons(37.0)) == pytest.approx(37.0)
    half = Camera(qe=([380.0, 780.0], [0.5, 0.5]))
    assert half.electrons_per_lux == pytest.approx(n / 2)
    assert base.describe() == "pitch 1 µm, f/2, 1/30 s, D65, white scene, lossless pixel"


def test_illuminants_differ_in_photons_per_lux():
    """Tungsten light has more red, where the eye is less sensitive: more photons per lux than
    daylight; the three are within a factor of two of each other."""
    d65, a, led = (photons_per_lux(i) for i in ("D65", "A", "LED"))
    assert a > d65
    assert max(d65, a, led) / min(d65, a, led) < 2


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"illuminant": "F2"}, "unknown illuminant 'F2'; expected one of D65, A, LED"),
        ({"pitch_um": 0}, "pitch_um must be > 0"),
        ({"f_number": -2}, "f_number must be > 0"),
        ({"reflectance": 1.5}, "reflectance must be in"),
        ({"qe": ([450.0, 650.0], [0.5, 0.5])}, "must cover 400-700 nm"),
        ({"qe": ([380.0, 780.0], [0.5, 1.2])}, r"within \[0, 1\]"),
    ],
)
def test_bad_settings_are_refused_in_one_line(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Camera(**kwargs)


def test_silicon_absorbs_less_of_the_red_within_a_shallow_photodiode():
    """QE = 1 - exp(-4 pi k d / lambda) from Green 2008's k (at 700 nm, k = 0.010528): checked
    by hand; falling from blue to red, rising with depth; a camera with it collects less."""
    import math

    from splitcam.physics.radiometry import SiliconQE

    qe = SiliconQE(3.0)
    assert float(qe(700.0)) == pytest.approx(1 - math.exp(-4 * math.pi * 0.010528 * 3.0 / 0.7))
    values = qe([450.0, 500.0, 550.0, 600.0, 650.0, 700.0])
    assert all(a > b for a, b in zip(values, values[1:], strict=False))
    assert float(SiliconQE(6.0)(650.0)) > float(qe(650.0))
    with_si = Camera(qe=qe)
    assert 0.5 < with_si.electrons_per_lux / Camera().electrons_per_lux < 1.0
    assert with_si.describe().endswith("QE of silicon 3 µm deep")
    with pytest.raises(ValueError, match="depth must be > 0"):
        SiliconQE(0.0)
