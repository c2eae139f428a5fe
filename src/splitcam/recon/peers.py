"""demosaicnet (Gharbi, Chaurasia, Paris and Durand, "Deep joint demosaicking and denoising",
SIGGRAPH Asia 2016) as a reconstruction method: the GPU-trained peer of our networks.

Its PyPI package (MIT licence) carries the two released networks' weights, for the Bayer and
the X-Trans filter arrays. How they are loaded, and why not through the package:

- The package imports ``pkg_resources`` (gone from recent setuptools) and ``wget`` when it is
  imported, so importing it can fail in a working environment. We never import it: the weight
  files are found through the installed distribution's file list
  (:func:`importlib.metadata.distribution`), and read with ``torch.load(weights_only=True)``,
  which restores tensors only and runs no code from the file.
- The networks are written here as plain modules whose parameters are named as the weight files
  name them (so a strict ``load_state_dict`` checks every tensor). Both use unpadded
  convolutions: the released Bayer network packs each 2x2 cell into 4 channels, applies 15
  convolutions of 64 filters (the last gives 128 channels, 64 filters and 64 masks that are
  multiplied), predicts 12 channels per cell, unpacks them to full resolution by a transposed
  convolution, and adds the mosaic back through a last full-resolution convolution; the X-Trans
  network runs 11 convolutions at full resolution and the same last stage. An output pixel is
  31 (Bayer) or 12 (X-Trans) pixels inside the input's edge.
- Whole images of any size: the mosaic is extended past each edge keeping its layout
  (:func:`~splitcam.recon.extend.extend_mosaic`), so the network sees a mosaic of its own
  layout everywhere and its output covers the image exactly. Images are reconstructed in tiles
  (:func:`~splitcam.recon.tiling.tiled`) so memory stays bounded.
- Phase: the released Bayer network expects the ``GRBG`` phase (green at the top-left, red to
  its right); our ``bayer`` is ``RGGB``. The extension puts an odd number of columns on the
  left, so the padded mosaic starts on a green pixel of a red row: ``GRBG`` exactly.

The released networks demosaick; they take no noise level (the noise-aware ones were not
released in the package): ``sigma`` is checked and ignored, as for the classical methods. They
were trained on sRGB values, so only the ``srgb`` domain is offered.
"""

from __future__ import annotations

import importlib.metadata
from collections import OrderedDict
from pathlib import Path

import numpy as np
import torch
from torch import nn

from ..checks import check_raw
from ..io.domains import SRGB
from ..patterns import Pattern, builtin, get
from ..physics.light import check_domain
from ..physics.noise import check_level
from .extend import extend_mosaic
from .tiling import DEFAULT_TILE, tiled

__all__ = ["DEMOSAICNET_PATTERNS", "Demosaicnet", "PeerUnavailable"]

#: The patterns demosaicnet has released networks for, and their weight files in its package.
DEMOSAICNET_PATTERNS = {"bayer": "bayer.pth", "xtrans": "xtrans.pth"}
INSTALL = "pip install 'splitcam[demosaicnet]'"


class PeerUnavailable(ImportError):
    """A peer method's package is not installed; the message gives the install command."""


def _weights(pattern: str) -> dict[str, torch.Tensor]:
    """The released weights of one network, from the installed package's files."""
    try:
        dist = importlib.metadata.distribution("demosaicnet")
    except importlib.metadata.PackageNotFoundError:
        raise PeerUnavailable(
            f"demosaicnet is not installed; install the optional peer with: {INSTALL}"
        ) from None
    name = f"demosaicnet/data/{DEMOSAICNET_PATTERNS[pattern]}"
    path = Path(str(dist.locate_file(name)))
    if not path.is_file():
        raise PeerUnavailable(f"the demosaicnet package has no {name}; reinstall it: {INSTALL}")
    return torch.load(path, map_location="cpu", weights_only=True)


def _conv_stack(first: int, depth: int, width: int, last: int) -> nn.Sequential:
    layers: OrderedDict[str, nn.Module] = OrderedDict()
    for i in range(depth):
        n_in = first if i == 0 else width
        n_out = last if i == depth - 1 else width
        layers[f"conv{i + 1}"] = nn.Conv2d(n_in, n_out, 3)
        layers[f"relu{i + 1}"] = nn.ReLU()
    return nn.Sequential(layers)


def _last_stage(n_in: int, width: int) -> nn.Sequential:
    return nn.Sequential(
        OrderedDict(
            [
                ("post_conv", nn.Conv2d(n_in, width, 3)),
                ("post_relu", nn.ReLU()),
                ("output", nn.Conv2d(width, 3, 1)),
            ]
        )
    )


def _centre(x: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """``x`` cut to ``like``'s height and width, the surplus split evenly (the extra pixel of
    an odd surplus at the bottom and right)."""
    dh, dw = x.shape[-2] - like.shape[-2], x.shape[-1] - like.shape[-1]
    return x[..., dh // 2 : x.shape[-2] - (dh - dh // 2), dw // 2 : x.shape[-1] - (dw - dw // 2)]


class _BayerNetwork(nn.Module):
    """The released Bayer network (GRBG mosaic as 3 channels in, RGB out, 31 pixels smaller on
    each side)."""

    MARGIN = 31
    WIDTH = 64

    def __init__(self) -> None:
        super().__init__()
        layers = _conv_stack(4, 15, self.WIDTH, 2 * self.WIDTH)
        self.main_processor = nn.Sequential(
            OrderedDict([("pack_mosaic", nn.Conv2d(3, 4, 2, stride=2)), *layers.named_children()])
        )
        self.residual_predictor = nn.Conv2d(self.WIDTH, 12, 1)
        self.upsampler = nn.ConvTranspose2d(12, 3, 2, stride=2, groups=3)
        self.fullres_processor = _last_stage(6, self.WIDTH)

    def forward(self, mosaic: torch.Tensor) -> torch.Tensor:
        features = self.main_processor(mosaic)
        filtered = features[:, : self.WIDTH] * features[:, self.WIDTH :]
        upsampled = self.upsampler(self.residual_predictor(filtered))
        return self.fullres_processor(torch.cat([_centre(mosaic, upsampled), upsampled], 1))


class _XTransNetwork(nn.Module):
    """The released X-Trans network (mosaic as 3 channels in, RGB out, 12 pixels smaller on
    each side)."""

    MARGIN = 12
    WIDTH = 64

    def __init__(self) -> None:
        super().__init__()
        self.main_processor = _conv_stack(3, 11, self.WIDTH, self.WIDTH)
        self.fullres_processor = _last_stage(3 + self.WIDTH, self.WIDTH)

    def forward(self, mosaic: torch.Tensor) -> torch.Tensor:
        features = self.main_processor(mosaic)
        return self.fullres_processor(torch.cat([_centre(mosaic, features), features], 1))


class Demosaicnet:
    """demosaicnet's released network of a filter array as a reconstruction method.

    Args:
        pattern: ``bayer`` or ``xtrans`` (:data:`DEMOSAICNET_PATTERNS`), a name or a pattern.
        tile: Tile size in pixels (``None``: whole images at once).
        domain: Only ``srgb``: the networks were trained on sRGB values.

    Raises:
        ValueError: Another pattern (the message names the two it has), or another domain.
        PeerUnavailable: The ``demosaicnet`` package is not installed (the message gives the
            install command).
    """

    def __init__(
        self,
        pattern: str | Pattern = "bayer",
        *,
        tile: int | None = DEFAULT_TILE,
        domain: str = SRGB,
        name: str | None = None,
    ) -> None:
        resolved = get(pattern)  # a constructor users call: names and files read here
        key = resolved.name.lower()
        if key not in DEMOSAICNET_PATTERNS or not resolved.equals(builtin(key)):
            raise ValueError(
                f"demosaicnet has released networks for the {' and '.join(DEMOSAICNET_PATTERNS)} "
                f"patterns only, got {resolved.name!r}"
            )
        if check_domain(domain) != SRGB:
            raise ValueError(
                "demosaicnet was trained on sRGB values; it reconstructs only the srgb domain"
            )
        self.pattern = resolved
        self.domain = SRGB
        self.name = name or f"{key}+demosaicnet"
        self.tile = tile
        network = _BayerNetwork() if key == "bayer" else _XTransNetwork()
        network.load_state_dict(_weights(key))
        self.network = network.eval().requires_grad_(False)
        # Colour site (0 R, 1 G, 2 B) of each pixel of the period.
        filters = resolved.kernels[:, :, 0, 0]
        self._sites = torch.from_numpy(np.argmax(filters[resolved.layout], axis=-1))
        # Bayer: an odd number of columns on the left turns our RGGB into the network's GRBG.
        self._left = network.MARGIN
        self._top = network.MARGIN + (1 if key == "bayer" else 0)
        #: How far a mosaic pixel reaches into the output (for tiling).
        self.radius = network.MARGIN + 2

    def reconstruct(self, raw: torch.Tensor, sigma: float = 0.0) -> torch.Tensor:
        """Demosaic each image of the batch in tiles (``sigma`` is checked, then ignored).

        Shape:
            - raw: ``(N, 1, H, W)`` mosaic of the pattern, its period starting at (0, 0).
            - output: ``(N, 3, H, W)``, same dtype and device as ``raw``.
        """
        check_raw(raw)
        check_level(sigma)
        return tiled(self.demosaic, raw, self.pattern.period, self.radius, tile=self.tile)

    def demosaic(self, raw: torch.Tensor) -> torch.Tensor:
        """Demosaic whole images at once (what :meth:`reconstruct` applies to each tile)."""
        h, w = raw.shape[-2:]
        ph, pw = self.pattern.period
        margin = self.network.MARGIN
        # Padded sides: at least the margin past the far edges, and even for Bayer's packing.
        bottom = margin + (h + self._top + margin) % 2 if ph == 2 else margin
        right = margin + (w + self._left + margin) % 2 if pw == 2 else margin
        # The network runs where the raw image is, in the float32 of its weights.
        dev = raw.device
        values = extend_mosaic(
            raw.detach().float()[:, 0], (self._top, bottom, self._left, right), (ph, pw)
        )
        hp, wp = values.shape[-2:]
        # The colour site of each padded pixel: the period's layout, from the padded origin.
        rows = (torch.arange(hp, device=dev) - self._top).remainder(ph)
        cols = (torch.arange(wp, device=dev) - self._left).remainder(pw)
        site = self._sites.to(dev)[rows][:, cols]
        mosaic = torch.stack([values * (site == c) for c in range(3)], dim=1)
        with torch.inference_mode():
            out = self.network.to(dev)(mosaic)
        # Output pixel (i, j) lies at padded (i + margin, j + margin).
        top, left = self._top - margin, self._left - margin
        return out[:, :, top : top + h, left : left + w].to(dtype=raw.dtype)

    def __repr__(self) -> str:
        return f"Demosaicnet({self.pattern.name!r})"
