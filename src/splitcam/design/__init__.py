"""Pattern design: optimise a pattern's kernels (:mod:`.kernels`, for the closed-form LMMSE or a
frozen network for any pattern) or a metasurface height map (:mod:`.metasurface`), both with the
one loop of :mod:`.ascent`; search over their settings with Optuna (:mod:`.search`); defaults
in :mod:`.defaults` (importable without torch).

Design sits above reconstruction (its objectives are reconstructions) and below training, which
starts a joint optimisation from a designed pattern. The names below load on first use, so
``splitcam.design.defaults`` imports no torch.
"""

from __future__ import annotations

from ..io.lazy import lazy_exports

_EXPORTS = {
    "DEFAULT_LR": "defaults",
    "DEFAULT_SIGMAS": "defaults",
    "DEFAULT_STEPS": "defaults",
    "OBJECTIVES": "defaults",
    "DesignResult": "kernels",
    "closed_form_psnr": "kernels",
    "design_pattern": "kernels",
    "network_psnr": "kernels",
    "training_patches": "kernels",
    "MetasurfaceDesign": "metasurface",
    "design_metasurface": "metasurface",
    "ascend": "ascent",
    "search_patterns": "search",
    "search_metasurfaces": "search",
}

__all__ = sorted(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
