"""A binary metasurface layer made to keep a minimum feature size, solid and void alike.

The filter of the design's densities (:func:`splitcam.design.fullwave.conic_filter`) keeps the
*continuous* densities smooth over its radius, but thresholding them where they are grey can
leave specks of pillar and slits of background far narrower than the radius: a binary layer
that no process at that feature size can make. The fabrication assumption is the one of
length-scale measures in inverse design (and of the invrs-gym leaderboard's 80 nm rule): a
layer has minimum length scale ``d`` cells when a disc "brush" of diameter ``d`` can paint
every solid feature and every void one, that is, when opening the layer with the brush leaves
it unchanged (no solid narrower than the brush) and so does closing it (no void narrower).

:func:`with_minimum_feature` makes a thresholded layer such: it alternates opening and closing
with the brush (periodic, as the layer is). Closing fills gaps narrower than the brush, which
can join two pillars by a neck the next opening would cut again; such a neck is removed with
the brush's width of pillar around it (the gap is widened instead of the neck bridged), so the
alternation ends. The order matters (opening first removes a pillar a slit has cut into thin
halves; closing first would mend it), so both orders are run, the second as the first on the
complementary layer, and the one that changes fewer cells is kept. Each stops only where both
the opening and the closing leave the layer unchanged: the result satisfies the rule by
construction.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


class LengthScaleError(ValueError):
    """A layer that the alternation could not bring to the brush's feature size."""


def brush(diameter: int) -> np.ndarray:
    """A disc of ``diameter`` cells: the cells whose centres lie inside the circle of that
    diameter centred on the ``(diameter, diameter)`` array."""
    if diameter < 1:
        raise LengthScaleError(f"a brush is at least 1 cell across, got {diameter}")
    centres = np.arange(diameter) - (diameter - 1) / 2
    return centres[:, None] ** 2 + centres[None, :] ** 2 < (diameter / 2) ** 2


def _periodic(op, layer: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    pad = kernel.shape[0] + 1
    return op(np.pad(layer, pad, mode="wrap"), kernel)[pad:-pad, pad:-pad]


def opened(layer: np.ndarray, diameter: int) -> np.ndarray:
    """The periodic layer opened with the brush: solid narrower than it removed."""
    return _periodic(ndimage.binary_opening, layer, brush(diameter))


def closed(layer: np.ndarray, diameter: int) -> np.ndarray:
    """The periodic layer closed with the brush: void narrower than it filled."""
    return _periodic(ndimage.binary_closing, layer, brush(diameter))


def keeps_minimum_feature(layer: np.ndarray, diameter: int) -> bool:
    """Whether the brush paints every solid and every void feature of the periodic layer."""
    layer = np.asarray(layer, dtype=bool)
    return bool(
        np.array_equal(opened(layer, diameter), layer)
        and np.array_equal(closed(layer, diameter), layer)
    )


def minimum_length_scale(layer: np.ndarray, limit: int = 64) -> tuple[int, int]:
    """The periodic layer's minimum solid and void length scales, in cells: the widest brush
    that paints every solid (opening leaves the layer as it is), and the same of void
    (closing); at most ``limit`` (or the layer's shorter side), which a phase absent or
    unbroken measures. A disc of odd width is not a union of the even brush one narrower
    (their centres sit half a cell apart), so the search goes on past a brush that fails and
    stops where two widths in a row fail. The measure the binary designs' reports print;
    imageruler's lets the brush miss single cells along an interface, and measures at least as
    wide."""
    layer = np.asarray(layer, dtype=bool)
    if layer.ndim != 2 or min(layer.shape) < 1 or limit < 1:
        raise LengthScaleError(
            f"a layer is a 2-D grid and the limit at least 1, got {layer.shape}, {limit}"
        )
    top = min(limit, *layer.shape)
    if layer.all() or not layer.any():
        return top, top

    def widest(keeps) -> int:
        best, d = 0, 1
        while d <= top:
            if keeps(d):
                best, d = d, d + 1
            elif d + 1 <= top and keeps(d + 1):
                best, d = d + 1, d + 2
            else:
                break
        return best

    solid = widest(lambda d: np.array_equal(opened(layer, d), layer))
    void = widest(lambda d: np.array_equal(closed(layer, d), layer))
    return solid, void


def with_minimum_feature(layer: np.ndarray, diameter: int, rounds: int = 20) -> np.ndarray:
    """The binary periodic ``layer`` (bool, or 0/1) changed as little as the rule allows so that
    a brush of ``diameter`` cells paints its every solid and void feature (module docstring).
    A diameter of 1 or less changes nothing.

    Raises:
        LengthScaleError: The layer is not 2-D, is narrower than the brush, or neither order
            of the alternation has settled after ``rounds``.
    """
    x = np.asarray(layer).astype(bool)
    if x.ndim != 2:
        raise LengthScaleError(f"a layer is a 2-D grid, got shape {x.shape}")
    if diameter <= 1:
        return x
    if min(x.shape) < diameter:
        raise LengthScaleError(
            f"a {diameter}-cell brush does not fit a layer of {x.shape[0]} x {x.shape[1]} cells"
        )
    settled = []
    for flip in (False, True):  # opening first; closing first (opening the void first)
        y = _settled(~x if flip else x, diameter, rounds)
        if y is not None:
            settled.append(~y if flip else y)
    if not settled:
        raise LengthScaleError(
            f"the layer did not settle to a {diameter}-cell minimum feature in {rounds} rounds"
        )
    return min(settled, key=lambda y: int((y != x).sum()))


def _settled(x: np.ndarray, diameter: int, rounds: int) -> np.ndarray | None:
    """Opening, then closing, until neither changes the layer (None if not in ``rounds``)."""
    kernel = brush(diameter)
    for _ in range(rounds + 1):
        once = opened(x, diameter)  # the check's opening and closing are the alternation's
        y = closed(once, diameter)  # (where the opening leaves x, this is x closed)
        if np.array_equal(once, x) and np.array_equal(y, x):
            return x
        necks = y & ~opened(y, diameter)  # joins the closing made that the opening cuts
        x = y & ~_periodic(ndimage.binary_dilation, necks, kernel)
    return None
