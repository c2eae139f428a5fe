"""Colour filter arrays from measured camera spectral sensitivities.

The ideal arrays of the library (``bayer``, ``rgbw``) have box filters: a red filter passes all
red light and nothing else. Real filters pass less than all of their band and leak into their
neighbours'. The arrays here use the spectral sensitivities of two cameras measured by the UK's
National Physical Laboratory, which ship with colour-science
(``colour.MSDS_CAMERA_SENSITIVITIES``): the Nikon D5100 (a Bayer sensor) and the Sigma SD
Merrill (a stacked Foveon sensor, whose three depths are broad, overlapping responses).

A measured sensitivity is the product of the filter's transmission and the bare pixel's
response (silicon quantum efficiency, infrared-cut filter, lens). It is published normalised
to a peak of 1, so the bare pixel's absolute response cannot be recovered from it. splitcam
takes the bare pixel's response as flat over the measured range (every photon counted the same
at every wavelength), the same assumption under which the routers' transmissions are compared:
a silicon response common to all pixels scales filters and routers alike. Each filter's
transmission is then its channel's sensitivity, peaking at 1, and the W pixel of an RGBW array
is the bare pixel: transmission 1 at every wavelength. A real filter peaks somewhat below 1 and
real silicon is less sensitive in the blue, so these arrays, like the ideal ones, flatter
filters slightly.

Each is a :class:`~splitcam.patterns.spectral.SpectralPattern` on the camera's measured range
within 400-700 nm at 10 nm, reduced to RGB kernels by the scene basis of
:mod:`splitcam.patterns.spectral`.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .core import Pattern
from .spectral import SpectralPattern

__all__ = ["CAMERAS", "camera_filters", "measured_array"]

#: Short names of the cameras and their entries in ``colour.MSDS_CAMERA_SENSITIVITIES``.
CAMERAS = {"d5100": "Nikon 5100 (NPL)", "sdmerrill": "Sigma SDMerill (NPL)"}

_RGGB = [[1, 2], [2, 3]]  # the splitter indices: 0 W, 1 R, 2 G, 3 B
_RGBW = [[0, 3, 0, 2], [3, 0, 2, 0], [0, 2, 0, 1], [2, 0, 1, 0]]  # as the library's rgbw


@lru_cache(maxsize=4)
def camera_filters(camera: str) -> tuple[np.ndarray, np.ndarray]:
    """``(wavelengths, transmission)``: the camera's measured range within 400-700 nm at 10 nm,
    and its R, G, B filters' transmissions there, ``(L, 3)``, each peaking at 1."""
    import colour

    curves = colour.MSDS_CAMERA_SENSITIVITIES[CAMERAS[camera]]
    low = max(400.0, float(curves.wavelengths[0]))
    high = min(700.0, float(curves.wavelengths[-1]))
    grid = np.arange(np.ceil(low / 10) * 10, high + 1e-9, 10.0)
    values = np.stack(
        [np.interp(grid, curves.wavelengths, curves.values[:, c]) for c in range(3)], axis=1
    )
    return grid, values / values.max(axis=0, keepdims=True)


def measured_array(kind: str, camera: str) -> Pattern:
    """``bayer`` or ``rgbw`` with the filters of ``camera`` (a key of :data:`CAMERAS`)."""
    grid, filters = camera_filters(camera)
    kernels = np.zeros((4, len(grid), 1, 1))
    kernels[0] = 1.0  # the bare pixel of an RGBW array
    for c in range(3):
        kernels[1 + c, :, 0, 0] = filters[:, c]
    layout = np.array(_RGGB if kind == "bayer" else _RGBW)
    used = np.unique(layout)
    kernels = kernels[used]
    layout = np.searchsorted(used, layout)
    name = f"{kind}-{camera}"
    share = "half W pixels (no filter), " if kind == "rgbw" else ""
    camera_name = CAMERAS[camera].split(" (")[0]
    # The SD Merrill is a Foveon sensor: three stacked photodiode layers at every pixel, no
    # mosaic. Its measured curves are the depths' responses, used here as if they were filters.
    curves = (
        f"filters shaped as the layer responses of the {camera_name} (a Foveon sensor: three "
        "stacked layers at every pixel, no mosaic),"
        if camera == "sdmerrill"
        else f"colour filters of the {camera_name} sensitivities"
    )
    spectral = SpectralPattern(
        name,
        layout,
        grid,
        kernels,
        provenance=f"measured filters ({CAMERAS[camera]})",
        description=f"{'RGBW' if kind == 'rgbw' else 'RGGB'} array, {share}{curves} measured "
        f"by NPL ({grid[0]:g}-{grid[-1]:g} nm; splitcam.patterns.measured)",
        reference="NPL camera spectral sensitivities, in colour-science "
        "(colour.MSDS_CAMERA_SENSITIVITIES)",
    )
    return spectral.to_pattern()
