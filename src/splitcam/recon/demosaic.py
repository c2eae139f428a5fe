"""Classical demosaicking of the Bayer pattern, through the ``colour-demosaicing`` package.

Our ``bayer`` raw image is exactly the standard RGGB mosaic, so the published algorithms apply
unchanged. They interpolate and do not denoise. Images are demosaicked in tiles
(:func:`splitcam.recon.tiling.tiled`) so that the package's float64 intermediates stay small on
large images; the tiled result equals the whole-image one exactly.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from ..checks import check_raw
from ..io.domains import SRGB
from ..patterns import builtin
from ..physics.light import check_domain
from ..physics.noise import check_level
from .extend import extend_mosaic
from .tiling import DEFAULT_TILE, tiled

__all__ = ["ClassicalDemosaic"]


def _demosaic_functions() -> dict[str, Callable[..., np.ndarray]]:
    import colour_demosaicing as cd

    return {
        "bilinear": cd.demosaicing_CFA_Bayer_bilinear,
        "malvar2004": cd.demosaicing_CFA_Bayer_Malvar2004,
        "menon2007": cd.demosaicing_CFA_Bayer_Menon2007,
    }


class ClassicalDemosaic:
    """Classical demosaicking of the ``bayer`` pattern (RGGB) with ``colour-demosaicing``.

    ``bilinear`` is ``demosaicing_CFA_Bayer_bilinear``, ``malvar2004`` is
    ``demosaicing_CFA_Bayer_Malvar2004`` (Malvar, He & Cutler 2004) and ``menon2007`` is
    ``demosaicing_CFA_Bayer_Menon2007`` (Menon, Andriani & Calvagno 2007, with its refining
    step). These algorithms interpolate and do not denoise: ``sigma`` is ignored, so at
    ``sigma > 0`` they pass the noise (and its demosaicking artefacts) straight through.

    The image is demosaicked in tiles of ``tile`` pixels that start on whole Bayer cells and
    overlap by :attr:`RADIUS` (rounded up to whole cells), the farthest any mosaic pixel reaches
    into the output. At image edges the mosaic is extended keeping its RGGB layout
    (:func:`~splitcam.recon.extend.extend_mosaic`; the package's own mirror breaks the layout),
    so the result equals demosaicking the whole image exactly, and a pixel at the edge keeps its
    recorded value at its own colour site.

    Args:
        method: One of ``bilinear``, ``malvar2004``, ``menon2007`` (case-insensitive).
        tile: Tile size in pixels; ``None`` demosaics whole images at once.
        name: Label in tables (default: the method's name).
        domain: The light domain of the raw images (fixed interpolation works in either).

    Raises:
        ValueError: Unknown method (the message lists the valid names) or domain.
    """

    METHODS = ("bilinear", "malvar2004", "menon2007")

    #: How far (Chebyshev distance, pixels) a mosaic pixel can change the output. Bilinear and
    #: Malvar-He-Cutler are single 3x3 and 5x5 convolutions. Menon2007 chains filters: the
    #: directional green (5 taps) and the direction decision (a 5x5 sum of differences of pixels 2
    #: apart) reach 4, the red/blue interpolation adds 2 (two 3-tap steps) and the refining step
    #: 2 more, so 8. Tests confirm each value both ways: tiles overlapping by the radius
    #: reproduce the whole-image result exactly, tiles overlapping by one pixel less do not; and
    #: changing one mosaic pixel of random mosaics never changes an output farther away.
    RADIUS = {"bilinear": 1, "malvar2004": 2, "menon2007": 8}

    #: What, beyond the method's name, tells its stored results apart
    #: (:func:`~splitcam.evaluation.protocol.method_fingerprint`): the rule at the image's edges.
    #: Change it with any change to the output, so that results computed before are recomputed
    #: on resume instead of kept beside new ones.
    fingerprint = "edges: the mosaic extended keeping its RGGB layout"

    def __init__(
        self,
        method: str,
        *,
        tile: int | None = DEFAULT_TILE,
        name: str | None = None,
        domain: str = SRGB,
    ) -> None:
        key = str(method).strip().lower()
        if key not in self.METHODS:
            raise ValueError(
                f"expected a demosaicking method among {', '.join(self.METHODS)}, got {method!r}"
            )
        self.name = name or key
        self.domain = check_domain(domain)
        self.pattern = builtin("bayer")
        self.radius = self.RADIUS[key]
        self.tile = tile
        self._function = _demosaic_functions()[key]

    def reconstruct(self, raw: torch.Tensor, sigma: float = 0.0) -> torch.Tensor:
        """Demosaic each image of the batch in tiles (``sigma``, a Gaussian sigma or a photon-model
        :class:`~splitcam.physics.noise.Exposure`, is checked, then ignored).

        Shape:
            - raw: ``(N, 1, H, W)``, the RGGB mosaic (R at (0, 0)).
            - output: ``(N, 3, H, W)``, same dtype and device as ``raw``.
        """
        check_raw(raw)
        check_level(sigma)
        return tiled(self.demosaic, raw, self.pattern.period, self.radius, tile=self.tile)

    def demosaic(self, raw: torch.Tensor) -> torch.Tensor:
        """Demosaic whole images at once (what :meth:`reconstruct` applies to each tile).

        Shape:
            - raw: ``(N, 1, H, W)``, the RGGB mosaic (R at (0, 0)).
            - output: ``(N, 3, H, W)``, same dtype and device as ``raw``.
        """
        height, width = raw.shape[-2:]
        # The package mirrors the mosaic about its edge pixel (scipy's ``reflect``), which puts
        # a red pixel where a green one belongs: bilinear borders came out up to 2.25 times too
        # bright. So the mosaic is first extended past every edge keeping the RGGB layout
        # (an even margin beyond the method's reach), and the result cut back; the package's
        # own border handling then only touches pixels that are cut away. This also keeps
        # images of one-pixel sides from losing an axis in the package's squeeze.
        m = 2 * ((self.radius + 2) // 2)
        cfa = extend_mosaic(raw.detach().cpu().double(), (m, m, m, m), self.pattern.period)
        cfa = cfa.numpy()
        # The package works in float64 on (H, W) arrays and returns (H, W, 3).
        out = np.stack([self._function(cfa[n, 0], "RGGB") for n in range(cfa.shape[0])])
        out = out[:, m : m + height, m : m + width]
        rgb = torch.from_numpy(np.ascontiguousarray(out.transpose(0, 3, 1, 2)))
        return rgb.to(device=raw.device, dtype=raw.dtype)

    def __repr__(self) -> str:
        return f"ClassicalDemosaic({self.name!r})"
