"""The published splitter patterns A–E, the Bayer filter (SPEC section 2) and the low-light
filter arrays RGBW and Quad Bayer (SPEC section 14).

Kernels are written ``[row][col]``; the centre tap is the light that stays on the pixel where it
arrived. A and D match the authors' code exactly; B, C and E are modelled from the device
descriptions because the paper's kernels for them are unpublished.
"""

from __future__ import annotations

import numpy as np

from .core import Pattern

_C3 = [[0, 0, 0], [0, 1, 0], [0, 0, 0]]
_CROSS = [[0, 0.25, 0], [0.25, 0, 0.25], [0, 0.25, 0]]
_CORNERS = [[0.25, 0, 0.25], [0, 0, 0], [0.25, 0, 0.25]]
_HORIZ = [[0, 0, 0], [0.5, 0, 0.5], [0, 0, 0]]
_VERT = [[0, 0.5, 0], [0, 0, 0], [0, 0.5, 0]]
_LAYOUT_2X2 = [[0, 1], [2, 3]]


def _pattern_a() -> Pattern:
    kernels = [
        [_C3, _CROSS, _CORNERS],  # s0, R site
        [_HORIZ, _C3, _VERT],  # s1, G site top-right
        [_VERT, _C3, _HORIZ],  # s2, G site bottom-left
        [_CORNERS, _CROSS, _C3],  # s3, B site
    ]
    return Pattern(
        name="A",
        layout=np.array(_LAYOUT_2X2),
        kernels=np.array(kernels, dtype=np.float64),
        provenance="authors' code",
        description="Bayer-type full colour sorting: each colour to the nearest RGGB pixel(s) of "
        "that colour",
        reference="Miyata et al., Optica 8(12), 2021",
    )


def _pattern_b() -> Pattern:
    kernels = [
        [_C3, [[0, 0, 0], [0, 0, 0.5], [0, 0.5, 0]], [[0, 0, 0], [0, 0, 0], [0, 0, 1]]],
        [
            [[0, 0, 0], [1, 0, 0], [0, 0, 0]],
            [[0, 0, 0], [0, 0.5, 0], [0.5, 0, 0]],
            [[0, 0, 0], [0, 0, 0], [0, 1, 0]],
        ],
        [
            [[0, 1, 0], [0, 0, 0], [0, 0, 0]],
            [[0, 0, 0.5], [0, 0.5, 0], [0, 0, 0]],
            [[0, 0, 0], [0, 0, 1], [0, 0, 0]],
        ],
        [[[1, 0, 0], [0, 0, 0], [0, 0, 0]], [[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]], _C3],
    ]
    return Pattern(
        name="B",
        layout=np.array(_LAYOUT_2X2),
        kernels=np.array(kernels, dtype=np.float64),
        provenance="modelled from the device description",
        description="Sub-pixel router with dual-focal green: each 2x2 cell pools its light into "
        "R, G, G, B sub-pixels",
        reference="Kim, Hong & Lee, Proc. SPIE 11898, 2021",
    )


def _pattern_c() -> Pattern:
    def row(pos: int) -> list[list[float]]:
        k = [0.0] * 5
        k[pos] = 1.0
        return [k]

    kernels = [
        [row(2), row(3), row(4)],
        [row(1), row(2), row(3)],
        [row(0), row(1), row(2)],
    ]
    return Pattern(
        name="C",
        layout=np.array([[0, 1, 2]]),
        kernels=np.array(kernels, dtype=np.float64),
        provenance="modelled from the device description",
        description="Full-colour sub-pixel nanorouter: each cell of three pixels pools its R, G "
        "and B light into three sub-pixels in a row",
        reference="Chen et al., Nanoscale 13, 2021",
    )


def _pattern_d() -> Pattern:
    stay = [[0, 1, 0]]
    split = [[0.5, 0, 0.5]]
    kernels = [
        [stay, stay, stay],  # s0, W+R pixel
        [split, stay, stay],  # s1, red deflector (W-R pixel)
        [stay, stay, split],  # s2, blue deflector (W-B pixel)
        [stay, stay, stay],  # s3, W+B pixel
    ]
    return Pattern(
        name="D",
        layout=np.array(_LAYOUT_2X2),
        kernels=np.array(kernels, dtype=np.float64),
        provenance="authors' code",
        description="Micro colour splitters: red and blue deflectors give W+R, W-R, W-B, W+B "
        "pixels",
        reference="Nishiwaki et al., Nature Photonics 7, 2013",
    )


def _pattern_e() -> Pattern:
    stay = [[0, 1, 0]]
    kernels = [
        [stay, stay, stay],  # s0, no splitter
        [[[1, 0, 0]], stay, [[0, 0, 1]]],  # s1, splitter: R left, G stays, B right
    ]
    return Pattern(
        name="E",
        layout=np.array([[0, 1, 0]]),
        kernels=np.array(kernels, dtype=np.float64),
        provenance="modelled from the device description",
        description="Pixel-scale colour splitters: one pixel in three sends R left and B right "
        "(W+R, G, W+B pixels)",
        reference="Miyata et al., ACS Photonics 6, 2019",
    )


def _pattern_bayer() -> Pattern:
    r, g, b = [[[1]], [[0]], [[0]]], [[[0]], [[1]], [[0]]], [[[0]], [[0]], [[1]]]
    return Pattern(
        name="bayer",
        layout=np.array(_LAYOUT_2X2),
        kernels=np.array([r, g, g, b], dtype=np.float64),
        provenance="standard",
        description="RGGB colour filter array: each pixel keeps one colour and absorbs the rest",
        reference="Bayer, US Patent 3,971,065, 1976",
    )


# Filters of the low-light arrays (SPEC section 14): W passes every colour, R, G, B their own.
_W, _R, _G, _B = 0, 1, 2, 3
_FILTERS = np.zeros((4, 3, 1, 1))
_FILTERS[_W] = 1.0
for _c in range(3):
    _FILTERS[1 + _c, _c] = 1.0


def _pattern_rgbw() -> Pattern:
    layout = [[_W, _B, _W, _G], [_B, _W, _G, _W], [_W, _G, _W, _R], [_G, _W, _R, _W]]
    return Pattern(
        name="rgbw",
        layout=np.array(layout),
        kernels=_FILTERS.copy(),
        provenance="standard",
        description="RGBW colour filter array: panchromatic (W) pixels on a checkerboard, half "
        "of all pixels, ideal filters; collects 2/3 of white light, twice a Bayer filter",
        reference="Compton & Hamilton (Kodak): image sensor with improved light sensitivity "
        "('CFA 2.0')",
    )


def _pattern_quad() -> Pattern:
    layout = [[_R, _R, _G, _G], [_R, _R, _G, _G], [_G, _G, _B, _B], [_G, _G, _B, _B]]
    return Pattern(
        name="quad",
        layout=np.array(layout),
        kernels=_FILTERS.copy(),
        provenance="standard",
        description="Quad Bayer (Tetracell) filter array: each colour of the RGGB arrangement on "
        "a 2x2 block of pixels, ideal filters; collects 1/3 of white light, as a Bayer filter",
        reference="Sony Quad Bayer / Samsung Tetracell image sensors",
    )


BUILTIN_FACTORIES = {
    "A": _pattern_a,
    "B": _pattern_b,
    "C": _pattern_c,
    "D": _pattern_d,
    "E": _pattern_e,
    "bayer": _pattern_bayer,
    "rgbw": _pattern_rgbw,
    "quad": _pattern_quad,
}
