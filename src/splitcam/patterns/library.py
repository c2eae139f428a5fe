"""The published splitter patterns A–E, the Bayer filter (model.md §2) and the low-light
filter arrays RGBW and Quad Bayer (model.md §14).

Kernels are written ``[row][col]``; the centre tap is the light that stays on the pixel where it
arrived. A and D match the authors' code exactly; B, C and E are modelled from the device
descriptions because the paper's kernels for them are unpublished.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from .core import Pattern
from .measured import CAMERAS, measured_array

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


# Filters of the low-light arrays (model.md §14): W passes every colour, R, G, B their own.
_W, _R, _G, _B = 0, 1, 2, 3
_FILTERS = np.zeros((4, 3, 1, 1))
_FILTERS[_W] = 1.0
for _c in range(3):
    _FILTERS[1 + _c, _c] = 1.0


def _filter_array(name: str, layout: list[list[int]], description: str, reference: str) -> Pattern:
    """An array of the ideal filters :data:`_FILTERS` (W, R, G, B) in ``layout``."""
    return Pattern(
        name=name,
        layout=np.array(layout),
        kernels=_FILTERS.copy(),
        provenance="standard",
        description=description,
        reference=reference,
    )


def _pattern_rgbw() -> Pattern:
    return _filter_array(
        "rgbw",
        [[_W, _B, _W, _G], [_B, _W, _G, _W], [_W, _G, _W, _R], [_G, _W, _R, _W]],
        "RGBW colour filter array: panchromatic (W) pixels on a checkerboard, half of all "
        "pixels, ideal filters; collects 2/3 of white light, twice a Bayer filter",
        "Compton & Hamilton (Kodak): image sensor with improved light sensitivity ('CFA 2.0')",
    )


def _pattern_quad() -> Pattern:
    return _filter_array(
        "quad",
        [[_R, _R, _G, _G], [_R, _R, _G, _G], [_G, _G, _B, _B], [_G, _G, _B, _B]],
        "Quad Bayer (Tetracell) filter array: each colour of the RGGB arrangement on a 2x2 "
        "block of pixels, ideal filters; collects 1/3 of white light, as a Bayer filter",
        "Sony Quad Bayer / Samsung Tetracell image sensors",
    )


def _pattern_xtrans() -> Pattern:
    g, r, b = _G, _R, _B
    return _filter_array(
        "xtrans",
        [
            [g, b, g, g, r, g],
            [r, g, r, b, g, b],
            [g, b, g, g, r, g],
            [g, r, g, g, b, g],
            [b, g, b, r, g, r],
            [g, r, g, g, b, g],
        ],
        "X-Trans colour filter array: a 6x6 cell with every row and column holding all three "
        "colours (20 G, 8 R, 8 B), ideal filters; collects 1/3 of white light",
        "Fujifilm X-Trans CMOS sensor (2012)",
    )


# Which colour each pixel of A's RGGB arrangement collects (model.md §2).
_A_COLOURS = np.array([[0, 1], [1, 2]])


def router(
    eta: float | tuple[float, float, float],
    chi: float | tuple[float, float, float] = 0.0,
    *,
    name: str | None = None,
    description: str = "",
    reference: str = "",
) -> Pattern:
    """A Bayer-type colour router with losses and crosstalk, on pattern A's geometry (model.md §15).

    For each colour ``c``: ``w = eta_c * w_A + chi_c * x_A``, where ``w_A`` is A's kernel (all
    light of colour ``c`` to the nearest pixel(s) of colour ``c``) and ``x_A`` spreads light
    evenly over the taps of A's 3x3 neighbourhood that are *not* pixels of colour ``c``. The rest,
    ``1 - eta_c - chi_c``, is lost. ``router(1, 0)`` is A.

    Args:
        eta: Band efficiencies (R, G, B), or one for all: the share of each colour's light that
            reaches pixels of that colour.
        chi: Crosstalk (R, G, B), or one for all: the share that reaches pixels of other colours.
        name: The pattern's name (default ``router(eta=...;chi=...)``).

    Raises:
        PatternError: Values outside [0, 1], or ``eta_c + chi_c > 1`` (light would be created).
    """
    from .core import PatternError

    def three(v, what: str) -> np.ndarray:
        arr = np.broadcast_to(np.asarray(v, dtype=np.float64), (3,)).copy()
        if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
            raise PatternError(f"router {what} must be 3 values in [0, 1], got {arr.tolist()}")
        return arr

    e, x = three(eta, "eta"), three(chi, "chi")
    over = np.flatnonzero(e + x > 1 + 1e-12)
    if over.size:
        c = int(over[0])
        raise PatternError(
            f"router colour {'RGB'[c]}: eta + chi = {e[c] + x[c]:g} > 1 (a router cannot send on "
            f"more light than arrives)"
        )
    a = _pattern_a()
    kernels = np.zeros_like(a.kernels)
    for s in range(4):
        i, j = divmod(s, 2)  # A's layout [[0, 1], [2, 3]]
        for c in range(3):
            other = np.array(
                [
                    [_A_COLOURS[(i + u) % 2, (j + v) % 2] != c for v in (-1, 0, 1)]
                    for u in (-1, 0, 1)
                ],
                dtype=np.float64,
            )
            kernels[s, c] = e[c] * a.kernels[s, c] + x[c] * other / other.sum()
    label = name or (
        "router(eta="
        + ",".join(f"{v:g}" for v in e)
        + ";chi="
        + ",".join(f"{v:g}" for v in x)
        + ")"
    )
    return Pattern(
        name=label,
        layout=a.layout,
        kernels=kernels,
        provenance="router model (model.md §15)",
        description=description
        or f"Bayer-type router with band efficiency {', '.join(f'{v:g}' for v in e)} and "
        f"crosstalk {', '.join(f'{v:g}' for v in x)} (R, G, B) on pattern A's geometry",
        reference=reference,
        metadata={"eta": e.tolist(), "chi": x.tolist()},
    )


def parse_router(spec: str) -> Pattern | None:
    """``router(eta=0.56,0.56,0.43;chi=0.42,0.41,0.54)`` (or one value each, ``chi`` optional)
    as a :func:`router`; None for any other text.

    Raises:
        PatternError: A ``router(...)`` that cannot be read (the message shows the syntax).
    """
    from .core import PatternError

    text = spec.strip().replace(" ", "")
    if not (text.lower().startswith("router(") and text.endswith(")")):
        return None
    syntax = "expected router(eta=R,G,B;chi=R,G,B), e.g. router(eta=0.56,0.56,0.43;chi=0.1)"
    values: dict[str, list[float]] = {}
    for part in filter(None, text[len("router(") : -1].split(";")):
        key, _, rest = part.partition("=")
        try:
            values[key.lower()] = [float(v) for v in rest.split(",")]
        except ValueError:
            raise PatternError(f"cannot read {spec!r}: {syntax}") from None
    if set(values) - {"eta", "chi"} or "eta" not in values:
        raise PatternError(f"cannot read {spec!r}: {syntax}")
    if any(len(v) not in (1, 3) for v in values.values()):
        raise PatternError(f"cannot read {spec!r}: give 1 or 3 values (R, G, B) each; {syntax}")
    return router(values["eta"], values.get("chi", [0.0]))


# Calibration of the router presets (model.md §15) to the invrs-gym Bayer-sorter leaderboard
# (github.com/invrs-io/leaderboard, challenges/bayer_sorter/leaderboard.txt, full-wave FMM
# simulations). There, efficiency_c is the in-band light of colour c reaching the pixel(s) of
# colour c, which is eta_c here; crosstalk_p is the out-of-band light landing in pixel p, a
# mean over the two other bands, so the light landing on wrong-colour pixels totals
# 2 * sum_p crosstalk_p (in units of one colour's incident light). The leaderboard does not say
# how it divides among the colours: here in proportion to each colour's light not routed right,
# chi_c = (1 - eta_c) * 2 sum_p crosstalk_p / sum_c (1 - eta_c).
_ZOU = {"eta": (0.5587, 0.5607, 0.4289), "chi": (0.4151, 0.4132, 0.5371)}
_BEST = {"eta": (0.5511, 0.5937, 0.6561), "chi": (0.4120, 0.3729, 0.3156)}


def _router_zou() -> Pattern:
    return router(
        **_ZOU,
        name="router-zou",
        description="Zou et al.'s fabricated metasurface Bayer router, full-wave: band efficiency "
        "R/G/B 0.559/0.561/0.429, pixel crosstalk 0.193/0.347/0.143 (invrs-gym leaderboard, "
        "220607_zou_00) mapped to eta = efficiency, chi = 0.415/0.413/0.537 (the wrong-pixel "
        "light 2 x sum of crosstalk = 1.365, shared in proportion to 1 - eta)",
        reference="Zou et al., Nat. Commun. 13, 3288 (2022); invrs-io/leaderboard bayer_sorter",
    )


def _router_best() -> Pattern:
    return router(
        **_BEST,
        name="router-best",
        description="Best Bayer-sorter design of the invrs-gym leaderboard (eval metric 0.551, "
        "240325_mfschubert_49ca0bd2), full-wave: band efficiency R/G/B 0.551/0.594/0.656, pixel "
        "crosstalk 0.135/0.271/0.144 mapped to eta = efficiency, chi = 0.412/0.373/0.316 (the "
        "wrong-pixel light 1.100, shared in proportion to 1 - eta)",
        reference="invrs-io/leaderboard, challenges/bayer_sorter (2024)",
    )


#: Spectral patterns shipped as data (``patterns/data/<name>.toml``, written by
#: ``splitcam optics rcwa``; docs/results/fullwave/): a user needs no solver to use them.
_SPECTRA_DIR = Path(__file__).resolve().parent / "data"
_SHIPPED_SPECTRAL = sorted(p.stem for p in _SPECTRA_DIR.glob("*.toml"))


def _shipped_spectral(name: str) -> Pattern:
    from .files import load

    return load(_SPECTRA_DIR / f"{name}.toml")


BUILTIN_FACTORIES = {
    "A": _pattern_a,
    "B": _pattern_b,
    "C": _pattern_c,
    "D": _pattern_d,
    "E": _pattern_e,
    "bayer": _pattern_bayer,
    "rgbw": _pattern_rgbw,
    "quad": _pattern_quad,
    "xtrans": _pattern_xtrans,
    "router-zou": _router_zou,
    "router-best": _router_best,
    # Routers from full-wave simulation (splitcam optics rcwa), shipped as spectra.
    **{name: partial(_shipped_spectral, name) for name in _SHIPPED_SPECTRAL},
    # Filter arrays of measured camera sensitivities (splitcam.patterns.measured).
    **{
        f"{kind}-{camera}": partial(measured_array, kind, camera)
        for camera in CAMERAS
        for kind in ("bayer", "rgbw")
    },
}
