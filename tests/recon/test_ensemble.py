"""Test-time flips (splitcam.recon.ensemble): exact symmetries of a sensor, and the average."""

from __future__ import annotations

import pytest
import torch

from splitcam import patterns
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.ensemble import TRANSFORMS, SelfEnsemble, symmetries


def test_every_transform_is_undone_by_its_inverse() -> None:
    x = torch.rand(2, 3, 5, 7)
    for g in TRANSFORMS:
        assert torch.equal(g.invert(g.apply(x)), x)
    assert len({g.label for g in TRANSFORMS}) == 8


@pytest.mark.parametrize("name", ["A", "B", "C", "D", "E", "bayer", "rgbw", "router-zou"])
@pytest.mark.parametrize("size", [(24, 24), (23, 31), (26, 21), (25, 24)])
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
