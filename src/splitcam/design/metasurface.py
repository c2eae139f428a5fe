"""Metasurface design: a height map optimised through scalar wave optics
(:mod:`splitcam.physics.optics`) for the closed-form LMMSE or for Bayer-type routing, with the
loop of :func:`~splitcam.design.ascent.ascend`."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import torch

from ..patterns import Pattern
from ..physics.optics import kernels_of, pattern_of, profile, rggb_collection
from ..physics.sensor import pixel_kernels
from ..recon.closed_form import ImageStatistics, closed_form_mse, shipped_image_statistics
from ..recon.lmmse import DEFAULT_RADIUS
from .ascent import ascend, check_sigmas, psnr_of
from .defaults import DEFAULT_SIGMAS

__all__ = ["MetasurfaceDesign", "design_metasurface"]


@dataclass
class MetasurfaceDesign:
    """What :func:`design_metasurface` found: the height map (µm), its pattern, the closed-form
    LMMSE PSNR per sigma before and after, the RGGB collection efficiency before and after (2x2
    periods), and the objective at every step (dB for ``lmmse``, the geometric mean efficiency
    for ``routing``)."""

    height: torch.Tensor
    start: torch.Tensor
    pattern: Pattern
    psnr_before: dict[float, float]
    psnr_after: dict[float, float]
    history: list[float] = field(default_factory=list)
    seconds: float = 0.0
    objective: str = "lmmse"
    collection_before: list[float] | None = None
    collection_after: list[float] | None = None


def design_metasurface(
    period: tuple[int, int],
    optics: Any,
    *,
    init: str | torch.Tensor = "random",
    sigmas: Iterable[float] | torch.Tensor = DEFAULT_SIGMAS,
    steps: int = 200,
    lr: float = 0.1,
    seed: int = 0,
    radius: int = DEFAULT_RADIUS,
    statistics: ImageStatistics | None = None,
    name: str = "metasurface",
    progress: bool = False,
    objective: str = "lmmse",
) -> MetasurfaceDesign:
    """Optimise a metasurface height map for the closed-form LMMSE (model.md §10 and §12), or
    for Bayer-type routing.

    The height is ``h_max * sigmoid(z)`` (always in ``[0, h_max]``); Adam on ``z`` maximises,
    through :func:`splitcam.physics.optics.kernels_of` (differentiable), with no images:

    - ``objective="lmmse"``: ``-10 log10`` of the closed-form LMMSE error averaged over
      ``sigmas`` (what the reconstruction gains);
    - ``objective="routing"``: the geometric mean of the R, G and B collection efficiencies into
      an RGGB pixel arrangement (:func:`splitcam.physics.optics.rggb_collection`; 2x2 periods), the
      figure of merit of published colour routers. The geometric mean, because the arithmetic
      one was measured to settle on lopsided routers (default geometry, random start, 600 steps:
      R 13 %, G 30 %, B 35 %; the geometric mean: 18 / 31 / 26 % in 400).

    Args:
        period: ``(Ph, Pw)`` of the router.
        optics: A :class:`splitcam.physics.optics.Optics`.
        init: ``random`` (uniform heights), ``lens`` (a microlens over every pixel, focused at
            the distance) or a height map.
        sigmas: As :func:`design_pattern`.
        steps: As :func:`design_pattern`.
        lr: As :func:`design_pattern`.
        seed: As :func:`design_pattern`.
        radius: As :func:`design_pattern`.
        statistics: As :func:`design_pattern`.
    """
    sigma_list = check_sigmas(sigmas)
    if objective not in ("lmmse", "routing"):
        raise ValueError(f"objective must be lmmse or routing, got {objective!r}")
    if objective == "routing" and tuple(period) != (2, 2):
        raise ValueError(f"the routing objective needs a 2x2 (RGGB) period, got {tuple(period)}")
    if isinstance(init, torch.Tensor):
        start = init.to(torch.float64)
        shape = (period[0] * optics.samples, period[1] * optics.samples)
        if tuple(start.shape) != shape:
            raise ValueError(f"expected a height map of shape {shape}, got {tuple(start.shape)}")
    elif init in ("random", "lens"):
        start = profile(init, period, optics, seed)
    else:
        raise ValueError(f"init must be random, lens or a height map, got {init!r}")
    hmax = optics.max_height
    frac = (start / hmax).clamp(1e-3, 1 - 1e-3)
    z = torch.log(frac / (1 - frac)).requires_grad_(True)
    stats = statistics if statistics is not None else shipped_image_statistics()
    sig = torch.tensor(sigma_list, dtype=torch.float64)
    layout = [[i * period[1] + j for j in range(period[1])] for i in range(period[0])]

    def mse_of(height: torch.Tensor) -> torch.Tensor:
        kernels = pixel_kernels(kernels_of(height, period, optics), layout)
        return closed_form_mse(kernels, sig, statistics=stats, radius=radius)

    def collection(height: torch.Tensor) -> list[float] | None:
        if tuple(period) != (2, 2):
            return None
        return rggb_collection(kernels_of(height, period, optics), layout).tolist()

    def value_of(height: torch.Tensor) -> torch.Tensor:
        if objective == "routing":
            return rggb_collection(kernels_of(height, period, optics), layout).log().mean().exp()
        return psnr_of(mse_of(height).mean())

    with torch.no_grad():
        before = mse_of(start)
        collection_before = collection(start)
    history, seconds = ascend(
        [z],
        lambda _: value_of(hmax * torch.sigmoid(z)),
        steps=steps,
        lr=lr,
        progress="metasurface design" if progress else None,
        unit="dB" if objective == "lmmse" else "efficiency",
    )
    height = (hmax * torch.sigmoid(z)).detach()
    with torch.no_grad():
        after = mse_of(height)
        collection_after = collection(height)
    return MetasurfaceDesign(
        height=height,
        start=start,
        pattern=pattern_of(height, period, optics, name=name),
        psnr_before={s: float(psnr_of(m)) for s, m in zip(sigma_list, before, strict=True)},
        psnr_after={s: float(psnr_of(m)) for s, m in zip(sigma_list, after, strict=True)},
        history=history,
        seconds=seconds,
        objective=objective,
        collection_before=collection_before,
        collection_after=collection_after,
    )
