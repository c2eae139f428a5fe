"""The pattern library, pattern files, validation and the design-principle measures."""

from __future__ import annotations

import json

import numpy as np
import pytest

from splitcam import patterns
from splitcam.patterns import Pattern, PatternError


def _valid() -> dict:
    return patterns.get("D").to_dict()


def test_registry_names_and_case_insensitive_lookup():
    assert patterns.names() == [
        "A",
        "B",
        "C",
        "D",
        "E",
        "bayer",
        "rgbw",
        "quad",
        "router-zou",
        "router-best",
    ]
    assert patterns.get("d").name == "D"
    assert patterns.get("BAYER").name == "bayer"
    with pytest.raises(PatternError, match="unknown pattern 'F'; valid names: A, B, C, D, E, bay"):
        patterns.get("F")


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
    """SPEC: B pools each cell's green half/half into its two G sub-pixels."""
    import torch

    from splitcam.physics.sensor import SplitterSensor

    f = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    raw = SplitterSensor("B")(f)[0, 0]
    torch.testing.assert_close(raw[0::2, 1::2], raw[1::2, 0::2])


@pytest.mark.parametrize("suffix", [".json", ".toml"])
@pytest.mark.parametrize("name", patterns.names())
def test_file_round_trip(tmp_path, name, suffix):
    p = patterns.get(name)
    path = patterns.save(p, tmp_path / f"p{suffix}")
    q = patterns.load(path)
    assert q.equals(p) and q.name == p.name and q.provenance == p.provenance
    assert q.description == p.description and q.reference == p.reference
    assert patterns.get(str(path)).equals(p)


def test_toml_written_by_hand(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(
        'name = "stripe"\nlayout = [[0, 1]]\n'
        "[[kernels]]\nR = [[0, 1, 0]]\nG = [[0, 1, 0]]\nB = [[0, 1, 0]]\n"
        "[[kernels]]\nR = [[1, 0, 0]]\nG = [[0, 1, 0]]\nB = [[0, 0.5, 0]]\n"
    )
    p = patterns.load(path)
    assert p.period == (1, 2) and p.num_splitters == 2 and p.absorbs_light
    assert p.kernels[1, 0, 0].tolist() == [1, 0, 0]


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


def test_file_errors(tmp_path):
    with pytest.raises(PatternError, match="not found"):
        patterns.load(tmp_path / "missing.json")
    with pytest.raises(PatternError, match="expected a .json or .toml file, got '.yaml'"):
        patterns.load(tmp_path / "p.yaml")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(PatternError, match="is not valid json"):
        patterns.load(bad)
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text("name = \n")
    with pytest.raises(PatternError, match="is not valid toml"):
        patterns.load(bad_toml)
    invalid = tmp_path / "invalid.json"
    data = _valid()
    data["layout"] = [[0, 9], [2, 3]]
    invalid.write_text(json.dumps(data))
    with pytest.raises(PatternError, match="invalid.json.*layout index 9"):
        patterns.get(str(invalid))


def test_measures_match_hand_computation():
    m = {n: patterns.measure(patterns.get(n)) for n in patterns.names()}
    # D: the red deflector moves all its red (1 of 12 colour-sites of light), the blue one its
    # blue: 2/12 of the incident light leaves its pixel.
    assert m["D"].split_fraction == pytest.approx(2 / 12)
    assert m["D"].spread == pytest.approx(1.0)
    # A: only R at R sites, G at G sites and B at B sites stay: 4 of 12 stay.
    assert m["A"].split_fraction == pytest.approx(8 / 12)
    assert m["A"].spread == pytest.approx(np.sqrt(2))
    # E: 2 of 9 colour-sites of light move (R and B of the splitter pixel).
    assert m["E"].split_fraction == pytest.approx(2 / 9)
    assert m["C"].spread == pytest.approx(2.0)
    assert m["bayer"].efficiency == pytest.approx((0.25, 0.5, 0.25))
    assert m["A"].efficiency == pytest.approx((1.0, 1.0, 1.0))
    assert [n for n in m if m[n].pooling] == ["B", "C"]
    assert m["B"].pooling_unit == 4 and m["C"].pooling_unit == 3
    # A's mean distance travelled, per period: R moves 1 unit by 1 px from each of the two G
    # sites and 1 unit by sqrt2 from the B site; G moves 1 unit by 1 px from the R and B sites;
    # B like R; divided by the 12 units of light.
    travel = (2 * (2 + np.sqrt(2)) + 2) / 12
    assert m["A"].mean_travel == pytest.approx(travel)


def test_low_light_filter_arrays_collect_their_share_of_white_light():
    """SPEC section 14: RGBW collects 2/3 of white light (twice Bayer), Quad Bayer 1/3; counted
    independently here from the layouts' pixel types."""
    import numpy as np

    rgbw, quad, bayer = (patterns.get(n) for n in ("rgbw", "quad", "bayer"))
    assert rgbw.period == quad.period == (4, 4)
    # Half of RGBW's pixels pass all three colours, the other half one.
    passes = rgbw.kernels[rgbw.layout].sum(axis=(-1, -2)).sum(-1)  # colours passed per pixel
    assert (passes == 3).sum() == 8 and (passes == 1).sum() == 8
    assert patterns.measure(rgbw).white == pytest.approx(2 / 3)
    assert patterns.measure(quad).white == pytest.approx(1 / 3)
    assert patterns.measure(bayer).white == pytest.approx(1 / 3)
    assert patterns.measure(patterns.get("A")).white == pytest.approx(1.0)
    # Quad Bayer is Bayer with every pixel doubled in both directions.
    colour = quad.kernels[quad.layout][..., 0, 0].argmax(-1)
    bayer_colour = bayer.kernels[bayer.layout][..., 0, 0].argmax(-1)
    assert np.array_equal(colour, np.kron(bayer_colour, np.ones((2, 2), dtype=int)))


def test_router_model_is_a_with_losses_and_crosstalk():
    """SPEC 15: router(1, 0) is A; every colour's kernel sums to eta + chi (light lost, never
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
