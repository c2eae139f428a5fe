"""Pattern design in seconds: gradient descent on the closed-form LMMSE error.

The closed-form LMMSE (:mod:`splitcam.recon.closed_form`) gives the expected error of the best
linear reconstruction of any kernels, differentiably and without images. Designing a pattern is
then a small optimisation: the logits of a learnable pattern (same layout and kernel size as the
start, a softmax over each kernel's taps as in the paper's Eq. 5, so it stays non-negative and
light-conserving) are moved by Adam to lower the closed-form LMMSE error averaged over a range of
noise levels, all noise levels in one batched solve.

The objective ranks patterns by what a linear reconstruction recovers from them; a trained
network recovers more. How the designed patterns score with the LMMSE on held-out images is in
``docs/results/design.md``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import torch

from ..checks import check_count
from ..patterns import Pattern, check_pattern
from ..physics.sensor import LearnableSplitterSensor
from ..recon.closed_form import ImageStatistics, closed_form_mse, shipped_image_statistics
from ..recon.lmmse import DEFAULT_RADIUS
from .ascent import ascend, check_sigmas, psnr_of
from .defaults import DEFAULT_LR, DEFAULT_SIGMAS, DEFAULT_STEPS, OBJECTIVES

__all__ = [
    "DEFAULT_LR",
    "DEFAULT_SIGMAS",
    "DEFAULT_STEPS",
    "OBJECTIVES",
    "DesignResult",
    "DesignSettings",
    "closed_form_psnr",
    "design_pattern",
    "network_psnr",
    "training_patches",
]


def _objective_db(mse: torch.Tensor, objective: str) -> torch.Tensor:
    """The objective in dB, to maximise: ``-10 log10(mean MSE)`` or ``mean(-10 log10 MSE)``.

    ``mse`` is optimised as the PSNR of the mean MSE: the same minimiser as the mean MSE, but a
    gradient whose scale does not depend on the error level. On the mean MSE itself (~1e-4) the
    gradients reaching near-zero taps fall below Adam's epsilon, and the ``exact`` start of D
    stayed at D for 400 steps.
    """
    return psnr_of(mse.mean()) if objective == "mse" else psnr_of(mse).mean()


def _network_db(
    sensor: torch.nn.Module,
    network: torch.nn.Module,
    rgb: torch.Tensor,
    sigma: float,
    generator: torch.Generator,
) -> torch.Tensor:
    """PSNR (dB) of ``network`` on ``rgb`` seen through the sensor at noise ``sigma``: the
    ``network`` objective of one step, differentiable in the sensor's kernels."""
    rgb = rgb.to(torch.float32)
    raw = sensor(rgb.double()).float()
    raw = raw + (sigma / 255.0) * torch.randn(raw.shape, generator=generator)
    out = network(raw, sigma, sensor.pixel_kernels())
    return psnr_of((out.float() - rgb).square().mean())


@dataclass
class DesignResult:
    """What :func:`design_pattern` found.

    Attributes:
        pattern: The designed pattern (same layout and kernel size as ``start``).
        start: The pattern the design started from.
        init: How the logits were initialised (``support``, ``exact`` or ``random``).
        sigmas: The noise levels (8-bit units) of the objective.
        objective: ``mse`` or ``psnr`` (see :data:`OBJECTIVES`).
        mse_before: Closed-form LMMSE MSE per colour (``[0, 1]`` units) of ``start``, per sigma.
        mse_after: The same of ``pattern``.
        history: The objective (dB, higher is better) at every step, before that step's update:
            ``-10 log10`` of the mean MSE over the sigmas for ``mse``, the mean PSNR for ``psnr``.
        seconds: Wall time of the optimisation.
        logits: The optimised logits (float64), what a learnable sensor continues from.
    """

    pattern: Pattern
    start: Pattern
    init: str
    sigmas: list[float]
    objective: str
    mse_before: dict[float, float]
    mse_after: dict[float, float]
    history: list[float] = field(default_factory=list)
    seconds: float = 0.0
    logits: torch.Tensor | None = None

    @property
    def psnr_before(self) -> dict[float, float]:
        """Closed-form LMMSE PSNR (dB) of ``start`` per sigma."""
        return {s: -10.0 * math.log10(v) for s, v in self.mse_before.items()}

    @property
    def psnr_after(self) -> dict[float, float]:
        """Closed-form LMMSE PSNR (dB) of ``pattern`` per sigma."""
        return {s: -10.0 * math.log10(v) for s, v in self.mse_after.items()}


def closed_form_psnr(
    kernels: Pattern | torch.Tensor,
    sigmas: Iterable[float],
    *,
    statistics: ImageStatistics | None = None,
    radius: int = DEFAULT_RADIUS,
) -> torch.Tensor:
    """``10 log10(1 / MSE)`` of the closed-form LMMSE at each sigma (float64, differentiable)."""
    sig = torch.tensor([float(s) for s in sigmas], dtype=torch.float64)
    return psnr_of(closed_form_mse(kernels, sig, statistics=statistics, radius=radius))


def network_psnr(
    pattern: Pattern,
    network: torch.nn.Module,
    rgb: torch.Tensor,
    sigmas: Iterable[float],
    seed: int = 0,
) -> dict[float, float]:
    """PSNR (dB, per sigma) of a network for any pattern on patches ``rgb`` seen through
    ``pattern``, with noise drawn from ``seed``: how the ``network`` objective scores a pattern
    on a fixed set of patches (no rounding to 8 bits; for comparing patterns)."""
    from ..physics.sensor import SplitterSensor

    sensor = SplitterSensor(check_pattern(pattern))
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        return {
            float(s): float(_network_db(sensor, network.eval(), rgb, float(s), generator))
            for s in sigmas
        }


@dataclass(frozen=True)
class DesignSettings:
    """How :func:`design_pattern` optimises (recorded in the designed pattern's metadata).

    Attributes:
        init: ``support``, ``exact`` or ``random`` (see
            :class:`~splitcam.physics.sensor.LearnableSplitterSensor`).
        sigmas: Noise levels (8-bit units) of the objective, each >= 0.
        steps: Adam steps, >= 1.
        lr: Adam learning rate on the logits, > 0.
        seed: Seed of the ``random`` initialisation (and of the ``network`` objective's noise).
        radius: LMMSE filter radius (filters are ``2r+1`` square).
        objective: ``mse``, ``psnr`` or ``network`` (:data:`OBJECTIVES`).
        batch_size: For ``network``: patches per step.
    """

    init: str = "support"
    sigmas: tuple[float, ...] = tuple(DEFAULT_SIGMAS)
    steps: int = DEFAULT_STEPS
    lr: float = DEFAULT_LR
    seed: int = 0
    radius: int = DEFAULT_RADIUS
    objective: str = "mse"
    batch_size: int = 8

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigmas", tuple(check_sigmas(self.sigmas)))
        check_count(self.steps, "steps", 1)
        lr = self.lr
        if (
            isinstance(lr, bool)
            or not isinstance(lr, (int, float))
            or not (math.isfinite(lr) and lr > 0)
        ):
            raise ValueError(f"expected lr as a finite number > 0, got {lr!r}")
        check_count(self.radius, "radius", 0)
        if self.objective not in OBJECTIVES:
            raise ValueError(
                f"expected objective to be one of {', '.join(OBJECTIVES)}, got {self.objective!r}"
            )

    def record(self) -> dict[str, Any]:
        """The settings a designed pattern's metadata keeps."""
        return {"init": self.init, "seed": self.seed, "sigmas": list(self.sigmas)} | {
            "objective": self.objective,
            "steps": self.steps,
            "lr": float(self.lr),
            "radius": self.radius,
        }


def design_pattern(
    start: Pattern,
    settings: DesignSettings | None = None,
    *,
    statistics: ImageStatistics | None = None,
    name: str | None = None,
    threads: int | None = 1,
    progress: bool = False,
    network: torch.nn.Module | None = None,
    patches: Any = None,
    **changes: Any,
) -> DesignResult:
    """Optimise a pattern's kernels for the closed-form LMMSE, averaged over ``sigmas``, or for
    a network of any pattern (``objective="network"``).

    Adam on the softmax logits of a :class:`~splitcam.physics.sensor.LearnableSplitterSensor`
    (float64); the loss of all sigmas comes from one batched closed-form solve per step. The
    designed pattern is the one of the last step.

    Budget: the defaults (300 steps at lr 0.1) take about 5 s for A and D (2x2 period,
    radius 4, 5 sigmas; 16-19 ms a step on one thread of a 2-core CPU with other work
    running). By then the objective is within 0.02 dB of where 600 steps take it from the
    support and exact starts of A and D, within 0.06 dB from random ones; at lr 0.02 and 0.05
    it ends lower at step 300 from every start (``docs/results/design.md``).

    Args:
        start: Starting pattern; its layout and kernel size are kept. Colour filters (kernels
            summing below 1, e.g. ``bayer``) are refused.
        settings: How to optimise (:class:`DesignSettings`; default its defaults).
        statistics: Image statistics (default: the shipped ones).
        network: For ``network``: the frozen network (called ``network(raw, sigma, kernels)``;
            gradients reach the kernels through its LMMSE estimate, its data-consistency
            residual and its kernel encoder).
        patches: For ``network``: where training patches come from (an object with
            ``sample(n) -> (n, 3, h, w)``, e.g. :class:`~splitcam.data.patches.PatchSampler`).
        name: Name of the designed pattern (default ``<start>-designed``).
        threads: Intra-op threads during the optimisation (restored afterwards; ``None`` leaves
            them). The problem is small: on a 2-core CPU with other work running, a step takes
            11 ms with 1 thread and 800 ms with 2 (threads waiting for each other).
        progress: Show a progress bar (tqdm).
        changes: Fields of ``settings`` to change (``steps=5``, ``sigmas=[0, 10]``...).

    Raises:
        ValueError: Bad ``init``, ``sigmas``, ``steps``, ``lr``, ``radius`` or ``objective``;
            a start that cannot be learned (:class:`~splitcam.patterns.PatternError`).

    >>> from splitcam import patterns
    >>> result = design_pattern(patterns.get("D"), steps=5, sigmas=[0.0, 10.0], radius=2)
    >>> result.pattern.name, result.pattern.period, result.pattern.kernel_size
    ('D-designed', (2, 2), (1, 3))
    >>> len(result.history)  # the objective (dB) before each of the 5 steps
    5
    >>> result.history[-1] > result.history[0]
    True
    >>> all(result.mse_after[s] < result.mse_before[s] for s in (0.0, 10.0))
    True
    """
    start = check_pattern(start, "start")
    try:
        settings = dataclasses.replace(settings or DesignSettings(), **changes)
    except TypeError as exc:  # a change that is not a setting
        raise TypeError(f"design_pattern(): {exc}") from None
    if threads is not None:
        check_count(threads, "threads", 1)
    if settings.objective == "network" and (network is None or patches is None):
        raise ValueError("objective 'network' needs a network and training patches")
    init, seed, objective = settings.init, settings.seed, settings.objective
    sigma_list, radius = list(settings.sigmas), settings.radius
    stats = statistics if statistics is not None else shipped_image_statistics()
    sig = torch.tensor(sigma_list, dtype=torch.float64)
    generator = torch.Generator().manual_seed(seed)
    sensor = LearnableSplitterSensor(start, init=init, generator=generator).double()

    def mse_of(kernels: Pattern | torch.Tensor) -> torch.Tensor:
        return closed_form_mse(kernels, sig, statistics=stats, radius=radius)

    with torch.no_grad():
        before = mse_of(start)
    noise = torch.Generator().manual_seed(seed + 1)
    if network is not None:
        network.eval().requires_grad_(False)

    def value_of(step: int) -> torch.Tensor:
        if objective == "network":
            sigma = sigma_list[step % len(sigma_list)]
            return _network_db(sensor, network, patches.sample(settings.batch_size), sigma, noise)
        return _objective_db(mse_of(sensor.pixel_kernels()), objective)

    history, seconds = ascend(
        [sensor.logits],
        value_of,
        steps=settings.steps,
        lr=settings.lr,
        threads=threads,
        progress=f"design from {start.name} ({init})" if progress else None,
    )
    designed = sensor.to_pattern(name or f"{start.name}-designed")
    with torch.no_grad():
        after = mse_of(designed)
    designed = _with_provenance(designed, start, settings.record())
    return DesignResult(
        pattern=designed,
        start=start,
        init=init,
        sigmas=sigma_list,
        objective=objective,
        mse_before=dict(zip(sigma_list, before.tolist(), strict=True)),
        mse_after=dict(zip(sigma_list, after.tolist(), strict=True)),
        history=history,
        seconds=seconds,
        logits=sensor.logits.detach().clone(),
    )


def _with_provenance(designed: Pattern, start: Pattern, settings: dict[str, Any]) -> Pattern:
    """The designed pattern with what made it: its description, reference and ``metadata``
    (the start's name and ``settings``)."""
    objective = settings["objective"]
    network = objective == "network"
    return dataclasses.replace(
        designed,
        provenance="designed",
        description=(
            f"designed from pattern {start.name} ({settings['init']} start) for "
            + ("a network for any pattern" if network else "the closed-form LMMSE")
            + f" ({objective}) at sigma {', '.join(f'{s:g}' for s in settings['sigmas'])}"
        ),
        reference="splitcam design"
        + (" (a frozen network)" if network else " (closed-form LMMSE)"),
        metadata={"start": start.name, **settings},
    )


def training_patches(folder: str, *, seed: int = 0, size: int = 64, held: int = 32) -> tuple:
    """What the ``network`` objective trains and scores on: a sampler of ``size`` patches from
    the images of ``folder`` except the last ``held`` (sorted by name; a tenth of the images if
    fewer than ten times that), as training holds them out, and a fixed batch of ``held``
    patches of the held-out images to score patterns before and after (a single image is both).

    Returns:
        ``(sampler, held_out)``: a :class:`~splitcam.data.patches.PatchSampler` and a
        ``(held, 3, size, size)`` tensor.

    Raises:
        ValueError: No images in ``folder``.
    """
    from ..data.patches import ImageCache, PatchSampler, list_images

    files = list_images(folder)
    hold = min(held, max(1, len(files) // 10)) if len(files) >= 2 else 0
    cache = ImageCache(files[: len(files) - hold], min_size=size, progress=False)
    sampler = PatchSampler(cache, patch_size=size, seed=seed)
    held_files = files[len(files) - hold :] if hold else files
    held_cache = ImageCache(held_files, min_size=size, progress=False)
    return sampler, PatchSampler(held_cache, patch_size=size, seed=12345).sample(held)
