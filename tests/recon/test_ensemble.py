"""Test-time flips (splitcam.recon.ensemble): exact symmetries of a sensor, and the average."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.patterns.random import random_pattern
from splitcam.physics.sensor import SplitterSensor, pattern_pixel_kernels
from splitcam.recon.base import NetworkReconstructor
from splitcam.recon.ensemble import (
    TRANSFORMS,
    SelfEnsemble,
    symmetries,
    transformed,
    with_flips,
)
from splitcam.recon.networks import UniversalReconNet

SIZES = [(24, 24), (23, 31), (26, 21), (25, 24)]


def _patterns_to_test() -> list[patterns.Pattern]:
    """The library (periods 1x3 to 4x4, kernels 1x1 to 3x3) and random draws (up to 4x4 and
    5x5, filters, routers and scatterers)."""
    rng = np.random.default_rng(11)
    return [patterns.get(n) for n in ("A", "C", "D", "E", "rgbw")] + [
        random_pattern(rng) for _ in range(6)
    ]


def test_every_transform_is_undone_by_its_inverse() -> None:
    x = torch.rand(2, 3, 5, 7)
    for g in TRANSFORMS:
        assert torch.equal(g.invert(g.apply(x)), x)
    assert len({g.label for g in TRANSFORMS}) == 8


@pytest.mark.parametrize("name", ["A", "B", "C", "D", "E", "bayer", "rgbw", "router-zou"])
@pytest.mark.parametrize("size", SIZES)
def test_symmetries_are_exactly_those_the_sensor_commutes_with(name, size) -> None:
    """On a whole random image of the size itself (not the probe): the sensor commutes with
    every transform returned and with none of the others."""
    pattern = patterns.get(name)
    sensor = SplitterSensor(pattern).double()
    x = torch.rand(1, 3, *size, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    found = symmetries(pattern, *size)
    assert found[0].label == "id"
    for g in TRANSFORMS:
        lhs, rhs = sensor(g.apply(x)), g.apply(sensor(x))
        commutes = lhs.shape == rhs.shape and torch.allclose(lhs, rhs, rtol=0, atol=1e-12)
        assert commutes == (g in found), (name, size, g.label)


def test_bayer_on_even_sides_has_only_its_diagonal_and_on_odd_sides_all_eight() -> None:
    bayer = patterns.get("bayer")
    assert [g.label for g in symmetries(bayer, 512, 768)] == ["id", "T"]
    assert len(symmetries(bayer, 321, 481)) == 8
    assert [g.label for g in symmetries(patterns.get("D"), 512, 768)] == ["id"]


def test_the_ensemble_averages_each_transformed_estimate_mapped_back() -> None:
    """A method whose estimate is the row index: averaged with its transposition (the only
    symmetry of Bayer on a 4x6 image), the row index mapped back is the column index."""

    class Rows:
        name = "rows"
        pattern = patterns.get("bayer")
        domain = "linear"
        fingerprint = "r1"

        def reconstruct(self, raw, sigma):
            h, w = raw.shape[-2:]
            return torch.arange(h, dtype=torch.float32)[:, None].expand(1, 3, h, w).clone()

    ensemble = SelfEnsemble(Rows())
    assert (ensemble.name, ensemble.domain, ensemble.fingerprint) == (
        "rows+flips",
        "linear",
        "r1+flips",
    )
    out = ensemble.reconstruct(torch.zeros(1, 1, 4, 6), 0.0)
    rows = torch.arange(4.0)[:, None].expand(4, 6)
    cols = torch.arange(6.0)[None, :].expand(4, 6)
    # a 4x6 image transposed is 6x4: the method sees 6 rows, its row index is the column here
    assert torch.equal(out[0, 0], (rows + cols) / 2)
    # D has no symmetry on even sides: the ensemble is the method itself
    Rows.pattern = patterns.get("D")
    assert torch.equal(SelfEnsemble(Rows()).reconstruct(torch.zeros(1, 1, 4, 6), 0.0)[0, 0], rows)


@pytest.mark.parametrize("size", SIZES)
def test_the_transformed_pattern_records_the_transformed_scene(size) -> None:
    """sensor'(g(x)) = g(sensor(x)) on a whole random image, for every transform, pattern and
    size (odd sides, sides ending part-way through the period): simulated on both sides."""
    x = torch.rand(1, 3, *size, generator=torch.Generator().manual_seed(5), dtype=torch.float64)
    for pattern in _patterns_to_test():
        raw = SplitterSensor(pattern).double()(x)
        for g in TRANSFORMS:
            other = transformed(pattern, g, *size)
            lhs = SplitterSensor(other).double()(g.apply(x))
            assert torch.allclose(lhs, g.apply(raw), rtol=0, atol=1e-12), (pattern.name, g.label)


@pytest.mark.parametrize("size", SIZES)
def test_a_pattern_is_its_own_transform_exactly_under_its_symmetries(size) -> None:
    for pattern in _patterns_to_test():
        own = pattern_pixel_kernels(pattern)
        for g in TRANSFORMS:
            moved = pattern_pixel_kernels(transformed(pattern, g, *size))
            same = moved.shape == own.shape and torch.allclose(moved, own, rtol=0, atol=1e-12)
            assert same == (g in symmetries(pattern, *size)), (pattern.name, size, g.label)


def _any_pattern_method(pattern: patterns.Pattern) -> NetworkReconstructor:
    """A small network of any pattern with random weights (far from equivariant), as the
    registry builds one for a pattern it is told."""
    torch.manual_seed(0)
    net = UniversalReconNet(features=8, blocks=1).eval()
    with torch.no_grad():
        for param in net.parameters():  # its last layer starts at zero: make every layer count
            param.add_(0.05 * torch.randn_like(param))
    method = NetworkReconstructor(net, pattern, "u", tile=None, precision="fp32")
    method.any_pattern = True
    return method


@pytest.mark.parametrize("size", [(21, 26), (24, 24)])
def test_a_network_of_any_pattern_gets_all_eight_looks_and_its_ensemble_is_equivariant(size):
    """Each look is told its own pattern, so the average over the group is exactly
    equivariant: the ensemble of g(raw) with the transformed pattern is g of the ensemble of
    raw, which holds only if every transformed pattern (and their composition) is right."""
    pattern = random_pattern(np.random.default_rng(3), max_period=4, max_kernel=5)
    method = _any_pattern_method(pattern)
    ensemble = SelfEnsemble(method, every_look=True)
    assert ensemble.name == "u+all-flips"
    assert [g.label for g, _ in ensemble.looks(*size)] == [g.label for g in TRANSFORMS]
    exact = [g.label for g in symmetries(pattern, *size)]
    assert [g.label for g, _ in SelfEnsemble(method).looks(*size)] == exact  # the default
    x = torch.rand(1, 3, *size, generator=torch.Generator().manual_seed(2))
    raw = SplitterSensor(pattern)(x)
    out = ensemble.reconstruct(raw, 5.0)
    plain = method.reconstruct(raw, 5.0)
    assert (out - plain).abs().max() > 1e-3  # the looks differ: the network is not equivariant
    for g in TRANSFORMS[1:]:
        moved = SelfEnsemble(method.for_pattern(transformed(pattern, g, *size)), every_look=True)
        assert torch.allclose(moved.reconstruct(g.apply(raw), 5.0), g.apply(out), atol=1e-5)


def test_a_network_of_one_pattern_keeps_to_its_symmetries() -> None:
    method = _any_pattern_method(patterns.get("bayer"))
    method.any_pattern = False  # e.g. a universal network fine-tuned on bayer
    ensemble = SelfEnsemble(method, every_look=True)
    assert [g.label for g, _ in ensemble.looks(512, 768)] == ["id", "T"]
    assert ensemble.name == "u+flips"
    with pytest.raises(ValueError, match="own pattern"):
        method.for_pattern(patterns.get("D"))


def test_the_looks_of_a_network_of_any_pattern_are_built_once_per_phase() -> None:
    """The retargeted methods depend only on where the image ends within the period: two
    sizes with the same remainders share them, another remainder gets its own."""
    ensemble = SelfEnsemble(_any_pattern_method(patterns.get("E")), every_look=True)  # 1x3
    first = ensemble.looks(21, 26)
    assert ensemble.looks(24, 32) is first
    assert ensemble.looks(21, 27) is not first
    assert len(first) == len(ensemble.looks(21, 27)) == 8


def test_with_flips_wraps_the_networks_only() -> None:
    network = _any_pattern_method(patterns.get("D"))

    class Lmmse:
        name, pattern = "lmmse", patterns.get("D")

    lmmse = Lmmse()
    assert with_flips([network, lmmse], None) == [network, lmmse]
    exact, kept = with_flips([network, lmmse], "exact")
    assert (exact.name, exact.every_look, kept) == ("u+flips", False, lmmse)
    assert with_flips([network], "all")[0].name == "u+all-flips"
    with pytest.raises(ValueError, match="unknown flips"):
        with_flips([network], "some")
