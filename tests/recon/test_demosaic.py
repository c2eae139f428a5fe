"""Classical demosaicking (splitcam.recon.demosaic): the package's methods, exactly, on a mosaic
extended past its edges keeping its layout; right at every pixel of the border; and their
radius."""

from __future__ import annotations

import math

import colour_demosaicing as cd
import numpy as np
import pytest
import torch

from splitcam.evaluation.metrics import psnr
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.base import Reconstructor as Method
from splitcam.recon.demosaic import ClassicalDemosaic
from splitcam.recon.tiling import tiled


def _smooth_images(n: int, h: int, w: int, seed: int) -> torch.Tensor:
    """Random images with some spatial correlation (a 3x3 box blur of uniform noise)."""
    gen = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, h + 2, w + 2, generator=gen, dtype=torch.float64)
    return torch.nn.functional.avg_pool2d(x, 3, stride=1)


def test_bayer_raw_is_the_rggb_mosaic_exactly():
    rgb = torch.rand(2, 3, 7, 10, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    raw = SplitterSensor("bayer")(rgb)
    for n in range(2):
        mosaic = cd.mosaicing_CFA_Bayer(rgb[n].permute(1, 2, 0).numpy(), "RGGB")
        assert torch.equal(raw[n, 0], torch.from_numpy(mosaic))


@pytest.mark.parametrize("method", ClassicalDemosaic.METHODS)
def test_classical_demosaic_equals_the_package(method):
    rgb = _smooth_images(2, 16, 20, seed=2)
    raw = SplitterSensor("bayer")(rgb)
    demosaic = ClassicalDemosaic(method)
    out = demosaic.reconstruct(raw, 0.0)
    function = getattr(
        cd,
        {
            "bilinear": "demosaicing_CFA_Bayer_bilinear",
            "malvar2004": "demosaicing_CFA_Bayer_Malvar2004",
            "menon2007": "demosaicing_CFA_Bayer_Menon2007",
        }[method],
    )
    m = 2 * ((demosaic.radius + 2) // 2)
    for n in range(2):
        mosaic = cd.mosaicing_CFA_Bayer(rgb[n].permute(1, 2, 0).numpy(), "RGGB")
        # For a 2x2 period numpy's mirror (edge pixel not repeated) keeps the layout.
        extended = np.pad(mosaic, m, mode="reflect")
        expected = torch.from_numpy(function(extended, "RGGB")[m:-m, m:-m]).permute(2, 0, 1)
        assert torch.equal(out[n], expected)
        # Inside, out of the border's reach, the package's own result on the image.
        inner = torch.from_numpy(function(mosaic, "RGGB")).permute(2, 0, 1)
        r = demosaic.radius + 1
        assert torch.equal(out[n, :, r:-r, r:-r], inner[:, r:-r, r:-r])
    assert out.dtype == torch.float64
    # sigma is ignored: no denoising.
    assert torch.equal(demosaic.reconstruct(raw, 25.0), out)
    assert demosaic.reconstruct(raw.float(), 0).dtype == torch.float32
    assert isinstance(demosaic, Method) and demosaic.pattern.name == "bayer"


def test_bilinear_on_a_smooth_image():
    yy, xx = torch.meshgrid(torch.arange(64.0), torch.arange(64.0), indexing="ij")
    rgb = torch.stack(
        [
            0.5 + 0.3 * torch.sin(2 * math.pi * xx / 40),
            0.5 + 0.3 * torch.cos(2 * math.pi * yy / 50),
            0.5 + 0.2 * torch.sin(2 * math.pi * (xx + yy) / 60),
        ]
    ).double()
    out = ClassicalDemosaic("bilinear").reconstruct(SplitterSensor("bayer")(rgb[None]), 0)
    # The border is held to the bound of the inside, less a little: the mirror extension
    # gives the edge pixels neighbours of their own colour sites (the package's own border
    # handling gave errors up to 0.6 there).
    assert psnr(out[0], rgb, crop=2) > 45
    assert psnr(out[0], rgb) > 40


def test_unknown_demosaic_method():
    with pytest.raises(ValueError, match="bilinear, malvar2004, menon2007.*'ahd'"):
        ClassicalDemosaic("ahd")


def _mosaic(size: tuple[int, int], seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(1, 1, *size, generator=g, dtype=torch.float64)


@pytest.mark.parametrize("method", ClassicalDemosaic.METHODS)
def test_demosaic_radius_is_exact_both_ways(method) -> None:
    """Tiles overlapping by the documented radius reproduce the whole image exactly; one pixel
    less does not; and one changed mosaic pixel changes nothing farther than the radius."""
    demosaic = ClassicalDemosaic(method, tile=None)
    radius = demosaic.radius
    raw = _mosaic((64, 72), 1)
    whole = demosaic.demosaic(raw)
    tile = 24 + 2 * radius
    out = tiled(demosaic.demosaic, raw, (2, 2), radius, tile=tile, overlap=radius)
    torch.testing.assert_close(out, whole, rtol=0, atol=0)
    if radius > 1:
        short = tiled(demosaic.demosaic, raw, (2, 2), radius - 1, tile=tile, overlap=radius - 1)
        assert not torch.equal(short, whole)
    # Reach: poke one pixel of each phase of the period in the middle, see how far the output
    # changes (it differs between phases: menon2007 reaches 6, 4, 7 and 6 pixels).
    reach = 0
    for dy in (0, 1):
        for dx in (0, 1):
            y, x = 32 + dy, 36 + dx
            poked = raw.clone()
            poked[0, 0, y, x] += 0.5
            diff = (demosaic.demosaic(poked) - whole).abs().amax(1)[0]
            ys, xs = torch.nonzero(diff > 0, as_tuple=True)
            reach = max(reach, int(torch.maximum((ys - y).abs(), (xs - x).abs()).max()))
    assert reach <= radius
    assert method == "bilinear" or reach >= radius - 1  # the radius is not loose either


@pytest.mark.parametrize("method", ClassicalDemosaic.METHODS)
@pytest.mark.parametrize("size", [(1, 1), (9, 1), (1, 9), (1, 2), (2, 1), (2, 2), (5, 3), (7, 8)])
def test_recorded_values_kept_at_their_sites_and_flat_colour_exact(method, size) -> None:
    """At its own colour site every pixel keeps its recorded value, border and corners
    included, for images as small as one pixel; and a flat colour comes back exactly at every
    pixel wherever the image holds all three sites. (The package's mirror broke the mosaic's
    layout at the border: bilinear scaled edge pixels by 1.5 and corners by 2.25, a 1x1 red
    0.851 became 1.915.)"""
    raw = torch.rand(2, 1, *size, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    out = ClassicalDemosaic(method).reconstruct(raw)
    assert out.shape == (2, 3, *size) and torch.isfinite(out).all()
    colour = [[0, 1], [1, 2]]  # RGGB
    for i in range(size[0]):
        for j in range(size[1]):
            torch.testing.assert_close(out[:, colour[i % 2][j % 2], i, j], raw[:, 0, i, j])
    if min(size) >= 2:
        flat = torch.tensor([0.8, 0.4, 0.2], dtype=torch.float64).view(1, 3, 1, 1)
        scene = flat.expand(1, 3, *size)
        back = ClassicalDemosaic(method).reconstruct(SplitterSensor("bayer")(scene))
        torch.testing.assert_close(back, scene, rtol=0, atol=1e-12)
