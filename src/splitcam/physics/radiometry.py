"""Exposure in a designer's units: scene illuminance (lux) and the exposure ``N`` of the photon
model (model.md §11: the photo-electrons a lossless pixel without filter or router collects
from a white scene).

The camera equation: a Lambertian scene of reflectance ``R`` lit with illuminance ``E`` lux has
luminance ``R E / pi``; a lens of f-number ``F`` and transmission ``T`` images it on axis (a
distant scene; no cos^4 fall-off towards the corners) with illuminance

    E_image = R T E / (4 F^2).

Lux weigh light by the eye (683 lm/W times the CIE 1924 photopic efficiency ``V``); a pixel
counts photons. For an illuminant of spectrum ``S``, one lux is

    photons per second and square metre = sum_band S(l) l / (h c) / (683 sum S(l) V(l)),

the photons counted over the band the sensor model spans (400-700 nm: light outside it is not
in the model's units), each weighted by the pixel's quantum efficiency ``QE(l)`` (default 1,
the model's lossless pixel). A pixel of pitch ``p`` exposed ``t`` seconds then collects

    N = E_image * photons_per_lux * p^2 * t

photo-electrons. Illuminants (colour-science's tables): CIE D65 (daylight), CIE A (tungsten,
2856 K) and CIE LED-B3 (a phosphor-converted white LED, about 4100 K).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["ILLUMINANTS", "Camera", "SiliconQE", "photons_per_lux"]

#: Illuminant names and colour-science's table of each.
ILLUMINANTS = {"D65": "D65", "A": "A", "LED": "LED-B3"}
PLANCK = 6.62607015e-34  # J s
LIGHT = 2.99792458e8  # m / s
LUMENS_PER_WATT = 683.0
BAND = (400.0, 700.0)


#: Crystalline silicon's extinction coefficient ``k`` (band-to-band absorption, 300 K) at
#: 380-720 nm every 10 nm: M. A. Green, *Self-consistent optical parameters of intrinsic
#: silicon at 300 K including temperature coefficients*, Sol. Energ. Mat. Sol. Cells 92,
#: 1305-1310 (2008), as tabulated in the refractiveindex.info database (public domain, CC0).
SILICON_K = (
    9.4600e-01, 4.4500e-01, 2.9600e-01, 2.2700e-01, 1.7600e-01, 1.3800e-01, 1.0700e-01,
    8.6302e-02, 7.1381e-02, 6.2086e-02, 5.5004e-02, 4.9131e-02, 4.4165e-02, 3.9367e-02,
    3.6415e-02, 3.3108e-02, 3.0295e-02, 2.7968e-02, 2.5758e-02, 2.4131e-02, 2.2524e-02,
    2.1081e-02, 1.9934e-02, 1.8446e-02, 1.7367e-02, 1.6444e-02, 1.5432e-02, 1.4431e-02,
    1.3498e-02, 1.2743e-02, 1.1905e-02, 1.1201e-02, 1.0528e-02, 1.0057e-02, 9.6257e-03,
)  # fmt: skip
SILICON_NM = tuple(380.0 + 10.0 * i for i in range(len(SILICON_K)))


@dataclass(frozen=True)
class SiliconQE:
    """The quantum efficiency of a silicon photodiode ``depth_um`` deep: the share of the light
    entering it that silicon absorbs within that depth, ``1 - exp(-4 pi k depth / lambda)``
    (Green 2008's ``k``, :data:`SILICON_K`). Light reflected at its surface and carriers lost
    before collection are not modelled (an ideal anti-reflection stack and collection): the
    curve is an upper bound set by absorption alone, which is what makes a deep-red pixel weak.
    A callable of wavelengths (nm), as :class:`Camera` takes for ``qe``."""

    depth_um: float = 3.0

    def __post_init__(self) -> None:
        if not self.depth_um > 0:
            raise ValueError(f"the photodiode depth must be > 0 µm, got {self.depth_um}")

    def __call__(self, nm: Any) -> np.ndarray:
        nm = np.asarray(nm, dtype=float)
        k = np.interp(nm, SILICON_NM, SILICON_K)
        return 1.0 - np.exp(-4.0 * np.pi * k * self.depth_um / (nm * 1e-3))

    def __str__(self) -> str:
        return f"silicon {self.depth_um:g} µm deep"


def _spectrum(illuminant: str | tuple[Sequence[float], Sequence[float]]):
    """``(wavelengths nm, values)`` of an illuminant name or a given spectrum."""
    if isinstance(illuminant, str):
        if illuminant not in ILLUMINANTS:
            raise ValueError(
                f"unknown illuminant {illuminant!r}; expected one of {', '.join(ILLUMINANTS)}"
            )
        import colour

        sd = colour.SDS_ILLUMINANTS[ILLUMINANTS[illuminant]]
        return np.asarray(sd.wavelengths, float), np.asarray(sd.values, float)
    lams, values = (np.asarray(v, dtype=float) for v in illuminant)
    if lams.ndim != 1 or lams.shape != values.shape or len(lams) < 1 or values.min() < 0:
        raise ValueError("an illuminant spectrum is (wavelengths, non-negative values)")
    return lams, values


def _curve(qe, lams: np.ndarray, band: tuple[float, float], what: str) -> np.ndarray:
    """A curve (``(wavelengths, values)`` or a function of nm) on ``lams``, checked: within
    [0, 1] and covering the band."""
    if qe is None:
        return np.ones_like(lams)
    if callable(qe):
        values = np.asarray(qe(lams), dtype=float)
    else:
        grid, vals = (np.asarray(v, dtype=float) for v in qe)
        if grid.min() > band[0] or grid.max() < band[1]:
            raise ValueError(
                f"{what} covers {grid.min():g}-{grid.max():g} nm; it must cover "
                f"{band[0]:g}-{band[1]:g} nm"
            )
        values = np.interp(lams, grid, vals)
    if not np.all(np.isfinite(values)) or values.min() < 0 or values.max() > 1:
        raise ValueError(f"{what} must lie within [0, 1]")
    return values


def photons_per_lux(
    illuminant: str | tuple[Sequence[float], Sequence[float]] = "D65",
    *,
    band: tuple[float, float] = BAND,
    qe: Callable | tuple | None = None,
) -> float:
    """Photo-electrons per second and square metre that one lux of ``illuminant`` gives a
    pixel of quantum efficiency ``qe`` (default 1) counting ``band`` (nm). The photometric
    integral runs over the whole spectrum given (``V`` is 0 outside 360-830 nm).

    Raises:
        ValueError: An unknown illuminant, or a QE curve outside [0, 1] or short of the band.
    """
    import colour

    lams, values = _spectrum(illuminant)
    v_sd = colour.SDS_LEFS["CIE 1924 Photopic Standard Observer"]
    v = np.interp(lams, v_sd.wavelengths, v_sd.values, left=0.0, right=0.0)
    steps = np.gradient(lams) if len(lams) > 1 else np.ones(1)
    luminous = LUMENS_PER_WATT * float(np.sum(values * v * steps))
    if luminous <= 0:
        raise ValueError("the illuminant has no light the eye sees (0 lux)")
    inside = (lams >= band[0]) & (lams <= band[1])
    efficiency = _curve(qe, lams, band, "the quantum efficiency")
    energy = values * lams * 1e-9 / (PLANCK * LIGHT) * efficiency * steps  # photons per W
    return float(np.sum(energy[inside])) / luminous


@dataclass(frozen=True)
class Camera:
    """The camera that turns scene lux into ``N``: pixel pitch (µm), f-number, exposure time
    (s), illuminant, the scene's reflectance (1: white, the model's ``f = 1``), the lens's
    transmission and the pixel's quantum efficiency (default 1: the model's lossless pixel).
    ``white`` is the share of ``N`` a bare pixel collects from a white scene in the model: 1 for
    scenes lit by D65, below 1 for scenes lit by another illuminant
    (:meth:`splitcam.physics.stack.SceneLight.white_share`), where ``N`` is in units of the
    brightest wavelength's light.

    Raises:
        ValueError: A pitch, f-number or time of 0 or less, a reflectance, transmission or
            white share outside (0, 1], an unknown illuminant or a bad QE curve.
    """

    pitch_um: float = 1.0
    f_number: float = 2.0
    exposure_s: float = 1.0 / 30.0
    illuminant: str = "D65"
    reflectance: float = 1.0
    transmission: float = 1.0
    qe: Any = field(default=None, compare=False)
    white: float = 1.0

    def __post_init__(self) -> None:
        for name in ("pitch_um", "f_number", "exposure_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("reflectance", "transmission", "white"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"{name} must be in (0, 1], got {getattr(self, name)}")
        photons_per_lux(self.illuminant, qe=self.qe)  # checks the illuminant and the QE

    @property
    def electrons_per_lux(self) -> float:
        """``N`` for one lux on the scene."""
        image = self.reflectance * self.transmission / (4.0 * self.f_number**2)
        area = (self.pitch_um * 1e-6) ** 2
        electrons = image * photons_per_lux(self.illuminant, qe=self.qe) * area * self.exposure_s
        return electrons / self.white

    def lux(self, photons: float) -> float:
        """The scene illuminance at which a lossless pixel collects ``photons``."""
        return photons / self.electrons_per_lux

    def photons(self, lux: float) -> float:
        """``N`` at scene illuminance ``lux``."""
        return lux * self.electrons_per_lux

    def describe(self) -> str:
        """``pitch 1 µm, f/2, 1/30 s, D65, white scene``: the settings as tables state them."""
        time = f"1/{1 / self.exposure_s:.3g} s" if self.exposure_s < 1 else f"{self.exposure_s:g} s"
        parts = [f"pitch {self.pitch_um:g} µm", f"f/{self.f_number:g}", time, self.illuminant]
        parts.append(
            "white scene" if self.reflectance == 1 else f"reflectance {self.reflectance:g}"
        )
        if self.transmission != 1:
            parts.append(f"lens transmission {self.transmission:g}")
        parts.append("lossless pixel" if self.qe is None else f"QE of {self.qe}")
        if self.white != 1:
            parts.append(f"the scene lit by {self.illuminant} (white gives {self.white:.3g} N)")
        return ", ".join(parts)
