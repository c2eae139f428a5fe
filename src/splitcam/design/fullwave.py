"""Metasurface routers designed through Maxwell's equations for the image they give.

The chain, every step differentiable (PyTorch autograd through torcwa's RCWA):

1. **Design variables → densities.** A latent array ``theta`` (one value per cell of the
   layer) goes through a sigmoid into [0, 1], a conic filter of radius ``r`` cells (periodic,
   as the metasurface is) and a tanh projection of sharpness ``beta`` about 0.5: the standard
   filter-and-project scheme of density-based inverse design (Wang, Lazarov & Sigmund,
   *On projection methods, convergence and robust formulations in topology optimization*,
   Struct. Multidisc. Optim. 43, 2011). The filter removes features narrower than about its
   radius, so ``r`` times the cell size is the design's minimum feature size; raising ``beta``
   over the run drives the densities to 0 and 1, and the reported design is the projection
   thresholded at 0.5 and made to keep the minimum feature (by default ``r`` cells) in solid
   and void alike (a brush of that diameter paints every feature:
   :mod:`splitcam.design.lengthscale`; thresholding alone leaves specks and slits where the
   densities are grey) (:meth:`FullwaveDesign.binary`), solved again as a binary layer.
   Binary steps descend on that layer itself.
2. **Densities → spectra.** :func:`splitcam.physics.fullwave.torcwa_quadrants`: the light of
   each wavelength crossing each pixel quadrant at the monitor depth, averaged over the two
   polarisations and over the directions of a lens's cone (normal incidence by default).
3. **Spectra → RGB kernels.** The reduction of :class:`splitcam.patterns.SpectralPattern`
   (the nearest-copy rule, then the scene basis of linear sRGB), written here in torch:
   :func:`rgb_kernels`, checked against the pattern class.
4. **Kernels → image error.** The closed-form LMMSE error of those kernels
   (:func:`splitcam.recon.closed_form.closed_form_mse`) at a photon-model exposure, with the
   linear-light image statistics: the expected error of the reconstruction a user would get,
   at the exposure the router is meant for.

A density of 1 is the pillar material, 0 the background (the permittivity is interpolated
linearly in between, as :class:`~splitcam.physics.fullwave.RouterDesign` does).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch.utils.checkpoint import checkpoint

from ..patterns.spectral import _nearest_copies, scene_basis
from ..physics.fullwave import (
    SOLVERS,
    FullwaveError,
    RouterDesign,
    check_workers,
    cone_directions,
    material_of,
    solve_quadrants,
)
from ..physics.noise import Exposure
from ..physics.sensor import pixel_kernels
from ..physics.solvepool import SolvePool, pooled_solves
from ..recon.closed_form import closed_form_mse, shipped_image_statistics
from .lengthscale import with_minimum_feature

__all__ = ["FullwaveDesign", "beta_at", "conic_filter", "project", "rgb_kernels", "run_design"]


def conic_filter(x: torch.Tensor, radius: float) -> torch.Tensor:
    """``x`` ``(rows, cols)`` averaged with weights ``max(0, radius - distance)`` over the
    cells within ``radius`` (in cells), wrapping around the edges (the layer is periodic);
    each layer of ``(layers, rows, cols)`` on its own. Keeps the mean and maps a constant to
    itself; radius below 1 returns ``x``."""
    if radius < 1:
        return x
    reach = int(math.ceil(radius)) - 1 if float(radius).is_integer() else int(radius)
    offsets = torch.arange(-reach, reach + 1, dtype=x.dtype)
    dist = torch.sqrt(offsets[:, None] ** 2 + offsets[None, :] ** 2)
    weights = torch.clamp(radius - dist, min=0.0)
    weights = weights / weights.sum()
    layers = x.reshape(-1, 1, *x.shape[-2:])
    padded = torch.nn.functional.pad(layers, (reach,) * 4, mode="circular")
    return torch.nn.functional.conv2d(padded, weights[None, None]).reshape(x.shape)


def project(x: torch.Tensor, beta: float, eta: float = 0.5) -> torch.Tensor:
    """The tanh projection of densities ``x`` about ``eta`` with sharpness ``beta``: 0 → 0,
    1 → 1, ``eta`` → ``eta``; a step at ``eta`` as ``beta`` grows. ``beta`` 0: ``x``."""
    if beta <= 0:
        return x
    a, b = math.tanh(beta * eta), math.tanh(beta * (1.0 - eta))
    return (a + torch.tanh(beta * (x - eta))) / (a + b)


def rgb_kernels(transmission: torch.Tensor, wavelengths: Sequence[float]) -> torch.Tensor:
    """The RGB splitter kernels ``(4, 3, 3, 3)`` (layout ``[[0, 1], [2, 3]]``) of a 2x2 router
    whose period sends ``transmission[i, j, l]`` of wavelength ``l`` to pixel ``(i, j)``: the
    reduction of :meth:`splitcam.patterns.SpectralPattern.from_transmission` (every pixel
    sends the same shares to the nearest copy of each pixel, split evenly where copies tie)
    and :meth:`~splitcam.patterns.SpectralPattern.to_pattern` (the scene basis), in torch so
    that gradients reach the transmissions."""
    t = transmission
    if t.shape[:2] != (2, 2) or t.ndim != 3 or t.shape[2] != len(wavelengths):
        raise FullwaveError(
            f"transmission must be (2, 2, {len(wavelengths)}), got {tuple(t.shape)}"
        )
    basis = torch.from_numpy(scene_basis(list(wavelengths))).to(t)  # (L, 3)
    rgb = torch.einsum("ijl,lc->ijc", t, basis)  # (2, 2, 3): each pixel's share per colour
    kernels = []
    for q in np.ndindex(2, 2):
        k = t.new_zeros(3, 3, 3)
        for p in np.ndindex(2, 2):
            copies = _nearest_copies(q, p, (2, 2))  # the pattern class's own rule
            for dy, dx in copies:
                k[:, dy + 1, dx + 1] = k[:, dy + 1, dx + 1] + rgb[p] / len(copies)
        kernels.append(k)
    return torch.stack(kernels)


@dataclass
class FullwaveDesign:
    """A 2x2-pixel router whose layer, or layers stacked, are designed for the LMMSE image
    error at one exposure.

    Args:
        geometry: The stack (pitch, thickness, depth, materials; the layers and their spacer);
            its grid sets the number of design cells and is where :meth:`start` begins from.
        wavelengths: nm, where the spectra are solved (the band's ends and middle at least).
        photons: The exposure designed for (photo-electrons of a lossless full-light pixel).
        read_noise: Electrons.
        directions: ``(polar angle, azimuth, weight)`` of the incident light
            (:func:`splitcam.physics.fullwave.cone_directions`; default normal incidence).
        order: torcwa's Fourier order per axis (and fmmax's terms, ``(2 order + 1)^2``, where
            ``terms`` is not given).
        samples: Flux grid points per pixel and axis.
        radius: The conic filter's radius in cells (the minimum feature, about radius x cell).
        feature: The binary layer's minimum feature in cells, in pillars and gaps alike (the
            brush of :mod:`splitcam.design.lengthscale`); None: the filter's radius, rounded.
        solver: One of :data:`~splitcam.physics.fullwave.SOLVERS`: torcwa (exact gradients), or
            fmmax (:func:`~splitcam.physics.fullwave.fmmax_quadrants`), whose Jones-direct
            formulation converges in fewer terms; its gradient holds the formulation's vector
            field fixed (fmmax's own choice), so it is close to, not equal to, the derivative.
        terms: fmmax's Fourier terms (circular truncation).
        optics: An :class:`~splitcam.physics.stack.OpticalStack` in front of every pixel (the
            silicon's quantum efficiency, an IR cut): the loss is the image error of the sensor
            behind it, each wavelength's transmission weighted by the stack's, as
            :meth:`~splitcam.physics.stack.OpticalStack.apply` weights a spectral pattern; the
            spectra reported stay the router's own. None: a bare, lossless pixel.
        workers: Processes that share each step's solves (one thread each;
            :mod:`splitcam.physics.solvepool`); 1: every solve in this process. The same spectra,
            and the same gradient to rounding, either way. Started on first use; :meth:`close`
            (or ``with design:``) stops them.
    """

    geometry: RouterDesign
    wavelengths: Sequence[float] = (450.0, 550.0, 650.0)
    photons: float = 100.0
    read_noise: float = 2.0
    directions: Sequence[tuple[float, float, float]] = ((0.0, 0.0, 1.0),)
    order: int = 5
    samples: int = 16
    radius: float = 2.0
    feature: int | None = None
    solver: str = "torcwa"
    terms: int | None = None
    optics: Any = None
    workers: int = 1
    _stats: Any = field(default=None, init=False, repr=False)
    _pool: Any = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.photons > 0:
            raise FullwaveError(
                f"the target exposure must be > 0 photo-electrons, got {self.photons}"
            )
        if self.radius < 0:
            raise FullwaveError(f"the filter radius must be >= 0 cells, got {self.radius}")
        if self.feature_cells > min(self.geometry.cells):
            rows, cols = self.geometry.cells
            raise FullwaveError(
                f"the minimum feature ({self.feature_cells} cells) is wider than the layer "
                f"({rows} x {cols} cells)"
            )
        if self.solver not in SOLVERS:
            raise FullwaveError(f"unknown solver {self.solver!r}; expected one of {SOLVERS}")
        if self.terms is not None and (self.solver == "torcwa" or self.terms < 1):
            raise FullwaveError("terms: a number >= 1, for an fmmax solver (torcwa takes order)")
        check_workers(self.workers)
        self._stats = shipped_image_statistics("linear")

    def __enter__(self) -> FullwaveDesign:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the worker processes, if any were started (a later solve starts them again)."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    @classmethod
    def from_settings(
        cls, grid: np.ndarray, settings: Mapping[str, Any], *, workers: int = 1
    ) -> FullwaveDesign:
        """The design problem a run's ``settings`` describe (as ``splitcam optics
        rcwa-design`` saves them beside its state): the stack (``[pitch, thickness, depth,
        pillar, background, substrate]``, a thickness per layer for layers stacked, and the
        ``spacer`` between them where given) around ``grid``, the lens's cone (``f_number`` 0:
        normal incidence), the exposure, the solver, the minimum feature in µm (and the filter's
        radius in µm where ``filter`` is given; else the feature), and the optical stack in
        front of every pixel where ``optics`` (its comma-separated names) is given. ``workers``
        is not a setting of the problem (a continued run may change it): see the class.

        Raises:
            FullwaveError: A feature size below the grid step, or any of the stack's or the
                design's own refusals.
        """
        from ..physics.stack import stack_of

        pitch, thickness, depth, *materials = settings["stack"]
        geometry = RouterDesign(
            grid,
            pitch,
            thickness,
            depth,
            *map(material_of, materials),
            spacer=settings.get("spacer", 0.0),
        )
        cell = 2.0 * pitch / max(geometry.cells)
        feature = settings["feature"]
        if feature < cell:
            raise FullwaveError(
                f"feature {feature:g} µm is below the grid step ({cell:.4g} µm per cell)"
            )
        radius = settings.get("filter", feature)
        if radius < 0:
            raise FullwaveError(f"the filter's radius must be >= 0 µm, got {radius:g}")
        f_number = settings["f_number"]
        optics = settings.get("optics")
        return cls(
            geometry,
            wavelengths=settings["wavelengths"],
            photons=settings["photons"],
            read_noise=settings["read_noise"],
            directions=cone_directions(f_number) if f_number else ((0.0, 0.0, 1.0),),
            order=settings["order"],
            samples=settings["samples"],
            radius=radius / cell,
            feature=int(round(feature / cell)),
            solver=settings["solver"],
            terms=settings["terms"],
            optics=stack_of(optics) if optics else None,
            workers=workers,
        )

    def start(self) -> torch.Tensor:
        """Design variables whose densities (``beta`` 0, no filter) are the geometry's grid,
        pulled to [0.25, 0.75]: a binary start (pillar 1, background 0) would sit where the
        sigmoid is flat and its gradient vanishes; the projection makes it binary again as
        ``beta`` grows."""
        g = np.clip(self.geometry.grid, 0.25, 0.75)
        return torch.from_numpy(np.log(g / (1 - g)))

    def densities(self, theta: torch.Tensor, beta: float) -> torch.Tensor:
        """Sigmoid, conic filter, projection: the layers' densities in [0, 1]."""
        return project(conic_filter(torch.sigmoid(theta), self.radius), beta)

    @property
    def feature_cells(self) -> int:
        """The minimum feature of the binary layer, in cells (by default the filter's radius,
        rounded)."""
        return int(round(self.radius)) if self.feature is None else int(self.feature)

    def binary(self, theta: torch.Tensor, beta: float) -> np.ndarray:
        """The fabricable design (0/1 cells): the projected densities thresholded at 0.5, made
        to keep :attr:`feature_cells` in solid and void
        (:func:`~splitcam.design.lengthscale.with_minimum_feature`)."""
        with torch.no_grad():
            return self._fabricable(self.densities(theta, beta))

    def _fabricable(self, density: torch.Tensor) -> np.ndarray:
        layers = (density.detach() >= 0.5).numpy().reshape(-1, *density.shape[-2:])
        kept = [with_minimum_feature(layer, self.feature_cells) for layer in layers]
        return np.stack(kept).reshape(density.shape).astype(np.float64)

    def binarised(self, theta: torch.Tensor, beta: float) -> torch.Tensor:
        """The binary layer of :meth:`binary` in the forward pass, the projected densities'
        gradient in the backward (a straight-through estimator): the loss is the fabricable
        design's own, which the continuous densities only approach."""
        d = self.densities(theta, beta)
        return d + (torch.from_numpy(self._fabricable(d)).to(d) - d).detach()

    def transmission(self, density: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(2, 2, L)`` transmission into each pixel (mean of the polarisations and the
        directions) and ``(L,)`` reflection, differentiable in ``density``."""
        weights = torch.tensor([w for _, _, w in self.directions], dtype=torch.float64)
        weights = weights / weights.sum()
        jobs = [(lam, theta, phi) for lam in self.wavelengths for theta, phi, _ in self.directions]
        if self.workers > 1:
            solved = iter(zip(*pooled_solves(self._solve_pool(), density, jobs), strict=True))
        else:
            solved = (self._solve(density, *job) for job in jobs)
        spectra, reflection = [], []
        for _ in self.wavelengths:  # jobs run wavelength by wavelength, directions inside
            t = density.new_zeros(2, 2)
            r = density.new_zeros(())
            for w in weights:
                quads, refl = next(solved)
                t = t + w * quads.mean(0)
                r = r + w * refl
            spectra.append(t)
            reflection.append(r)
        return torch.stack(spectra, dim=-1), torch.stack(reflection)

    def _solve_pool(self) -> SolvePool:
        if self._pool is None:
            setting = (self.geometry, self.solver, self.order, self.terms, self.samples)
            self._pool = SolvePool(solve_quadrants, setting, self.workers)
        return self._pool

    def _solve(
        self, density: torch.Tensor, lam: float, theta: float, phi: float
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`quadrants`, holding no solve's intermediates between the forward and the
        backward pass: with a gradient to take, the forward solves without them and the
        backward solves again, with them, one solve at a time. Memory is then one solve's,
        not every wavelength's and direction's (a 200x200 layer behind a lens's cone, 42
        solves, did not fit in 24 GiB), for about one more forward solve each."""
        if not (density.requires_grad and torch.is_grad_enabled()):
            return self.quadrants(density, lam, theta, phi)
        return checkpoint(self.quadrants, density, lam, theta, phi, use_reentrant=True)

    def quadrants(
        self, density: torch.Tensor, lam: float, theta: float, phi: float
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One solve by the design's solver: ``(2, 2, 2)`` quadrant transmissions per
        polarisation and the reflection, differentiable in ``density``."""
        setting = (self.geometry, self.solver, self.order, self.terms, self.samples)
        return solve_quadrants(setting, density, lam, theta, phi)

    def image_error(self, transmission: torch.Tensor) -> torch.Tensor:
        """The closed-form LMMSE error (per colour, linear light in [0, 1]) of the router with
        these spectra at the design exposure (behind :attr:`optics`, where given)."""
        if self.optics is not None:
            weights = self.optics.weights(np.asarray(self.wavelengths, dtype=float))
            transmission = transmission * torch.from_numpy(weights).to(transmission)
        kernels = pixel_kernels(
            rgb_kernels(transmission, self.wavelengths), np.arange(4).reshape(2, 2)
        )
        exposure = Exposure(self.photons, read_noise=self.read_noise)
        return closed_form_mse(kernels, exposure, statistics=self._stats)

    def objective(
        self, theta: torch.Tensor, beta: float, binary: bool = False
    ) -> tuple[torch.Tensor, dict]:
        """The design loss (the image error in dB: ``10 log10 mse``, lower is better) and what
        a report shows: the error, the PSNR it means, each pixel's share of white light.
        ``binary``: of the thresholded layer (:meth:`binarised`)."""
        layer = self.binarised(theta, beta) if binary else self.densities(theta, beta)
        t, reflection = self.transmission(layer)
        mse = self.image_error(t)
        loss = 10.0 * torch.log10(mse)
        info = {
            "mse": float(mse.detach()),
            "psnr": float(-loss.detach()),
            "transmission": t.detach().numpy().tolist(),
            "reflection": float(reflection.detach().mean()),
        }
        return loss, info


STATE_FORMAT = "splitcam-fullwave-design"


def beta_at(step: int, steps: int, beta_start: float, beta_end: float) -> float:
    """The projection's sharpness at ``step`` of ``steps``: geometric from ``beta_start`` to
    ``beta_end`` (the usual continuation: the design settles before it is forced binary)."""
    if steps <= 1:
        return beta_end
    return beta_start * (beta_end / beta_start) ** (step / (steps - 1))


def run_design(
    design: FullwaveDesign,
    out: Any,
    *,
    steps: int,
    lr: float = 0.1,
    beta_start: float = 2.0,
    beta_end: float = 32.0,
    binary_steps: int = 0,
    binary_lr: float | None = None,
    backtrack: bool = False,
    settings: dict | None = None,
    progress: Any = None,
) -> dict[str, Any]:
    """Gradient descent (Adam) on :meth:`FullwaveDesign.objective`, saved after every step in
    ``out/state.safetensors`` + ``state.json`` (design variables, optimiser moments, history):
    the same call after an interruption continues from the last step saved. ``settings``: what
    the state must match to be continued (a run of other settings in ``out`` is refused).

    ``steps`` of continuation (``beta`` from ``beta_start`` to ``beta_end``), then
    ``binary_steps`` more on the binary layer itself (:meth:`FullwaveDesign.binarised`, at
    ``beta_end``): the continuous densities' optimum is lost in part when they are thresholded,
    and these steps descend on what is fabricated, by a fresh Adam at ``binary_lr`` (default
    ``lr``; the continuation's moments describe another loss). A cell flips when its variable
    crosses 0, and Adam moves every variable by about the learning rate, so a smaller rate flips
    fewer cells a step. With binary steps, the design returned is the best binary layer any of
    them scored (Adam on a thresholded layer does not descend monotonically). The number of
    binary steps is the one setting a continued run may change: more extends the binary phase,
    fewer ends it early, with the best binary layer of the steps done.

    ``backtrack``: a binary step that scores below the best binary layer so far sends the
    next one back to that layer, at half the rate of the step that fell: the step the optimiser
    took from the best layer is taken again at that rate (its direction and Adam's moments as
    they were there), so no solve is spent scoring the best layer again. A non-monotone descent
    then settles instead of oscillating. It may be switched on when a run is continued (a run
    saved before it kept no moments of its best layer: that layer is scored once more, by a
    fresh Adam); each binary row records its ``lr``.

    Returns ``{"theta", "history", "beta"}``; ``history``: one row per step (``step``, ``beta``,
    ``binary``, ``psnr``, ``mse``, ``reflection``, ``seconds``).

    ``steps`` 0: binary steps only, from the start as given (a binary start such as a
    published design: the steps descend on fabricable layers from the first).

    Raises:
        FullwaveError: No steps, steps or binary steps below 0, a learning rate or sharpness of
            0 or less, or ``out`` holding a run of other settings (or one saved before binary
            layers kept their minimum feature).
    """
    import time
    from pathlib import Path

    rate = lr if binary_lr is None else binary_lr
    if (
        min(steps, binary_steps) < 0
        or steps + binary_steps < 1
        or not min(lr, rate) > 0
        or not 0 < beta_start <= beta_end
    ):
        raise FullwaveError(
            f"steps >= 0, binary steps >= 0 (at least one step in all), learning rates > 0 and "
            f"0 < beta start <= beta end, got {steps}, {binary_steps}, {lr}, {rate}, "
            f"{beta_start}, {beta_end}"
        )
    out = Path(out)
    settings = {**(settings or {}), "steps": steps, "lr": lr, "beta": [beta_start, beta_end]}
    # Binary layers keep the minimum feature (FullwaveDesign.binary): a run saved before they
    # did scored other layers, and is not continued.
    settings["binary_layer"] = "keeps the minimum feature"
    if binary_steps:  # absent otherwise: runs saved before binary steps existed continue
        settings["binary_steps"] = binary_steps
        if binary_lr is not None:
            settings["binary_lr"] = binary_lr
    if backtrack:
        settings["backtrack"] = True
    state_path = out / "state"
    theta = design.start().clone().requires_grad_(True)
    opt, history, best = _restored(state_path, settings, theta, steps, lr, rate)
    if history and progress is not None:  # a continued run shows where it stands at once
        progress(history[-1])
    for step in range(len(history), steps + binary_steps):
        start = time.perf_counter()
        binary = step >= steps
        if step == steps:  # the binary steps start: a fresh optimiser
            opt = torch.optim.Adam([theta], lr=rate)
        if binary and backtrack and _fell(history):
            opt = _back_to_best(theta, best, opt)
        beta = beta_at(min(step, steps - 1), steps, beta_start, beta_end)
        before = theta.detach().clone() if binary else None  # the layer a binary step scores
        opt.zero_grad()
        loss, info = design.objective(theta, beta, binary=binary)
        loss.backward()
        opt.step()
        if binary and (
            best is None
            or info["psnr"] >= _best_binary(history)
            or torch.equal(before, best["best"])  # the best layer scored again
        ):
            # the layer this step scored, before its update, and the step taken from it (a
            # backtrack takes it again, shorter, without scoring the layer again)
            best = {"best": before, **_step_from(theta, opt)}
        history.append(
            {
                "step": step + 1,
                "beta": round(beta, 4),
                "binary": binary,
                "psnr": info["psnr"],
                "mse": info["mse"],
                "reflection": info["reflection"],
                "seconds": round(time.perf_counter() - start, 2),
                **({"lr": opt.param_groups[0]["lr"]} if binary else {}),
            }
        )
        _save_state(state_path, theta, opt, best, settings, history)
        if progress is not None:
            progress(history[-1])
    return {
        "theta": theta.detach() if best is None else best["best"],
        "history": history,
        "beta": beta_end if binary_steps else beta_at(steps - 1, steps, beta_start, beta_end),
    }


def _restored(
    state_path: Any, settings: dict, theta: torch.Tensor, steps: int, lr: float, rate: float
) -> tuple[torch.optim.Adam, list[dict], torch.Tensor | None]:
    """The optimiser, history and best binary layer of a run saved at ``state_path`` (the
    design variables copied into ``theta``), or a fresh start where nothing is saved."""
    from ..io.tensorfiles import load_pair, paired_paths

    opt = torch.optim.Adam([theta], lr=lr)
    if not paired_paths(state_path)[1].exists():
        return opt, [], None
    tensors, meta, _ = load_pair(state_path, STATE_FORMAT, 1, "design state", FullwaveError)
    if _fixed(meta["settings"]) != _fixed(json_safe(settings)):
        older = "binary_layer" not in meta["settings"]
        raise FullwaveError(
            f"{state_path.parent} holds a design run of other settings"
            + (" (saved before binary layers kept their minimum feature)" if older else "")
            + "; give another folder"
        )
    with torch.no_grad():
        theta.copy_(tensors["theta"])
    history = meta["history"]
    done = len(history)  # the steps the saved moments have seen
    if done > steps:  # in the binary steps: their own optimiser, at the rate it last had
        opt, done = torch.optim.Adam([theta], lr=history[-1].get("lr", rate)), done - steps
    if history and len(history) != steps:  # (at ``steps`` the binary optimiser starts fresh)
        opt.state[theta] = {
            "step": torch.tensor(float(meta.get("adam_step", done))),
            "exp_avg": tensors["exp_avg"].clone(),
            "exp_avg_sq": tensors["exp_avg_sq"].clone(),
        }
    best = {k: v for k, v in tensors.items() if k.startswith("best")}
    return opt, history, best or None


def _fell(history: list[dict]) -> bool:
    """Whether the last step was a binary one that scored below the best binary layer
    before it."""
    return (
        bool(history)
        and bool(history[-1].get("binary"))
        and (history[-1]["psnr"] < _best_binary(history[:-1]))
    )


def _step_from(theta: torch.Tensor, opt: torch.optim.Adam) -> dict[str, torch.Tensor]:
    """The step the optimiser just took from the best layer: where it led, at which rate, and
    Adam's moments and count after it."""
    moments = opt.state[theta]
    return {
        "best_after": theta.detach().clone(),
        "best_lr": torch.tensor(float(opt.param_groups[0]["lr"])),
        "best_adam_step": torch.tensor(float(moments["step"])),
        "best_exp_avg": moments["exp_avg"].clone(),
        "best_exp_avg_sq": moments["exp_avg_sq"].clone(),
    }


def _back_to_best(
    theta: torch.Tensor, best: dict[str, torch.Tensor], opt: torch.optim.Adam
) -> torch.optim.Adam:
    """The step from the best binary layer taken again at half the rate of the step that fell
    (an Adam at that rate, with the moments it had there); where that step was not kept (a run
    saved before backtracking), ``theta`` back at the best layer and a fresh Adam."""
    rate = opt.param_groups[0]["lr"] / 2
    back = torch.optim.Adam([theta], lr=rate)
    with torch.no_grad():
        theta.copy_(best["best"])
        if "best_after" in best:
            theta.add_((best["best_after"] - best["best"]) * (rate / float(best["best_lr"])))
            back.state[theta] = {
                "step": best["best_adam_step"].clone(),
                "exp_avg": best["best_exp_avg"].clone(),
                "exp_avg_sq": best["best_exp_avg_sq"].clone(),
            }
    return back


def _fixed(settings: dict) -> dict:
    """The settings a continued run must share: all but the number of binary steps and
    whether they backtrack."""
    return {k: v for k, v in settings.items() if k not in ("binary_steps", "backtrack")}


def _save_state(
    state_path: Any,
    theta: torch.Tensor,
    opt: torch.optim.Adam,
    best: dict[str, torch.Tensor] | None,
    settings: dict,
    history: list[dict],
) -> None:
    """Everything a stopped run continues from: the variables, the optimiser's moments and
    its step count, the best binary layer so far (and the step taken from it), the settings
    and the history."""
    from ..io.tensorfiles import save_pair

    moments = opt.state[theta]
    tensors = {
        "theta": theta.detach(),
        "exp_avg": moments["exp_avg"],
        "exp_avg_sq": moments["exp_avg_sq"],
        **(best or {}),
    }
    meta = {
        "settings": json_safe(settings),
        "history": history,
        "adam_step": int(moments["step"]),
    }
    save_pair(state_path, tensors, STATE_FORMAT, 1, meta)


def _best_binary(history: list[dict]) -> float:
    """The highest PSNR of the binary steps so far (-inf before any)."""
    return max((r["psnr"] for r in history if r.get("binary")), default=-math.inf)


def json_safe(value: Any) -> Any:
    """``value`` as it reads back from JSON (tuples as lists, numbers as floats or ints)."""
    import json

    return json.loads(json.dumps(value))
