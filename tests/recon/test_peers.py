"""demosaicnet as a method (splitcam.recon.peers): our modules against the package's own code on
its own mosaics, the Bayer phase mapped exactly (a known mosaic), whole images of any size, and
one clear line for what it cannot do."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.extend import mirror_index
from splitcam.recon.peers import Demosaicnet, PeerUnavailable
from splitcam.recon.registry import build_method

try:
    importlib.metadata.distribution("demosaicnet")
    HAVE = True
except importlib.metadata.PackageNotFoundError:
    HAVE = False
needs = pytest.mark.skipif(not HAVE, reason="demosaicnet is not installed (splitcam[demosaicnet])")


def _package_module(name: str) -> types.ModuleType:
    """One module of the demosaicnet package, loaded from its file with a stand-in for the
    ``pkg_resources`` it imports (the package's own __init__ is not run)."""
    dist = importlib.metadata.distribution("demosaicnet")
    path = Path(str(dist.locate_file(f"demosaicnet/{name}.py")))
    stub = types.ModuleType("pkg_resources")
    stub.resource_filename = lambda package, rel: str(path.parent / rel)  # type: ignore[attr-defined]
    saved = sys.modules.get("pkg_resources")
    sys.modules["pkg_resources"] = stub
    try:
        spec = importlib.util.spec_from_file_location(f"_demosaicnet_{name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        if saved is None:
            del sys.modules["pkg_resources"]
        else:
            sys.modules["pkg_resources"] = saved
    return module


def _scene(h: int, w: int, seed: int = 0) -> torch.Tensor:
    """A smooth colourful scene with some edges, ``(1, 3, h, w)`` in [0, 1]."""
    y, x = torch.meshgrid(torch.linspace(0, 1, h), torch.linspace(0, 1, w), indexing="ij")
    g = torch.Generator().manual_seed(seed)
    phase = torch.rand(3, generator=g) * 6
    img = torch.stack([0.5 + 0.4 * torch.sin(5 * x + 3 * y + p) for p in phase])
    img[:, h // 3 : h // 2, w // 4 :] = torch.tensor([0.9, 0.2, 0.1]).view(3, 1, 1)
    return img[None]


@needs
@pytest.mark.parametrize("kind", ["bayer", "xtrans"])
def test_our_networks_are_the_packages_on_its_own_mosaics(kind) -> None:
    """Their code, their weights, their mosaic layout and unpadded convolutions, against our
    module with the same weights: the same output."""
    modules, mosaic_of = _package_module("modules"), _package_module("mosaic")
    theirs = (modules.BayerDemosaick if kind == "bayer" else modules.XTransDemosaick)()
    ours = Demosaicnet(kind, tile=None).network
    img = _scene(72, 66)[0]
    mosaic = (mosaic_of.bayer if kind == "bayer" else mosaic_of.xtrans)(img.clone())[None]
    with torch.no_grad():
        torch.testing.assert_close(ours(mosaic), theirs.eval()(mosaic), rtol=0, atol=1e-5)


@needs
def test_bayer_phase_is_mapped_exactly() -> None:
    """A flat colour through our RGGB sensor comes back as that colour at every pixel, edges
    included; the same mosaic read one column off (the network's GRBG taken as ours) does not."""
    colour = torch.tensor([0.8, 0.45, 0.15])
    scene = colour.view(1, 3, 1, 1).expand(1, 3, 20, 23).contiguous()
    raw = SplitterSensor(patterns.get("bayer"))(scene)
    method = Demosaicnet("bayer")
    out = method.reconstruct(raw)
    assert out.shape == scene.shape
    assert float((out - scene).abs().max()) < 0.02
    # The phase mistaken: the network reads R and B sites as green ones and vice versa.
    shifted = method.demosaic(raw[..., :, 1:])
    assert float((shifted - scene[..., :, 1:]).abs().max()) > 0.1


@needs
@pytest.mark.parametrize("kind", ["bayer", "xtrans"])
@pytest.mark.parametrize("size", [(1, 1), (5, 7), (37, 41), (151, 143)])
def test_whole_images_of_any_size_and_tiles(kind, size) -> None:
    pattern = patterns.get(kind)
    scene = _scene(*size)
    raw = SplitterSensor(pattern)(scene)
    whole = Demosaicnet(kind, tile=None).reconstruct(raw)
    assert whole.shape == scene.shape and torch.isfinite(whole).all()
    if min(size) >= 30:
        err = float((whole.clamp(0, 1) - scene).square().mean())
        assert 10 * np.log10(1 / err) > 30  # a smooth scene comes back well
    if min(size) > 80:  # tiles of 80 with the method's overlap: the whole image's result
        tiled = Demosaicnet(kind, tile=80).reconstruct(raw)
        torch.testing.assert_close(tiled, whole, rtol=0, atol=1e-5)


def test_mirror_index_keeps_the_phase() -> None:
    for size, period in [(10, 2), (13, 6), (7, 3), (2, 6)]:
        index = mirror_index(size, 9, 8, period)
        positions = np.arange(-9, size + 8)
        inside = (positions >= 0) & (positions < size)
        assert (index[inside] == positions[inside]).all()
        found = index >= 0
        assert (index[found] % period == positions[found] % period).all()
        assert (index < size).all()
        # Absent only where the image holds no pixel of that phase.
        present = set(range(min(size, period)))
        assert all((p % period in present) == f for p, f in zip(positions, found, strict=True))
    # Period 2: numpy's mirror.
    np.testing.assert_array_equal(
        mirror_index(10, 5, 6, 2), np.pad(np.arange(10), (5, 6), mode="reflect")
    )


@needs
def test_registry_and_bad_input() -> None:
    method = build_method("demosaicnet")
    assert method.name == "bayer+demosaicnet" and method.pattern.name == "bayer"
    assert build_method("demosaicnet", pattern="xtrans").name == "xtrans+demosaicnet"
    with pytest.raises(ValueError, match="bayer and xtrans patterns only, got 'D'"):
        build_method("demosaicnet", pattern="D")
    with pytest.raises(ValueError, match="only the srgb domain"):
        build_method("demosaicnet", domain="linear")


def test_missing_package_names_the_install_command(monkeypatch) -> None:
    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "distribution", missing)
    with pytest.raises(PeerUnavailable, match=r"pip install 'splitcam\[demosaicnet\]'"):
        Demosaicnet("bayer")
