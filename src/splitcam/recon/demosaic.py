"""Classical demosaicking of the Bayer pattern, through the ``colour-demosaicing`` package.

Our ``bayer`` raw image is exactly the standard RGGB mosaic, so the published algorithms apply
unchanged. They interpolate and do not denoise.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from ..patterns import get
from .base import check_raw, check_sigma

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

    Args:
        method: One of ``bilinear``, ``malvar2004``, ``menon2007`` (case-insensitive).

    Raises:
        ValueError: Unknown method; the message lists the valid names.
    """

    METHODS = ("bilinear", "malvar2004", "menon2007")

    def __init__(self, method: str) -> None:
        key = str(method).strip().lower()
        if key not in self.METHODS:
            raise ValueError(
                f"expected a demosaicking method among {', '.join(self.METHODS)}, got {method!r}"
            )
        self.name = key
        self.pattern = get("bayer")
        self._function = _demosaic_functions()[key]

    def reconstruct(self, raw: torch.Tensor, sigma: float = 0.0) -> torch.Tensor:
        """Demosaic each image of the batch (``sigma`` is checked, then ignored).

        Shape:
            - raw: ``(N, 1, H, W)``, the RGGB mosaic (R at (0, 0)).
            - output: ``(N, 3, H, W)``, same dtype and device as ``raw``.
        """
        check_raw(raw)
        check_sigma(sigma)
        cfa = raw.detach().cpu().double().numpy()
        # The package works in float64 on (H, W) arrays and returns (H, W, 3).
        out = np.stack([self._function(cfa[n, 0], "RGGB") for n in range(cfa.shape[0])])
        rgb = torch.from_numpy(np.ascontiguousarray(out.transpose(0, 3, 1, 2)))
        return rgb.to(device=raw.device, dtype=raw.dtype)

    def __repr__(self) -> str:
        return f"ClassicalDemosaic({self.name!r})"


