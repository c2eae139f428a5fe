"""The pattern library (splitcam.patterns.library): the paper's values, routers and their
presets."""

from __future__ import annotations

import numpy as np
import pytest

from splitcam import patterns
from splitcam.patterns import PatternError


def test_library_values_follow_the_spec():
    a = patterns.get("A")
    assert a.period == (2, 2) and a.kernel_size == (3, 3) and a.provenance == "authors' code"
    # A: green light at the R site goes to the four edge neighbours, a quarter each.
    assert a.kernels[0, 1].tolist() == [[0, 0.25, 0], [0.25, 0, 0.25], [0, 0.25, 0]]
    d = patterns.get("D")
    assert d.kernel_size == (1, 3) and d.kernels[1, 0].tolist() == [[0.5, 0, 0.5]]
    assert d.kernels[2, 2].tolist() == [[0.5, 0, 0.5]]
    c = patterns.get("C")
    assert c.layout.tolist() == [[0, 1, 2]] and c.kernel_size == (1, 5)
    e = patterns.get("E")
    assert e.layout.tolist() == [[0, 1, 0]]
    for name in ["A", "B", "C", "D", "E"]:
        p = patterns.get(name)
        assert np.allclose(p.kernels.sum(axis=(2, 3)), 1.0), name  # splitters are lossless
        assert p.description and p.reference
    bayer = patterns.get("bayer")
    assert bayer.absorbs_light and bayer.kernel_size == (1, 1)
    assert bayer.provenance == "standard"
    assert patterns.get("B").provenance.startswith("modelled")


def test_pattern_b_two_green_pixels_of_a_cell_read_the_same():
    """model.md §2: B pools each cell's green half/half into its two G sub-pixels."""
    import torch

    from splitcam.physics.sensor import SplitterSensor

    f = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    raw = SplitterSensor("B")(f)[0, 0]
    torch.testing.assert_close(raw[0::2, 1::2], raw[1::2, 0::2])


def test_router_model_is_a_with_losses_and_crosstalk():
    """model.md §15: router(1, 0) is A; every colour's kernel sums to eta + chi (light lost, never
    created); the eta part lands on pixels of its colour and the chi part only on others."""
    import numpy as np

    a = patterns.get("A")
    assert np.array_equal(patterns.get("router(eta=1;chi=0)").kernels, a.kernels)
    eta, chi = (0.56, 0.6, 0.43), (0.3, 0.25, 0.5)
    r = patterns.router(eta, chi)
    assert np.allclose(r.kernels.sum((2, 3)), np.add(eta, chi)[None, :])
    colour = np.array([[0, 1], [1, 2]])  # A's RGGB pixels
    for s in range(4):
        i, j = divmod(s, 2)
        for c in range(3):
            target = np.array(
                [[colour[(i + u) % 2, (j + v) % 2] == c for v in (-1, 0, 1)] for u in (-1, 0, 1)]
            )
            assert r.kernels[s, c][target].sum() == pytest.approx(eta[c])
            assert r.kernels[s, c][~target].sum() == pytest.approx(chi[c])
    same = patterns.get("router(eta=0.56,0.6,0.43;chi=0.3,0.25,0.5)")
    assert np.allclose(same.kernels, r.kernels)
    with pytest.raises(PatternError, match="eta \\+ chi = 1.2 > 1"):
        patterns.router(0.7, 0.5)
    with pytest.raises(PatternError, match="expected router"):
        patterns.get("router(eta=0.5;gamma=1)")
    with pytest.raises(PatternError, match="1 or 3 values"):
        patterns.get("router(eta=0.5,0.5)")


def test_router_presets_match_their_published_numbers():
    """router-zou and router-best: eta is the leaderboard's band efficiency; chi shares the
    wrong-pixel light 2 * sum(crosstalk) in proportion to 1 - eta (library docstring)."""
    import numpy as np

    published = {
        "router-zou": ((0.5587, 0.5607, 0.4289), (0.1928, 0.3467, 0.1432)),
        "router-best": ((0.5511, 0.5937, 0.6561), (0.1354, 0.2709, 0.1439)),
    }
    for name, (eta, crosstalk) in published.items():
        p = patterns.get(name)
        assert np.allclose(p.metadata["eta"], eta)
        chi = np.asarray(p.metadata["chi"])
        assert chi.sum() == pytest.approx(2 * sum(crosstalk), abs=2e-3)
        assert np.allclose(
            chi / chi.sum(), (1 - np.asarray(eta)) / (1 - np.asarray(eta)).sum(), atol=1e-3
        )
        assert (p.kernels.sum((2, 3)) <= 1).all()
