"""The Pattern class (splitcam.patterns.core): accepted kernels and the patterns refused."""

from __future__ import annotations

import numpy as np
import pytest

from splitcam import patterns
from splitcam.patterns import Pattern, PatternError


def _valid() -> dict:
    return patterns.get("D").to_dict()


def test_4d_kernel_list_accepted():
    data = _valid()
    data["kernels"] = patterns.get("D").kernels.tolist()
    assert Pattern.from_dict(data).equals(patterns.get("D"))


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda d: d["kernels"][0].update(R=[[0, 1]]), "mismatched sizes"),
        (
            lambda d: [k.update(R=[[0, 1]], G=[[0, 1]], B=[[0, 1]]) for k in d["kernels"]],
            "kernel size must be odd in both directions.*got 1x2",
        ),
        (
            lambda d: d.update(layout=[[0, 1], [2, 4]]),
            r"layout index 4 at position \(1, 1\) is out of range for 4 splitters",
        ),
        (lambda d: d.update(layout=[[0, -1], [2, 3]]), "layout index -1"),
        (lambda d: d.update(layout=[0, 1, 2, 3]), "layout must be a 2-D grid of integers"),
        (lambda d: d.update(layout=[[[0]]]), "layout must be a 2-D grid of integers"),
        (lambda d: d.update(layout=[[0, 1], [2]]), "layout has mismatched sizes"),
        (lambda d: d.update(layout=[[0, 1.5], [2, 3]]), "layout must be a 2-D grid of integers"),
        (lambda d: d.update(layout=[["a", 1], [2, 3]]), "layout must be a 2-D grid of integers"),
        (
            lambda d: d["kernels"][1].update(G=[[0, -0.5, 1.5]]),
            "splitter 1, colour G at \\(0, 1\\) is negative",
        ),
        (lambda d: d["kernels"][1].update(G=[[0, float("nan"), 0]]), "is not finite"),
        (lambda d: d["kernels"][1].update(G=[[0, float("inf"), 0]]), "is not finite"),
        (
            lambda d: d["kernels"][2].update(B=[[0.5, 1, 0.5]]),
            "splitter 2, colour B sums to 2 > 1.*create light",
        ),
        (
            lambda d: d.update(kernels=np.zeros((4, 2, 1, 3)).tolist()),
            "kernels must have 3 colours",
        ),
        (
            lambda d: d.update(kernels=np.zeros((4, 4, 1, 3)).tolist()),
            "kernels must have 3 colours .* got 4",
        ),
        (lambda d: d["kernels"][0].pop("B"), "splitter 0 must give exactly the colours R, G, B"),
        (lambda d: d.update(kernels=[[0, 1, 0]]), "kernels must have shape"),
        (lambda d: d.pop("layout"), "missing field.*layout"),
        (lambda d: d.update(colour="red"), "unknown field.*colour"),
        (lambda d: d.update(name=""), "non-empty name"),
    ],
)
def test_invalid_patterns_are_refused(change, message):
    data = _valid()
    change(data)
    with pytest.raises(PatternError, match=message):
        Pattern.from_dict(data)


def test_kernels_constructor_errors():
    with pytest.raises(PatternError, match="kernels must be numbers"):
        Pattern("x", [[0]], [[[["a"]]] * 3])


def test_a_pixel_that_records_no_light_is_refused_by_name() -> None:
    """Kernels under which some pixel of the period gets no light at all passed the validator,
    then the LMMSE raised LinAlgError. The validator names the pixel; one that gets light only
    from a neighbour's splitter is fine."""
    import numpy as np

    from splitcam.patterns.core import Pattern, PatternError

    right = np.zeros((2, 3, 1, 3))
    right[0, :, 0, 2] = 1.0  # splitter 0 sends everything one pixel to the right
    right[1, :, 0, 1] = 1.0  # splitter 1 keeps its light
    with pytest.raises(PatternError, match=r"pixel \(0, 0\) of the period records no light"):
        Pattern("dark", np.array([[0, 1]]), right)
    with pytest.raises(PatternError, match=r"pixel \(0, 0\)"):
        Pattern("none", np.array([[0]]), np.zeros((1, 3, 1, 1)))
    right[1, :, 0, 1] = 0.0
    right[1, :, 0, 2] = 1.0  # both send right: each pixel gets its left neighbour's light
    assert Pattern("shifted", np.array([[0, 1]]), right).period == (1, 2)
