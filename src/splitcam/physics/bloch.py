"""Where a router sends the light that arrives on each pixel: spatial kernels computed from the
full-wave fields, by Brillouin-zone integration (docs/model.md §20).

A periodic solve (:func:`~splitcam.physics.fullwave.quadrant_spectra`) gives the period's totals:
how much of the light arriving on the whole period lands on each pixel. It cannot say whether the
red that reaches the red pixel arrived above it or above its neighbour, and Eq. 2's kernels need
exactly that; the nearest-copy rule of
:meth:`~splitcam.patterns.spectral.SpectralPattern.from_transmission` assumes it. This module
computes it for a scene imaged through a lens.

**The light.** A point of the scene makes a focused spot: the lens's plane waves (direction sines
in a disk of radius ``1/(2N)`` about the chief ray's, equal power each) in phase at the spot's
centre. Spots are centred on a ``positions x positions`` grid inside each pixel.

**The solve.** A spot is an integral of Bloch waves over the Brillouin zone of the router's
lattice. Sampling the zone on ``M x M`` wavevectors is exactly a supercell of ``M x M`` periods
(``2M x 2M`` pixels) with one spot per supercell: one fmmax solve per wavevector (both
polarisations and every spot share it), the fields at the monitor plane summed over the
wavevectors, the time-averaged Poynting flux integrated over every pixel of the supercell and
divided by the spot's incident flux.

**The lens's own blur taken out.** Eq. 2's input is the light arriving on each pixel, already
blurred by the lens, and an f/2 spot spills over its pixel before any router acts. What the spots
of each pixel deliver is therefore fitted by kernels applied to where their light arrives
(``_unblur``), as shares of light (non-negative, each kernel summing to at most 1). Without a
router the kernels are the identity.

**What it cannot hold.** Light arriving on neighbouring pixels from one spot is coherent, so the
true response is not an intensity kernel; the fit's relative residual (``misfit``) says how far
from one it is. The kernels' totals over the period match the periodic solves of the pupil's
plane waves (tests/physics/test_bloch.py), so the answer for uniform scenes is kept. Light
travelling farther than ``M`` pixels wraps round the supercell; the pixel ``M`` away is split
between the kernel's two edges.

The cost is ``M^2`` solves per wavelength, each about as costly as one solve of
:func:`~splitcam.physics.fullwave.quadrant_spectra` at the same terms.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .fullwave import (
    FullwaveError,
    RouterDesign,
    _fmmax,
    _FmmaxStack,
    _off_grazing,
    _periodic_solve,
    _permittivities,
    _solved,
    _SolveLog,
    check_solver,
    cone_directions,
)

__all__ = ["pixel_kernels", "quadrant_sums"]


def _spot_centres(design: RouterDesign, cells: int, positions: int) -> np.ndarray:
    """``(4 * positions^2, 2)`` (x, y) spot centres, µm: a ``positions x positions`` grid inside
    each pixel of the supercell's middle period, pixels row-major (rows along y)."""
    middle = (cells // 2) * 2.0 * design.pitch
    steps = (np.arange(positions) + 0.5) / positions * design.pitch
    return np.asarray(
        [
            (middle + col * design.pitch + ox, middle + row * design.pitch + oy)
            for s in range(4)
            for row, col in [divmod(s, 2)]
            for oy in steps
            for ox in steps
        ]
    )


def _spot_amplitudes(fields, ambient, waves, inside, centres) -> Any:
    """``(2n, 2 * spots)`` forward amplitudes in the ambient: for each of fmmax's two
    polarisations and each centre, the pupil's plane waves (``inside``, 1 or 0 per wave) at
    equal power, phased so that they meet at the centre (a lens's focused spot)."""
    import jax.numpy as jnp

    n = waves.shape[0]
    unit = jnp.eye(2 * n, dtype=complex)
    power = fields.amplitude_poynting_flux(unit, jnp.zeros_like(unit), ambient)[0]
    power = power.sum(axis=0)  # the flux of each unit amplitude
    phase = jnp.exp(-1j * waves @ centres.T)  # (n, spots)
    forward = jnp.zeros((2 * n, 2, centres.shape[0]), complex)
    for p in (0, 1):
        weight = inside / jnp.sqrt(jnp.maximum(jnp.real(power[p * n : (p + 1) * n]), 1e-300))
        forward = forward.at[p * n : (p + 1) * n, p].set(weight[:, None] * phase)
    return forward.reshape(2 * n, -1)  # [.., (polarisation, spot)]


def _bloch_fields(design: RouterDesign, setting: dict[str, Any]) -> tuple[Callable, Any, int]:
    """The solve of one Bloch wavevector as a compiled JAX function (one per stack and setting,
    kept: every wavevector and wavelength reuses the compilation), its expansion's orders and
    its terms: ``(density, um, eps, wavevector, inside) -> [incident, reflected, arriving]``,
    each ``(ex, ey, hx, hy)`` over the supercell's grid and the (polarisation, spot) columns."""
    items = (k for k in setting.items() if k[0] not in ("f_number", "chief_sines"))
    return _compiled_bloch(design.stack(), tuple(sorted(items)))


@functools.lru_cache(maxsize=8)
def _compiled_bloch(stack, setting_items) -> tuple[Callable, Any, int]:
    """The Bloch solve of one stack (:meth:`RouterDesign.stack`) and setting, compiled once:
    the periodic solve with the spots' plane waves as the incident light, the fields over the
    supercell."""
    _, fields, _, _ = _fmmax()
    import jax
    import jax.numpy as jnp

    setting = dict(setting_items)
    design = RouterDesign.blank(stack)
    cells, samples, positions = setting["cells"], setting["samples"], setting["positions"]
    period = 2.0 * design.pitch
    fmmax_stack = _FmmaxStack.of(design, setting["terms"], setting["formulation"])
    orders = np.asarray(fmmax_stack.expansion.basis_coefficients, dtype=np.float64)  # (n, 2)
    centres = jnp.asarray(_spot_centres(design, cells, positions))
    grid = (2 * samples, 2 * samples)

    @jax.jit
    def solve(density, um, eps, wavevector, inside):
        waves = wavevector + 2 * np.pi * orders / period  # (n, 2)

        def spots(ambient):
            return _spot_amplitudes(fields, ambient, waves, inside, centres)

        sol = _periodic_solve(fmmax_stack, density, um, eps, wavevector, spots)
        out = []
        for f, b, result in (
            (sol["forward"], sol["zero"], sol["ambient"]),  # incident
            (sol["zero"], sol["reflected"], sol["ambient"]),  # reflected
            (sol["arriving"], sol["zero"], sol["substrate"]),  # arriving
        ):
            e, h = fields.fields_from_wave_amplitudes(f, b, result)
            (ex, ey, _), (hx, hy, _), _ = fields.fields_on_grid(
                e, h, result, grid, num_unit_cells=(cells, cells)
            )  # over the supercell, with this wavevector's Bloch phase from cell to cell
            out.append((ex, ey, hx, hy))
        return out

    return solve, orders, int(fmmax_stack.expansion.num_terms)


def _one_wavelength(
    design: RouterDesign,
    lam: float,
    setting: dict[str, Any],
) -> tuple[np.ndarray, float, float, int]:
    """``((2, 4, 2M+1, 2M+1)`` kernels per polarisation and source pixel, the reflected share
    averaged over both, the fit's misfit (the larger of the two polarisations'), the Fourier
    terms)`` at one wavelength.

    One solve per Bloch wavevector (compiled once, :func:`_bloch_fields`), the fields summed
    over them (each solve on its own: fmmax's batched stacking of scattering matrices was seen
    to stall in XLA's CPU runtime)."""
    basis, _, _, _ = _fmmax()
    import jax.numpy as jnp

    cells, samples, positions = setting["cells"], setting["samples"], setting["positions"]
    solve, orders, n = _bloch_fields(design, setting)
    period = 2.0 * design.pitch
    lattice = basis.LatticeVectors(u=basis.X * period, v=basis.Y * period)
    um = _off_grazing(lam, period, design) / 1000.0
    eps = _permittivities(design, lam)
    zone = np.asarray(basis.brillouin_zone_in_plane_wavevector((cells, cells), lattice))
    zone = zone.reshape(-1, 2)
    k0 = 2 * np.pi * math.sqrt(eps[1]) / um
    centre = np.asarray(setting["chief_sines"]) * k0
    density = jnp.asarray(design.grid)
    summed: list | None = None
    pupil = 0
    for wavevector in zone:
        # The lens's pupil: the plane waves of this wavevector whose direction sines lie in the
        # disk of radius 1/(2N) about the chief ray's, each carrying the same power.
        waves = wavevector + 2 * np.pi * orders / period  # (n, 2)
        inside = np.linalg.norm(waves - centre, axis=-1) <= k0 / (2.0 * setting["f_number"])
        if not inside.any():
            continue
        pupil += int(inside.sum())
        parts = solve(
            density,
            jnp.asarray(um),
            jnp.asarray(eps),
            jnp.asarray(wavevector),
            jnp.asarray(inside, dtype=float),
        )
        parts = [[np.asarray(a) for a in fields] for fields in parts]
        if summed is None:
            summed = parts
        else:
            summed = [
                [a + b for a, b in zip(old, new, strict=True)]
                for old, new in zip(summed, parts, strict=True)
            ]
    if not pupil or summed is None:
        raise FullwaveError("no plane wave of the Bloch grid falls in the lens's pupil")
    named = dict(zip(("incident", "reflected", "arriving"), summed, strict=True))

    def flux(name):  # [X, Y, column] over the supercell
        ex, ey, hx, hy = named[name]
        return 0.5 * np.real(ex * np.conj(hy) - ey * np.conj(hx))

    arriving_flux, incident_flux = flux("arriving"), flux("incident")
    incident = incident_flux.sum(axis=(0, 1))  # [column]
    reflected = -flux("reflected").sum(axis=(0, 1)) / incident
    pixels = 2 * cells

    def per_pixel(f):  # [Y, X, polarisation, source]: shares per pixel, mean over the spots
        shares = (f / incident).reshape(pixels, samples, pixels, samples, -1).sum(axis=(1, 3))
        shares = shares.reshape(pixels, pixels, 2, 4, positions * positions).mean(axis=-1)
        return shares.transpose(1, 0, 2, 3)

    detected, arrived = per_pixel(arriving_flux), per_pixel(incident_flux)
    kernels = np.zeros((2, 4, pixels + 1, pixels + 1))
    misfit = 0.0
    for p in (0, 1):
        torus, error = _unblur(detected[:, :, p], arrived[:, :, p], cells)
        misfit = max(misfit, error)
        for s in range(4):
            kernels[p, s] = _fold(torus[s], 0, 0, cells)
    return kernels, float(reflected.mean()), misfit, int(n)


def _unblur(detected: np.ndarray, arrived: np.ndarray, cells: int) -> tuple[np.ndarray, float]:
    """The kernels on the supercell's torus, ``(4, 2M, 2M)`` (type of source pixel, offset
    ``(dy, dx)`` mod 2M), from what the spots of each source pixel deliver (``detected``,
    ``(2M, 2M, 4)``) and where their light arrives (``arrived``, the same shape: the lens's own
    blur at the pixels, before the router): ``detected_s(q) = sum_r arrived_s(r) K_type(r)(q -
    r)``, one equation per source and pixel, as many as unknowns, solved in the least-squares
    sense for kernels that are shares of light (non-negative, each summing to at most 1), with
    the relative residual: the part of the coherent truth that no intensity kernel
    reproduces. Without a router (``detected = arrived``) every kernel is the identity and the
    residual 0."""
    pixels = 2 * cells
    size = pixels * pixels
    system = np.zeros((4 * size, 4 * size))
    for s in range(4):
        for qy in range(pixels):
            for qx in range(pixels):
                row = s * size + qy * pixels + qx
                for dy in range(pixels):
                    for dx in range(pixels):
                        ry, rx = (qy - dy) % pixels, (qx - dx) % pixels
                        kind = (ry % 2) * 2 + rx % 2
                        system[row, kind * size + dy * pixels + dx] += arrived[ry, rx, s]
    from scipy.optimize import minimize, nnls

    target = detected.transpose(2, 0, 1).reshape(-1)
    start, _ = nnls(system, target, maxiter=50 * system.shape[1])
    sums = start.reshape(4, -1).sum(axis=1)
    start = (start.reshape(4, -1) / np.maximum(sums, 1.0)[:, None]).reshape(-1)
    gram, rhs = system.T @ system, system.T @ target
    fit = minimize(
        lambda k: (0.5 * k @ gram @ k - rhs @ k, gram @ k - rhs),
        start,
        jac=True,
        method="SLSQP",
        bounds=[(0.0, 1.0)] * len(start),
        constraints=[
            {"type": "ineq", "fun": lambda k, t=t: 1.0 - k[t * size : (t + 1) * size].sum()}
            for t in range(4)
        ],
        options={"maxiter": 500, "ftol": 1e-14},
    )
    solution = np.clip(fit.x, 0.0, None)
    residual = np.linalg.norm(system @ solution - target) / np.linalg.norm(target)
    return solution.reshape(4, pixels, pixels), float(residual)


def _fold(shares: np.ndarray, sy: int, sx: int, cells: int) -> np.ndarray:
    """The ``2M x 2M`` pixel shares of a supercell as a ``(2M+1)^2`` kernel of offsets from the
    source pixel ``(sy, sx)``: offsets ``-M+1 .. M-1`` as they are, the pixel ``M`` away (reached
    both ways round the supercell) split between offsets ``-M`` and ``+M``."""
    pixels = 2 * cells
    kernel = np.zeros((pixels + 1, pixels + 1))
    for y in range(pixels):
        dy = (y - sy + cells) % pixels - cells  # in -M .. M-1
        ys = [dy] if dy != -cells else [-cells, cells]
        for x in range(pixels):
            dx = (x - sx + cells) % pixels - cells
            xs = [dx] if dx != -cells else [-cells, cells]
            for oy in ys:
                for ox in xs:
                    kernel[oy + cells, ox + cells] += shares[y, x] / (len(ys) * len(xs))
    return kernel


def quadrant_sums(kernels: np.ndarray) -> np.ndarray:
    """``(2, 2, L)``: what each pixel of the period receives when every pixel sends by
    ``kernels`` (``(4, L, k, k)``, sources row-major in the 2x2 period) under uniform light,
    as a share of the light arriving on the period: comparable with the periodic solve's
    ``transmission``."""
    k = np.asarray(kernels)
    half = k.shape[-1] // 2
    out = np.zeros((2, 2, k.shape[1]))
    for s in range(4):
        row, col = divmod(s, 2)
        for dy in range(-half, half + 1):
            for dx in range(-half, half + 1):
                out[(row + dy) % 2, (col + dx) % 2] += k[s, :, dy + half, dx + half] / 4.0
    return out


def _checked_setting(
    f_number: float,
    chief_ray: float,
    azimuth: float,
    cells: int,
    positions: int,
    terms: int,
    formulation: str,
    samples: int,
) -> dict[str, Any]:
    """:func:`pixel_kernels`' settings, refused before any solve where they cannot be run."""
    for name, value, low in (
        ("cells", cells, 2),
        ("positions", positions, 1),
        ("terms", terms, 1),
        ("samples", samples, 1),
    ):
        if int(value) != value or value < low:
            raise FullwaveError(f"{name} must be a whole number >= {low}, got {value}")
    if formulation not in ("JONES_DIRECT", "FFT"):
        raise FullwaveError(f"formulation: JONES_DIRECT or FFT, got {formulation!r}")
    cone_directions(f_number, chief_ray, azimuth)  # the same checks as the periodic solves
    check_solver("fmmax-jones")  # installed, before any solve
    return {
        "cells": int(cells),
        "positions": int(positions),
        "terms": int(terms),
        "samples": int(samples),
        "formulation": formulation,
        "f_number": float(f_number),
        "chief_sines": (
            math.sin(chief_ray) * math.cos(azimuth),
            math.sin(chief_ray) * math.sin(azimuth),
        ),
    }


def pixel_kernels(
    design: RouterDesign,
    wavelengths: Sequence[float],
    *,
    f_number: float = 2.0,
    chief_ray: float = 0.0,
    azimuth: float = 0.0,
    cells: int = 3,
    positions: int = 2,
    terms: int = 361,
    formulation: str = "JONES_DIRECT",
    samples: int = 16,
    progress: Callable[[int], None] | None = None,
    cache: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """The kernels of a 2x2 router computed from its fields, for a scene imaged through a lens
    (the module docstring).

    Args:
        design: The router.
        wavelengths: nm.
        f_number: Of the lens: its pupil is the disk of direction sines of radius ``1/(2N)``.
        chief_ray: The chief ray's angle off the normal, radians (0: the centre of the field).
        azimuth: Towards which the chief ray tilts (0: along x, the design's columns).
        cells: ``M``: the Brillouin zone sampled on ``M x M`` wavevectors, a supercell of
            ``2M x 2M`` pixels; kernels are ``(2M+1) x (2M+1)``. At least 2.
        positions: Spot centres per pixel and axis (``positions^2`` per pixel).
        terms: About this many Fourier terms (fmmax, circular truncation).
        formulation: fmmax's ``JONES_DIRECT`` or ``FFT``.
        samples: Grid points per pixel and axis of the flux integral.
        progress: Called with the number of wavelengths done.
        cache: A JSON-lines file where each wavelength's result is appended as soon as it is
            solved; a run given the same file continues where it stopped.

    Returns:
        ``kernels``: ``(4, L, 2M+1, 2M+1)``, source pixels row-major in the period (rows along
        y), averaged over the two polarisations: the share of the light arriving on the source
        pixel that lands on each offset; ``by_polarisation``: ``(2, 4, L, 2M+1, 2M+1)``;
        ``reflection``: ``(L,)``; ``terms``; ``cost`` (``solves``: wavelengths times ``M^2``
        Bloch wavevectors, ``reused``, ``seconds``).

    Raises:
        FullwaveError: ``cells`` below 2, ``positions``, ``terms`` or ``samples`` below 1, an
            unknown formulation, an f-number or chief ray :func:`~splitcam.physics.fullwave.
            cone_directions` refuses, or fmmax not installed (the message names the install
            command).
    """
    setting = _checked_setting(
        f_number, chief_ray, azimuth, cells, positions, terms, formulation, samples
    )
    size = 2 * cells + 1
    log = None
    if cache is not None:
        extra = {k: setting[k] for k in ("cells", "positions", "f_number", "chief_sines")}
        log = _SolveLog(
            cache,
            design,
            f"fmmax-{formulation.lower()}-bloch",
            terms,
            samples,
            extra=extra,
            shape=(2, 4, size, size),
        )
    by_pol = np.zeros((2, 4, len(wavelengths), size, size))
    reflection = np.zeros(len(wavelengths))
    misfit = np.zeros(len(wavelengths))
    cost = {"solves": 0, "reused": 0, "seconds": 0.0}
    count = int(terms)

    def solve(lam: float, *_: float) -> tuple[np.ndarray, float, dict[str, Any]]:
        found, reflected, fit, used = _one_wavelength(design, lam, setting)
        return found, reflected, {"misfit": fit, "terms": used}

    keys = [(lam, chief_ray, azimuth) for lam in wavelengths]
    for li, (kernels, reflected, seconds, reused, notes) in enumerate(
        _solved(keys, log, solve, (), 1)
    ):
        misfit[li], count = notes["misfit"], notes["terms"]
        cost["reused"] += cells * cells * reused
        cost["solves"] += cells * cells
        cost["seconds"] += seconds
        by_pol[:, :, li] = kernels
        reflection[li] = reflected
        if progress is not None:
            progress(li + 1)
    return {
        "kernels": by_pol.mean(axis=0),
        "by_polarisation": by_pol,
        "reflection": reflection,
        "misfit": misfit,
        "terms": count,
        "cost": cost,
    }
