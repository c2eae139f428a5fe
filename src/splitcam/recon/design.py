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

import contextlib
import dataclasses
import math
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import torch

from ..patterns import Pattern, get
from ..physics.sensor import LearnableSplitterSensor
from .closed_form import ImageStatistics, closed_form_mse, shipped_image_statistics
from .lmmse import DEFAULT_RADIUS

__all__ = [
    "DEFAULT_LR",
    "DEFAULT_SIGMAS",
    "DEFAULT_STEPS",
    "OBJECTIVES",
    "DesignResult",
    "closed_form_psnr",
    "design_pattern",
    "network_psnr",
]

#: Noise levels (8-bit units) the design averages over by default: the paper's test levels.
DEFAULT_SIGMAS = (0.0, 5.0, 10.0, 15.0, 20.0)
#: Adam steps and learning rate (on the logits) of :func:`design_pattern` by default.
DEFAULT_STEPS = 300
DEFAULT_LR = 0.1
#: ``mse``: minimise the closed-form MSE averaged over the sigmas (the high-noise levels weigh
#: most, their errors are largest); ``psnr``: maximise the closed-form PSNR averaged over the
#: sigmas (every level weighs the same in dB); ``network``: maximise the PSNR of a frozen network
#: for any pattern (:class:`~splitcam.recon.networks.UniversalReconNet`) on training patches,
#: one sigma of the list per step in turn.
OBJECTIVES = ("mse", "psnr", "network")


def _objective_db(mse: torch.Tensor, objective: str) -> torch.Tensor:
    """The objective in dB, to maximise: ``-10 log10(mean MSE)`` or ``mean(-10 log10 MSE)``.

    ``mse`` is optimised as the PSNR of the mean MSE: the same minimiser as the mean MSE, but a
    gradient whose scale does not depend on the error level. On the mean MSE itself (~1e-4) the
    gradients reaching near-zero taps fall below Adam's epsilon, and the ``exact`` start of D
    stayed at D for 400 steps.
    """
    return _psnr(mse.mean()) if objective == "mse" else _psnr(mse).mean()


def _psnr(mse: torch.Tensor) -> torch.Tensor:
    return -10.0 * torch.log10(mse)


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
    return _psnr((out.float() - rgb).square().mean())


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
    kernels: Pattern | str | torch.Tensor,
    sigmas: Iterable[float],
    *,
    statistics: ImageStatistics | None = None,
    radius: int = DEFAULT_RADIUS,
) -> torch.Tensor:
    """``10 log10(1 / MSE)`` of the closed-form LMMSE at each sigma (float64, differentiable)."""
    sig = torch.tensor([float(s) for s in sigmas], dtype=torch.float64)
    return _psnr(closed_form_mse(kernels, sig, statistics=statistics, radius=radius))


def network_psnr(
    pattern: Pattern | str,
    network: torch.nn.Module,
    rgb: torch.Tensor,
    sigmas: Iterable[float],
    seed: int = 0,
) -> dict[float, float]:
    """PSNR (dB, per sigma) of a network for any pattern on patches ``rgb`` seen through
    ``pattern``, with noise drawn from ``seed``: how the ``network`` objective scores a pattern
    on a fixed set of patches (no rounding to 8 bits; for comparing patterns)."""
    from ..physics.sensor import SplitterSensor

    sensor = SplitterSensor(get(pattern))
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        return {
            float(s): float(_network_db(sensor, network.eval(), rgb, float(s), generator))
            for s in sigmas
        }


@contextlib.contextmanager
def _intra_op_threads(threads: int | None) -> Iterator[None]:
    """Run with ``threads`` intra-op threads (``None``: leave as is), restored afterwards."""
    before = torch.get_num_threads()
    if threads is not None and threads != before:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)


def _check_sigmas(sigmas: Iterable[float] | torch.Tensor) -> list[float]:
    try:
        values = [float(s) for s in sigmas]
    except (TypeError, ValueError):
        raise ValueError(f"expected sigmas as numbers (8-bit units), got {sigmas!r}") from None
    if not values or any(not (math.isfinite(s) and s >= 0) for s in values):
        raise ValueError(f"expected one or more finite sigmas >= 0 (8-bit units), got {values}")
    return values


def design_pattern(
    start: Pattern | str,
    *,
    init: str = "support",
    sigmas: Iterable[float] | torch.Tensor = DEFAULT_SIGMAS,
    steps: int = DEFAULT_STEPS,
    lr: float = DEFAULT_LR,
    seed: int = 0,
    radius: int = DEFAULT_RADIUS,
    statistics: ImageStatistics | None = None,
    objective: str = "mse",
    name: str | None = None,
    threads: int | None = 1,
    progress: bool = False,
    network: torch.nn.Module | None = None,
    patches: Any = None,
    batch_size: int = 8,
) -> DesignResult:
    """Optimise a pattern's kernels for the closed-form LMMSE, averaged over ``sigmas``, or for
    a network of any pattern (``objective="network"``).

    Adam on the softmax logits of a :class:`~splitcam.physics.sensor.LearnableSplitterSensor`
    (float64); the loss of all sigmas comes from one batched closed-form solve per step. The
    designed pattern is the one of the last step.

    Budget: the defaults (300 steps at lr 0.1) took 4.7-5.6 s for A and D (2x2 period,
    radius 4, 5 sigmas; 16-19 ms a step) on one core of this project's 2-core CPU while a
    training run kept both cores busy. By then the objective is within 0.02 dB of where 600
    steps take it from the support and exact starts of A and D, within 0.06 dB from random
    ones; at lr 0.02 and 0.05 it ended lower at step 300 from every start
    (``docs/results/design.md``).

    Args:
        start: Starting pattern (name, file or :class:`Pattern`); its layout and kernel size are
            kept. Colour filters (kernels summing below 1, e.g. ``bayer``) are refused.
        init: ``support``, ``exact`` or ``random`` (see
            :class:`~splitcam.physics.sensor.LearnableSplitterSensor`).
        sigmas: Noise levels (8-bit units) of the objective, each >= 0: a sequence, a range or
            a 1-D tensor.
        steps: Adam steps, >= 1.
        lr: Adam learning rate on the logits, > 0.
        seed: Seed of the ``random`` initialisation.
        radius: LMMSE filter radius (filters are ``2r+1`` square).
        statistics: Image statistics (default: the shipped ones).
        objective: ``mse`` (the mean closed-form MSE over the sigmas), ``psnr`` (the mean
            closed-form PSNR) or ``network``; see :data:`OBJECTIVES`.
        network: For ``network``: the frozen network (called ``network(raw, sigma, kernels)``;
            gradients reach the kernels through its LMMSE estimate, its data-consistency
            residual and its kernel encoder).
        patches: For ``network``: where training patches come from (an object with
            ``sample(n) -> (n, 3, h, w)``, e.g. :class:`~splitcam.data.patches.PatchSampler`).
        batch_size: For ``network``: patches per step.
        name: Name of the designed pattern (default ``<start>-designed``).
        threads: Intra-op threads during the optimisation (restored afterwards; ``None`` leaves
            them). The problem is small: on this 2-core machine, busy with a training run, a step
            took 11 ms with 1 thread and 800 ms with 2 (threads waiting for each other).
        progress: Show a progress bar (tqdm).

    Raises:
        ValueError: Bad ``init``, ``sigmas``, ``steps``, ``lr``, ``radius`` or ``objective``;
            a start that cannot be learned (:class:`~splitcam.patterns.PatternError`).
    """
    start = get(start)
    sigma_list = _check_sigmas(sigmas)
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"expected steps as an integer >= 1, got {steps!r}")
    if (
        isinstance(lr, bool)
        or not isinstance(lr, (int, float))
        or not (math.isfinite(lr) and lr > 0)
    ):
        raise ValueError(f"expected lr as a finite number > 0, got {lr!r}")
    if isinstance(radius, bool) or not isinstance(radius, int) or radius < 0:
        raise ValueError(f"expected radius as an integer >= 0, got {radius!r}")
    if objective not in OBJECTIVES:
        raise ValueError(
            f"expected objective to be one of {', '.join(OBJECTIVES)}, got {objective!r}"
        )
    if threads is not None and (
        isinstance(threads, bool) or not isinstance(threads, int) or threads < 1
    ):
        raise ValueError(f"expected threads as an integer >= 1 or None, got {threads!r}")
    if objective == "network" and (network is None or patches is None):
        raise ValueError("objective 'network' needs a network and training patches")
    stats = statistics if statistics is not None else shipped_image_statistics()
    sig = torch.tensor(sigma_list, dtype=torch.float64)
    generator = torch.Generator().manual_seed(seed)
    sensor = LearnableSplitterSensor(start, init=init, generator=generator).double()

    def mse_of(kernels: Pattern | torch.Tensor) -> torch.Tensor:
        return closed_form_mse(kernels, sig, statistics=stats, radius=radius)

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=steps, desc=f"design from {start.name} ({init})", unit="step")
    history: list[float] = []
    began = time.perf_counter()
    with _intra_op_threads(threads):
        with torch.no_grad():
            before = mse_of(start)
        optimizer = torch.optim.Adam([sensor.logits], lr=lr)
        noise = torch.Generator().manual_seed(seed + 1)
        if network is not None:
            network.eval().requires_grad_(False)
        for step in range(steps):
            if objective == "network":
                sigma = sigma_list[step % len(sigma_list)]
                value = _network_db(sensor, network, patches.sample(batch_size), sigma, noise)
            else:
                value = _objective_db(mse_of(sensor.pixel_kernels()), objective)
            optimizer.zero_grad(set_to_none=True)
            (-value).backward()
            optimizer.step()
            history.append(value.item())
            if bar is not None:
                bar.set_postfix(dB=f"{history[-1]:.3f}", refresh=False)
                bar.update(1)
        designed = sensor.to_pattern(name or f"{start.name}-designed")
        with torch.no_grad():
            after = mse_of(designed)
    seconds = time.perf_counter() - began
    if bar is not None:
        bar.close()
    designed = dataclasses.replace(
        designed,
        provenance="designed",
        description=(
            f"designed from pattern {start.name} ({init} start) for "
            + ("a network for any pattern" if objective == "network" else "the closed-form LMMSE")
            + f" ({objective}) at sigma {', '.join(f'{s:g}' for s in sigma_list)}"
        ),
        reference="splitcam design"
        + (" (a frozen network)" if objective == "network" else " (closed-form LMMSE)"),
        metadata={
            "start": start.name,
            "init": init,
            "seed": seed,
            "sigmas": sigma_list,
            "objective": objective,
            "steps": steps,
            "lr": float(lr),
            "radius": radius,
        },
    )
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
    """Optimise a metasurface height map for the closed-form LMMSE (SPEC sections 10 and 12), or
    for Bayer-type routing.

    The height is ``h_max * sigmoid(z)`` (always in ``[0, h_max]``); Adam on ``z`` maximises,
    through :func:`splitcam.optics.kernels_of` (differentiable), with no images:

    - ``objective="lmmse"``: ``-10 log10`` of the closed-form LMMSE error averaged over
      ``sigmas`` (what the reconstruction gains);
    - ``objective="routing"``: the geometric mean of the R, G and B collection efficiencies into
      an RGGB pixel arrangement (:func:`splitcam.optics.rggb_collection`; 2x2 periods), the
      figure of merit of published colour routers. The geometric mean, because the arithmetic
      one was measured to settle on lopsided routers (default geometry, random start, 600 steps:
      R 13 %, G 30 %, B 35 %; the geometric mean: 18 / 31 / 26 % in 400).

    Args:
        period: ``(Ph, Pw)`` of the router.
        optics: A :class:`splitcam.optics.Optics`.
        init: ``random`` (uniform heights), ``lens`` (a microlens over every pixel, focused at
            the distance) or a height map.
        steps, lr, seed, radius, statistics, sigmas: As :func:`design_pattern`.
    """
    from ..optics import kernels_of, pattern_of, profile, rggb_collection
    from ..physics.sensor import pixel_kernels

    sigma_list = _check_sigmas(sigmas)
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
        return _psnr(mse_of(height).mean())

    with torch.no_grad():
        before = mse_of(start)
        collection_before = collection(start)
    optimizer = torch.optim.Adam([z], lr=lr)
    history: list[float] = []
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=steps, desc="metasurface design", unit="step")
    began = time.perf_counter()
    for _ in range(steps):
        value = value_of(hmax * torch.sigmoid(z))
        optimizer.zero_grad(set_to_none=True)
        (-value).backward()
        optimizer.step()
        history.append(value.item())
        if bar is not None:
            bar.set_postfix(
                {"dB" if objective == "lmmse" else "efficiency": f"{history[-1]:.3f}"},
                refresh=False,
            )
            bar.update(1)
    if bar is not None:
        bar.close()
    height = (hmax * torch.sigmoid(z)).detach()
    with torch.no_grad():
        after = mse_of(height)
        collection_after = collection(height)
    return MetasurfaceDesign(
        height=height,
        start=start,
        pattern=pattern_of(height, period, optics, name=name),
        psnr_before={s: float(_psnr(m)) for s, m in zip(sigma_list, before, strict=True)},
        psnr_after={s: float(_psnr(m)) for s, m in zip(sigma_list, after, strict=True)},
        history=history,
        seconds=time.perf_counter() - began,
        objective=objective,
        collection_before=collection_before,
        collection_after=collection_after,
    )
