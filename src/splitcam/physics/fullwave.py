"""Full-wave spectra of a 2x2-pixel metasurface colour router, by rigorous coupled-wave analysis.

The scalar optics of :mod:`splitcam.physics.optics` treat a metasurface as a thin phase mask;
a designer trusts Maxwell's equations. This module solves them for one periodic layer of pillars
(a grid of cells, each 1 = pillar material, 0 = background, or a density in between, whose
permittivity is interpolated linearly) on a substrate, lit from above at normal incidence or at
an angle, in both polarisations, and counts the transmitted power that crosses each pixel
quadrant of a monitor plane inside the substrate: the time-averaged z-component of the Poynting
vector, ``0.5 Re(E x H*)``, integrated over the quadrant (midpoint rule on a fine grid). The
reflected power is counted independently just above the layer (incident minus reflected flux),
so transmission plus reflection = 1 checks the solve.

The default solver is torcwa (Kim & Lee, *TORCWA: GPU-accelerated Fourier modal method and
gradient-based optimization for metasurface design*, Computer Physics Communications 282, 2023),
a PyTorch RCWA: the optional extra ``splitcam[fullwave]``. It was chosen over fmmax (JAX) by the
side-by-side measurement in docs/results/fullwave/: the same numbers at the same Fourier terms, no
second array library beside torch. ``order`` ``m`` keeps the ``(2m + 1)^2`` lowest Fourier terms.

fmmax (Schubert & Hammond, the solver of the invrs-gym leaderboard; the extra
``splitcam[fmmax]``) is the second solver behind the same function (``solver="fmmax-fft"`` or
``"fmmax-jones"``): its Jones-direct formulation converges from the other side on sharp pillar
edges, and it is how a design is scored at the leaderboard's settings (about 1000 terms in a
circular truncation, ``terms=1000``).

Materials are published dispersion fits, written here: silicon nitride after Luke et al.,
*Broadband mid-infrared frequency comb generation in a Si3N4 microresonator*, Opt. Lett. 40,
2015 (Sellmeier, 0.31-5.5 µm); fused silica after Malitson, *Interspecimen comparison of the
refractive index of fused silica*, JOSA 55, 1965 (0.21-3.71 µm). Nothing is downloaded.
"""

from __future__ import annotations

import functools
import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..checks import check_count
from ..io import appending, read_json_lines

__all__ = [
    "MATERIALS",
    "SOLVERS",
    "FullwaveError",
    "RouterDesign",
    "band_efficiencies",
    "band_purities",
    "check_solver",
    "cone_directions",
    "fmmax_quadrants",
    "index_of",
    "quadrant_spectra",
    "solve_quadrants",
    "read_design",
    "torcwa_quadrants",
]

INSTALL = "pip install 'splitcam[fullwave]'"
INSTALL_FMMAX = "pip install 'splitcam[fmmax]'"

#: The solvers :func:`quadrant_spectra` runs: torcwa, or fmmax in one of its formulations.
SOLVERS = ("torcwa", "fmmax-fft", "fmmax-jones")


class FullwaveError(ValueError):
    """A design, a material or a setting the full-wave solver cannot take; one line."""


def _sellmeier(terms: Sequence[tuple[float, float]]) -> Callable[[np.ndarray], np.ndarray]:
    def index(um: np.ndarray) -> np.ndarray:
        l2 = np.asarray(um, dtype=np.float64) ** 2
        return np.sqrt(1 + sum(b * l2 / (l2 - c**2) for b, c in terms))

    return index


#: Refractive index against wavelength in µm, by name.
MATERIALS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "Si3N4": _sellmeier([(3.0249, 0.1353406), (40314.0, 1239.842)]),
    "SiO2": _sellmeier([(0.6961663, 0.0684043), (0.4079426, 0.1162414), (0.8974794, 9.896161)]),
    "vacuum": lambda um: np.ones_like(np.asarray(um, dtype=np.float64)),
}


def material_of(text: str | float) -> str | float:
    """A material as given in text: a number is an index, anything else a name of
    :data:`MATERIALS` (checked where it is used)."""
    try:
        return float(text)
    except ValueError:
        return text


def index_of(material: str | float, wavelength_nm: float) -> float:
    """The refractive index of a named material (:data:`MATERIALS`) or a number."""
    if isinstance(material, (int, float)):
        return float(material)
    try:
        return float(MATERIALS[material](wavelength_nm / 1000.0))
    except KeyError:
        raise FullwaveError(
            f"unknown material {material!r}; known: {', '.join(MATERIALS)}, or an index"
        ) from None


@dataclass(frozen=True)
class RouterDesign:
    """A 2x2-pixel metasurface router of one patterned layer or several stacked (lengths in µm).

    Args:
        grid: ``(rows, columns)`` densities in [0, 1] over the period of one layer, or
            ``(layers, rows, columns)`` of layers stacked, the first the one the light meets
            first; rows run along y, columns along x, as written in a design file.
        pitch: Pixel pitch (the period is two pixels each way).
        thickness: Of the patterned layer, or one per layer (a single number: each layer's).
        depth: Of the monitor plane below the last layer, inside the substrate.
        pillar: The pillars' material (a name of :data:`MATERIALS` or an index).
        background: Between the pillars; light arrives through it.
        substrate: Below the layers, where the monitor plane lies.
        spacer: Of the background between one layer and the next (0: the layers touch).
    """

    grid: np.ndarray
    pitch: float = 1.0
    thickness: float | tuple[float, ...] = 0.6
    depth: float = 2.4
    pillar: str | float = "Si3N4"
    background: str | float = "vacuum"
    substrate: str | float = "SiO2"
    spacer: float = 0.0

    def __post_init__(self) -> None:
        grid = np.asarray(self.grid, dtype=np.float64)
        if grid.ndim not in (2, 3) or min(grid.shape) < 1:
            raise FullwaveError(
                f"a design is a 2-D grid, or a 3-D stack of layers' grids, got shape {grid.shape}"
            )
        if not np.all(np.isfinite(grid)) or grid.min() < 0 or grid.max() > 1:
            raise FullwaveError("a design's cells are densities in [0, 1]")
        # One number for every layer (a sequence of one is that number: a one-layer design's
        # thickness stays a number, as its solve logs and descriptions record it).
        thickness = tuple(float(t) for t in np.atleast_1d(self.thickness))
        layers = grid.shape[0] if grid.ndim == 3 else 1
        if len(thickness) not in (1, layers):
            raise FullwaveError(
                f"{len(thickness)} thicknesses for a design of {layers} layer(s): give one "
                f"per layer, or one for every layer"
            )
        thickness = thickness[0] if len(thickness) == 1 else thickness
        if not self.pitch > 0:
            raise FullwaveError(f"pitch must be > 0 µm, got {self.pitch}")
        for value in np.atleast_1d(thickness):
            if not value > 0:
                raise FullwaveError(f"thickness must be > 0 µm, got {value}")
        for name in ("depth", "spacer"):
            if not getattr(self, name) >= 0:
                raise FullwaveError(f"{name} must be >= 0 µm, got {getattr(self, name)}")
        for material in (self.pillar, self.background, self.substrate):
            index_of(material, 550.0)
        object.__setattr__(self, "grid", grid)
        object.__setattr__(self, "thickness", thickness)

    @property
    def layers(self) -> np.ndarray:
        """``(layers, rows, columns)``: the grid of each layer, the first the one light meets
        first (one layer for a 2-D grid)."""
        return self.grid if self.grid.ndim == 3 else self.grid[None]

    @property
    def cells(self) -> tuple[int, int]:
        """``(rows, columns)`` of each layer's grid."""
        rows, cols = self.grid.shape[-2:]
        return rows, cols

    @property
    def thicknesses(self) -> tuple[float, ...]:
        """Each layer's thickness, from the top."""
        if isinstance(self.thickness, tuple):
            return self.thickness
        return (float(self.thickness),) * len(self.layers)

    def stack(self) -> tuple[Any, ...]:
        """Everything but the cells' densities, hashable: the grid's shape, the lengths and the
        materials (:meth:`blank` makes a design of it again). Solvers compiled for one stack
        are kept under it."""
        lengths = (self.pitch, self.thicknesses, self.depth, self.spacer)
        return self.grid.shape, lengths, (self.pillar, self.background, self.substrate)

    @classmethod
    def blank(cls, stack: tuple[Any, ...]) -> RouterDesign:
        """A design of :meth:`stack`'s stack, every cell 0."""
        shape, (pitch, thicknesses, depth, spacer), materials = stack
        return cls(np.zeros(shape), pitch, thicknesses, depth, *materials, spacer=spacer)


def read_design(path: str | os.PathLike) -> np.ndarray:
    """A design CSV: a rectangular grid of numbers in [0, 1] (commas, one row per line).

    Raises:
        FullwaveError: Missing file, a ragged or non-numeric grid, or values outside [0, 1];
            the message names the file and the row.
    """
    path = Path(path)
    try:
        lines = [line for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise FullwaveError(f"cannot read design {str(path)!r}: {exc}") from None
    rows = []
    for i, line in enumerate(lines, 1):
        try:
            rows.append([float(v) for v in line.split(",")])
        except ValueError:
            raise FullwaveError(f"design {str(path)!r}, row {i}: not a list of numbers") from None
        if len(rows[-1]) != len(rows[0]):
            raise FullwaveError(
                f"design {str(path)!r}, row {i}: {len(rows[-1])} cells, row 1 has "
                f"{len(rows[0])} (the grid must be rectangular)"
            )
    if not rows:
        raise FullwaveError(f"design {str(path)!r} is empty")
    grid = np.array(rows)
    if not np.all(np.isfinite(grid)) or grid.min() < 0 or grid.max() > 1:
        raise FullwaveError(f"design {str(path)!r}: cells must be densities in [0, 1]")
    return grid


def cone_directions(
    f_number: float | None, chief_ray: float = 0.0, azimuth: float = 0.0
) -> list[tuple[float, float, float]]:
    """``(polar angle, azimuth, weight)`` (radians) of the light a lens of ``f_number`` sends
    to a pixel whose chief ray arrives ``chief_ray`` (radians) off the normal, tilted towards
    ``azimuth`` (0: along x, the design's columns; pi/4: along the diagonal, towards a corner
    of the field).

    The exit pupil is a disk of uniform irradiance, and a lens that obeys the sine condition
    fills a disk of direction sines ``sin(theta) (cos phi, sin phi)`` of radius
    ``1 / (2 N)`` centred on the chief ray's sines. The 7-point rule (the centre, weight 1/4,
    and six points at ``sqrt(2/3)`` of the radius, 1/8 each) integrates polynomials up to
    degree 5 over the disk exactly (tests/physics/test_fullwave.py). ``f_number`` None: a
    collimated beam along the chief ray (one direction).

    Raises:
        FullwaveError: An f-number of 0.5 or less, or a chief ray whose cone reaches grazing
            incidence (direction sines of 1 or more) or points outside [0, 90) degrees.
    """
    if f_number is not None and not f_number > 0.5:
        raise FullwaveError(f"f-number must be > 0.5, got {f_number}")
    if not 0.0 <= chief_ray < math.pi / 2:
        raise FullwaveError(
            f"chief-ray angle must be in [0, 90) degrees, got {math.degrees(chief_ray):g}"
        )
    radius = 0.0 if f_number is None else 1.0 / (2.0 * f_number)
    if math.sin(chief_ray) + radius >= 1.0:
        raise FullwaveError(
            f"a chief ray of {math.degrees(chief_ray):g} degrees with an f/{f_number:g} cone "
            f"reaches grazing incidence (sine {math.sin(chief_ray) + radius:.3f} >= 1)"
        )
    # (sine, azimuth, weight) of each point about the disk's centre.
    points = [(0.0, 0.0, 0.25 if f_number is not None else 1.0)]
    if f_number is not None:
        points += [(math.sqrt(2.0 / 3.0) * radius, k * math.pi / 3.0, 0.125) for k in range(6)]
    if chief_ray == 0.0:
        return [(math.asin(r), phi, w) for r, phi, w in points]
    cu, cv = math.sin(chief_ray) * math.cos(azimuth), math.sin(chief_ray) * math.sin(azimuth)
    out = []
    for r, phi, weight in points:
        u, v = cu + r * math.cos(phi), cv + r * math.sin(phi)
        out.append((math.asin(math.hypot(u, v)), math.atan2(v, u), weight))
    return out


def check_solver(solver: str) -> None:
    """Refuse a solver whose optional extra is not installed, before any work (the message
    gives the install command); nothing is imported.

    Raises:
        FullwaveError: ``torcwa`` without ``splitcam[fullwave]``, or an fmmax solver without
            ``splitcam[fmmax]``.
    """
    import importlib.util

    if solver == "torcwa" and importlib.util.find_spec("torcwa") is None:
        raise FullwaveError(f"the full-wave solver is an optional extra: {INSTALL}")
    if solver.startswith("fmmax") and (
        importlib.util.find_spec("fmmax") is None or importlib.util.find_spec("jax") is None
    ):
        raise FullwaveError(f"the fmmax solver is an optional extra: {INSTALL_FMMAX}")


def _solver():
    try:
        import torcwa
    except ImportError:
        raise FullwaveError(f"the full-wave solver is an optional extra: {INSTALL}") from None
    return torcwa


def quadrant_spectra(
    design: RouterDesign,
    wavelengths: Sequence[float],
    *,
    order: int = 9,
    directions: Sequence[tuple[float, float, float]] = ((0.0, 0.0, 1.0),),
    samples: int = 64,
    solver: str = "torcwa",
    terms: int | None = None,
    progress: Callable[[int], None] | None = None,
    cache: str | os.PathLike | None = None,
    workers: int = 1,
) -> dict[str, Any]:
    """Transmission into each pixel quadrant of the monitor plane, per wavelength.

    Args:
        design: The router.
        wavelengths: nm.
        order: Fourier order per axis: ``(2 order + 1)^2`` terms.
        directions: ``(polar angle, azimuth, weight)`` of the incident light (radians; the
            weights are normalised): one direction, or a lens's cone (:func:`cone_directions`).
        samples: Grid points per pixel and axis of the flux integral.
        solver: One of :data:`SOLVERS`.
        terms: fmmax only: about this many Fourier terms in a circular truncation (default
            ``(2 order + 1)^2``).
        progress: Called with the number of wavelengths done.
        cache: A JSON-lines file where every solve (one wavelength, one direction, both
            polarisations) is appended as soon as it finishes, with the seconds it took; solves
            of the same design and setting found there are not repeated. An interrupted run
            given the same file continues where it stopped (at most the solve in progress is
            lost), and several runs may share one file.
        workers: Processes (spawned, one thread each) that share the solves not found in
            ``cache``; 1: every solve in this process. The same results either way.

    Returns:
        ``transmission``: ``(2, 2, L)`` the share of the light arriving on the period crossing
        each quadrant (rows along y, as the design), averaged over the two polarisations and
        the directions; ``by_polarisation``: ``(2, 2, 2, L)`` for the two polarisations
        (direction-averaged); ``reflection``: ``(L,)``; ``terms``: the Fourier terms solved;
        ``cost``: ``solves`` (wavelengths times directions), ``reused`` (of them, found in
        ``cache``) and ``seconds`` (of solving all of them, earlier runs' included).

    Raises:
        FullwaveError: A bad order, direction weights or solver name; the solver not installed
            (the message names the install command).
    """
    if order < 0:
        raise FullwaveError(f"order must be >= 0, got {order}")
    if solver not in SOLVERS:
        raise FullwaveError(f"unknown solver {solver!r}; expected one of {', '.join(SOLVERS)}")
    if terms is not None and (solver == "torcwa" or terms < 1):
        raise FullwaveError("terms: a number >= 1, for an fmmax solver (torcwa takes order)")
    weights = np.array([w for _, _, w in directions], dtype=np.float64)
    if weights.size == 0 or weights.min() < 0 or weights.sum() <= 0:
        raise FullwaveError("directions need non-negative weights")
    weights = weights / weights.sum()
    check_workers(workers)
    setting = (design, solver, order, terms, samples)
    solve, count = _spectra_solver(setting)
    log = _SolveLog(cache, design, solver, count, samples) if cache is not None else None
    keys = [(lam, theta, phi) for lam in wavelengths for theta, phi, _ in directions]
    solved = _solved(keys, log, solve, setting, workers)
    by_pol = np.zeros((2, 2, 2, len(wavelengths)))
    reflection = np.zeros(len(wavelengths))
    cost = {"solves": 0, "reused": 0, "seconds": 0.0}
    for li, _ in enumerate(wavelengths):
        for weight in weights:
            quads, reflected, seconds, reused, _ = next(solved)
            cost["reused"] += reused
            cost["solves"] += 1
            cost["seconds"] += seconds
            by_pol[..., li] += weight * quads
            reflection[li] += weight * reflected
        if progress is not None:
            progress(li + 1)
    solved.close()  # stops the worker processes, if any
    return {
        "transmission": by_pol.mean(axis=0),
        "by_polarisation": by_pol,
        "reflection": reflection,
        "terms": count,
        "cost": cost,
    }


def _spectra_solver(setting: tuple[RouterDesign, str, int, int | None, int]) -> tuple[_Solve, int]:
    """The solve of the design's own grid at ``setting`` (:func:`solve_quadrants`, without
    its gradient) as NumPy, and the Fourier terms it solves."""
    import torch

    design, solver, order, terms, samples = setting
    density = torch.from_numpy(np.asarray(design.grid, dtype=np.float64))

    def solve(lam: float, theta: float, phi: float) -> tuple[np.ndarray, float]:
        with torch.no_grad():
            quads, reflected = solve_quadrants(setting, density, lam, theta, phi)
        return quads.numpy(), float(reflected)

    if solver == "torcwa":
        return solve, (2 * order + 1) ** 2
    return solve, _fmmax_core(design, *_fmmax_setting(solver, order, terms), samples)[1]


def _fmmax_setting(solver: str, order: int, terms: int | None) -> tuple[int, str]:
    """An fmmax solver's Fourier terms asked for and its formulation."""
    formulation = "JONES_DIRECT" if solver == "fmmax-jones" else "FFT"
    return terms or (2 * order + 1) ** 2, formulation


def _solved(
    keys: list[tuple[float, float, float]],
    log: _SolveLog | None,
    solve: _Solve,
    setting: tuple[Any, ...],
    workers: int,
) -> Iterator[tuple[np.ndarray, float, float, bool, dict[str, Any]]]:
    """``(array, reflected, seconds, reused, notes)`` of each key in order: from ``log``
    where it holds the solve, else solved (here, or by ``workers`` processes when more than one
    solve is missing), each new solve timed and logged as it is taken. ``solve(*key)`` gives
    ``(array, reflected)``, or ``(array, reflected, notes)`` where a solve has more numbers to
    keep beside it (a dict; the worker processes' solves have none). The one place a solve is
    looked up, timed and logged: the spectra's and the Bloch kernels' alike."""
    todo = list(dict.fromkeys(k for k in keys if log is None or log.get(*k) is None))
    pool = None
    if workers > 1 and len(todo) > 1:
        from .solvepool import SolvePool

        pool = SolvePool(solve_quadrants, setting, min(workers, len(todo)))
        solutions = pool.solutions(np.asarray(setting[0].grid, dtype=np.float64), todo)
        results = ((*found, {}) for found in solutions)
    else:
        results = (_timed(solve, *key) for key in todo)
    try:
        fresh: dict[tuple[float, float, float], tuple[np.ndarray, float, float, dict]] = {}
        for key in keys:  # the missing ones come back in the order of todo: the order of keys
            if key in todo and key not in fresh:
                fresh[key] = next(results)
                if log is not None:
                    log.add(*key, *fresh[key])
            reused = key not in fresh
            array, reflected, seconds, notes = log.get(*key) if reused else fresh[key]
            yield array, reflected, seconds, reused, dict(notes or {})
    finally:
        if pool is not None:
            pool.close()


def check_workers(workers: Any) -> int:
    """``workers`` as an ``int`` >= 1 (:func:`splitcam.checks.check_count`), else
    :class:`FullwaveError`."""
    try:
        return check_count(workers, "workers", 1)
    except ValueError as exc:
        raise FullwaveError(str(exc)) from None


def _timed(solve: Callable[..., tuple], *key: float) -> tuple[np.ndarray, float, float, dict]:
    start = time.perf_counter()
    array, reflected, *notes = solve(*key)
    return array, reflected, time.perf_counter() - start, (notes[0] if notes else {})


def solve_quadrants(
    setting: tuple[RouterDesign, str, int, int | None, int],
    density: Any,
    lam: float,
    theta: float,
    phi: float,
) -> tuple[Any, Any]:
    """One solve of the design ``setting`` names, ``(design, solver, order, terms, samples)``,
    with its layers' cells set to ``density`` (a float64 tensor of the grid's shape): the
    ``(2, 2, 2)`` quadrant transmissions per polarisation and the reflection, differentiable
    in ``density`` (:func:`torcwa_quadrants`, :func:`fmmax_quadrants`). A module-level
    function of picklable arguments, so that worker processes
    (:mod:`splitcam.physics.solvepool`) run the very same solve."""
    design, solver, order, terms, samples = setting
    if solver == "torcwa":
        return torcwa_quadrants(design, density, lam, theta, phi, order, samples)
    terms, formulation = _fmmax_setting(solver, order, terms)
    return fmmax_quadrants(design, density, lam, theta, phi, terms, samples, formulation)


class _SolveLog:
    """The solves of one design at one solver setting, kept in a JSON-lines file shared with
    other settings and designs: each line is one solve, tagged with a digest of its setting."""

    def __init__(
        self,
        path,
        design: RouterDesign,
        solver: str,
        terms: int,
        samples: int,
        *,
        extra: dict[str, Any] | None = None,
        shape: tuple[int, ...] = (2, 2, 2),
    ) -> None:
        """``extra``: more of the setting (tagged only where given, so the digests of earlier
        logs are unchanged); ``shape``: of the array each solve stores."""
        import hashlib
        import json

        setting = {
            "grid": hashlib.sha256(
                repr(design.grid.shape).encode() + design.grid.tobytes()
            ).hexdigest(),
            **{k: getattr(design, k) for k in ("pitch", "thickness", "depth")},
            **{k: str(getattr(design, k)) for k in ("pillar", "background", "substrate")},
            **({"spacer": design.spacer} if len(design.layers) > 1 else {}),
            "solver": solver,
            "terms": int(terms),
            "samples": int(samples),
            **(extra or {}),
        }
        self.setting = hashlib.sha256(json.dumps(setting, sort_keys=True).encode()).hexdigest()[:16]
        self.path = Path(path)
        # each solve's (array, reflected share, seconds, notes)
        self.done: dict[tuple[str, str, str], tuple[np.ndarray, float, float, dict]] = {}
        rows, _ = read_json_lines(self.path)  # a line cut short by a killed run is skipped
        for _, _, rec in rows:
            try:
                if rec["setting"] == self.setting:
                    key = self._key(rec["wavelength"], rec["theta"], rec["phi"])
                    quads = np.asarray(rec["quadrants"], dtype=np.float64).reshape(shape)
                    notes = dict(rec.get("notes", {}))
                    self.done[key] = (quads, float(rec["reflection"]), float(rec["seconds"]), notes)
            except (ValueError, KeyError, TypeError):
                continue  # not a solve of this module

    @staticmethod
    def _key(lam: float, theta: float, phi: float) -> tuple[str, str, str]:
        return tuple(f"{float(v):.12g}" for v in (lam, theta, phi))

    def get(self, lam: float, theta: float, phi: float):
        """The logged ``(array, reflected share, seconds, notes)`` of a solve, or None."""
        return self.done.get(self._key(lam, theta, phi))

    def add(
        self,
        lam,
        theta,
        phi,
        quads: np.ndarray,
        reflected: float,
        seconds: float,
        notes: dict[str, Any] | None = None,
    ) -> None:
        """``notes``: more numbers of the solve, kept beside it (the last of :meth:`get`)."""
        import json

        rec = {
            "setting": self.setting,
            "wavelength": float(lam),
            "theta": float(theta),
            "phi": float(phi),
            "quadrants": np.asarray(quads, dtype=np.float64).tolist(),
            "reflection": float(reflected),
            "seconds": round(seconds, 2),
            **({"notes": notes} if notes else {}),
        }
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # After a line cut short by a killed run, start a new line rather than extend it.
        cut = (
            self.path.is_file() and self.path.stat().st_size > 0 and not _ends_in_newline(self.path)
        )
        with appending(self.path) as f:
            f.write(("\n" if cut else "") + json.dumps(rec) + "\n")
            f.flush()
            os.fsync(f.fileno())
        key = self._key(lam, theta, phi)
        self.done[key] = (np.asarray(quads), float(reflected), seconds, dict(notes or {}))


#: One solve: ``(wavelength nm, polar angle, azimuth)`` → ``((2, 2, 2)`` quadrant transmissions
#: for the two polarisations, the reflection averaged over them``)``.
_Solve = Callable[[float, float, float], tuple[np.ndarray, float]]


def _permittivities(design: RouterDesign, lam: float) -> tuple[float, float, float]:
    materials = (design.pillar, design.background, design.substrate)
    return tuple(index_of(m, lam) ** 2 for m in materials)


def torcwa_quadrants(
    design: RouterDesign,
    density: Any,
    lam: float,
    theta: float = 0.0,
    phi: float = 0.0,
    order: int = 9,
    samples: int = 64,
) -> tuple[Any, Any]:
    """One torcwa solve of ``design``'s stack with its layers' cells set to ``density`` (a
    float64 tensor of the grid's shape, values in [0, 1]), differentiable with respect to it:
    ``((2, 2, 2)`` quadrant transmissions per polarisation ``[p, row, column]``, the reflection
    averaged over the polarisations``)`` as tensors. What :func:`quadrant_spectra` computes
    with torcwa, exposed for designs optimised through Maxwell's equations
    (:mod:`splitcam.design.fullwave`)."""
    import torch

    torcwa = _solver()
    period = 2.0 * design.pitch
    n = 2 * samples
    coords = (torch.arange(n, dtype=torch.float64) + 0.5) / n * period
    fine = _fine_density(design, density)
    um = _off_grazing(lam, period, design) / 1000.0
    eps_p, eps_b, eps_s = _permittivities(design, lam)
    layers = [
        (eps_b + (eps_p - eps_b) * f.T).to(torch.complex128)  # [x, y]
        for f in fine.reshape(-1, *fine.shape[-2:])
    ]
    sim = _stack(torcwa, um, order, period, (eps_b, eps_s), (theta, phi), design, layers)
    # The incident flux of each source: through an empty stack of the background.
    empty = _stack(torcwa, um, 0, period, (eps_b, eps_b), (theta, phi))
    quads = []
    reflected = 0.0
    for amplitude in ([1.0, 0.0], [0.0, 1.0]):
        empty.source_planewave(amplitude=amplitude, direction="forward")
        incident = _flux(empty.field_xy(-1, coords[:1], coords[:1])).mean()
        sim.source_planewave(amplitude=amplitude, direction="forward")
        monitor = sim.field_xy(sim.layer_N, coords, coords, z_prop=design.depth)  # the substrate
        sz = _flux(monitor) / incident
        quads.append(sz.reshape(2, samples, 2, samples).mean(dim=(1, 3)) / 4.0)
        top = _flux(sim.field_xy(-1, coords, coords, z_prop=0.0)) / incident
        reflected = reflected + 0.5 * (1.0 - top.mean())
    return torch.stack(quads), reflected


def _fine_density(design: RouterDesign, density: Any) -> Any:
    """A density tensor sampled finely enough for the layers' Fourier series: every cell a
    whole number of samples, at least 256 across (the solvers' convolution matrices come from
    an FFT); differentiable."""
    _check_density(design, density)
    up = max(1, math.ceil(256 / max(design.cells)))
    return density.repeat_interleave(up, -2).repeat_interleave(up, -1)


def _check_density(design: RouterDesign, density: Any) -> None:
    if tuple(density.shape) != design.grid.shape:
        raise FullwaveError(
            f"density of shape {tuple(density.shape)} for a design of shape {design.grid.shape}"
        )


def _fmmax() -> tuple[Any, Any, Any, Any]:
    """fmmax's ``basis, fields, fmm, scattering`` modules, JAX set to 64-bit floats.

    Raises:
        FullwaveError: fmmax not installed (the message names the install command).
    """
    try:
        import jax
        from fmmax import basis, fields, fmm, scattering
    except ImportError:
        raise FullwaveError(f"the fmmax solver is an optional extra: {INSTALL_FMMAX}") from None
    jax.config.update("jax_enable_x64", True)
    return basis, fields, fmm, scattering


def _fmmax_core(
    design: RouterDesign, terms: int, formulation: str, samples: int
) -> tuple[Callable[..., tuple[Any, Any]], int]:
    """fmmax's solve of the stack as a JAX function of the layers' cell densities,
    ``(density, lam, theta, phi) -> (quads (2, 2, 2) [p, y, x], reflection)``, differentiable
    with respect to ``density`` (JAX arrays; :func:`fmmax_quadrants` is its PyTorch face): an
    ambient layer of the background, the patterned layers (the design's spacer of the
    background between them), the substrate down to the monitor plane. Each polarisation's
    fluxes are divided by its incident flux in the ambient; the reflection is the backward
    wave's flux there. One function (and its compiled program) per stack, grid shape and
    setting: the cells' values are its argument."""
    return _compiled_core(design.stack(), int(terms), formulation, samples)


class _FmmaxStack(NamedTuple):
    """A design's stack as fmmax solves it at one setting (the lattice of the 2x2-pixel period,
    the Fourier expansion, the formulation, the up-sampling of the cells onto the solve's
    grid): built once per design shape and setting, and solved inside compiled programs by
    :func:`_periodic_solve` (the periodic solves here and the Bloch solves of
    :mod:`splitcam.physics.bloch`)."""

    lattice: Any
    expansion: Any
    formulation: str
    up: Any
    thicknesses: tuple[float, ...]
    depth: float
    spacer: float

    @classmethod
    def of(cls, design: RouterDesign, terms: int, formulation: str) -> _FmmaxStack:
        basis, _, _, _ = _fmmax()
        import jax.numpy as jnp

        period = 2.0 * design.pitch
        lattice = basis.LatticeVectors(u=basis.X * period, v=basis.Y * period)
        expansion = basis.generate_expansion(
            primitive_lattice_vectors=lattice,
            approximate_num_terms=terms,
            truncation=basis.Truncation.CIRCULAR,
        )
        up = jnp.ones((max(1, math.ceil(256 / max(design.cells))),) * 2)  # as _fine_density samples
        return cls(
            lattice, expansion, formulation, up, design.thicknesses, design.depth, design.spacer
        )


def _periodic_solve(
    stack: _FmmaxStack, density: Any, um: Any, eps: Any, wavevector: Any, incident: Callable
) -> dict[str, Any]:
    """The layers of ``density`` (a grid, or a stack of layers' grids) between ambient and
    substrate, the spacers between them of the ambient's medium, solved at one wavelength
    (``um``) and in-plane wavevector (JAX, traceable); ``incident(ambient)``: the forward
    amplitudes of the light arriving from the ambient. Returns the outer media's modes (``ambient``,
    ``substrate``), the amplitudes ``forward`` and ``zero``, the backward amplitude in the
    ambient (``reflected``) and the forward amplitude at the monitor (``arriving``).

    Nothing comes back from below the monitor, so the stack's one scattering matrix gives both
    outer amplitudes (``b_0 = s21 a_0`` in the ambient, ``a_2 = s11 a_0`` entering the
    substrate; fmmax's convention, forward amplitudes at a layer's start, backward at its end):
    the interior matrices of every layer, which cost about twice as much, are not needed, and
    the backward amplitude in the substrate is ``zero``."""
    _, fields, fmm, scattering = _fmmax()
    import jax.numpy as jnp

    eps_p, eps_b, eps_s = eps[0], eps[1], eps[2]

    def modes(permittivity):
        return fmm.eigensolve_isotropic_media(
            wavelength=um,
            in_plane_wavevector=wavevector,
            primitive_lattice_vectors=stack.lattice,
            permittivity=jnp.asarray(permittivity, dtype=complex),
            expansion=stack.expansion,
            formulation=getattr(fmm.Formulation, stack.formulation),
        )

    ambient = modes(jnp.full((1, 1), eps_b))
    substrate = modes(jnp.full((1, 1), eps_s))
    forward = incident(ambient)
    media, thicknesses = [ambient], [jnp.zeros(())]
    layers = density if density.ndim == 3 else density[None]
    for i, (layer, thickness) in enumerate(zip(layers, stack.thicknesses, strict=True)):
        if i and stack.spacer > 0:  # the ambient's medium between two layers
            media.append(ambient)
            thicknesses.append(jnp.asarray(stack.spacer))
        fine = jnp.kron(layer, stack.up).T  # fmmax: [x, y]
        media.append(modes(eps_b + (eps_p - eps_b) * fine))
        thicknesses.append(jnp.asarray(thickness))
    s = scattering.stack_s_matrix([*media, substrate], [*thicknesses, jnp.asarray(stack.depth)])
    entering = s.s11 @ forward  # at the substrate's top
    arriving = fields.propagate_amplitude(entering, jnp.asarray(stack.depth), substrate)
    return {
        "ambient": ambient,
        "substrate": substrate,
        "forward": forward,
        "zero": jnp.zeros_like(forward),
        "reflected": s.s21 @ forward,
        "arriving": arriving,
    }


@functools.lru_cache(maxsize=16)
def _compiled_core(
    stack: tuple[Any, ...],
    terms: int,
    formulation: str,
    samples: int,
) -> tuple[Callable[..., tuple[Any, Any]], int]:
    """:func:`_fmmax_core` of the stack (:meth:`RouterDesign.stack`), kept so that every solve
    of one setting reuses the compilation."""
    design = RouterDesign.blank(stack)
    _, fields, _, _ = _fmmax()
    import jax
    import jax.numpy as jnp

    period = 2.0 * design.pitch
    setting = _FmmaxStack.of(design, terms, formulation)
    n = setting.expansion.num_terms
    grid = (2 * samples, 2 * samples)

    def plane_wave(ambient: Any) -> Any:  # each polarisation's zeroth order, amplitude 1
        return jnp.zeros((2 * n, 2), complex).at[0, 0].set(1.0).at[n, 1].set(1.0)

    @jax.jit
    def solved(density: Any, um: Any, eps: Any, wavevector: Any) -> tuple[Any, Any]:
        # compiled once per design shape and setting: the wavelength, permittivities and
        # direction are traced, so every solve after the first reuses the compiled program
        sol = _periodic_solve(setting, density, um, eps, wavevector, plane_wave)
        forward, zero, ambient = sol["forward"], sol["zero"], sol["ambient"]

        def flux(f, b, result):  # [x, y, polarisation]
            e, h = fields.fields_from_wave_amplitudes(f, b, result)
            (ex, ey, _), (hx, hy, _), _ = fields.fields_on_grid(e, h, result, grid, (1, 1))
            return 0.5 * jnp.real(ex * jnp.conj(hy) - ey * jnp.conj(hx))

        incident = jnp.mean(flux(forward, zero, ambient), axis=(0, 1))
        arriving = flux(sol["arriving"], zero, sol["substrate"])
        sz = (arriving / incident).transpose(2, 1, 0)
        quads = sz.reshape(2, 2, samples, 2, samples).mean(axis=(2, 4)) / 4.0  # [p, y, x]
        top = jnp.mean(flux(zero, sol["reflected"], ambient), axis=(0, 1)) / incident
        return quads, -top.mean()

    def solve(density: Any, lam: float, theta: float, phi: float) -> tuple[Any, Any]:
        um = _off_grazing(lam, period, design) / 1000.0
        eps = _permittivities(design, lam)
        k = 2 * math.pi * math.sqrt(eps[1]) * math.sin(theta) / um
        wavevector = jnp.asarray([k * math.cos(phi), k * math.sin(phi)])
        return solved(jnp.asarray(density), jnp.asarray(um), jnp.asarray(eps), wavevector)

    return solve, int(n)


def fmmax_quadrants(
    design: RouterDesign,
    density: Any,
    lam: float,
    theta: float = 0.0,
    phi: float = 0.0,
    terms: int = 361,
    samples: int = 16,
    formulation: str = "JONES_DIRECT",
) -> tuple[Any, Any]:
    """:func:`torcwa_quadrants` solved by fmmax: the same stack and outputs (PyTorch float64
    tensors), differentiable with respect to ``density`` through JAX's reverse mode
    (``jax.vjp`` in the forward pass, its pullback in the backward). Its Jones-direct
    formulation converges with the Fourier terms where torcwa's plain one is slow on the sharp
    edges of pillars (docs/results/fullwave/), so a design loss can be solved nearer the
    setting a design is verified at."""
    import jax
    import jax.numpy as jnp
    import torch

    _check_density(design, density)
    core, _ = _fmmax_core(design, terms, formulation, samples)

    def run(x):
        return core(x, lam, theta, phi)

    def torch_of(a):
        return torch.from_numpy(np.array(a, dtype=np.float64))

    class _Pullback(torch.autograd.Function):
        @staticmethod
        def forward(ctx, d):  # noqa: ANN001 - torch's signature
            (quads, reflected), ctx.pullback = jax.vjp(run, jnp.asarray(d.detach().numpy()))
            return torch_of(quads), torch_of(reflected)

        @staticmethod
        def backward(ctx, d_quads, d_reflected):  # noqa: ANN001
            cotangent = (jnp.asarray(d_quads.numpy()), jnp.asarray(d_reflected.numpy()))
            (grad,) = ctx.pullback(cotangent)
            return torch_of(grad)

    if not (density.requires_grad and torch.is_grad_enabled()):
        quads, reflected = run(jnp.asarray(density.detach().numpy()))
        return torch_of(quads), torch_of(reflected)
    return _Pullback.apply(density)


def _ends_in_newline(path: Path) -> bool:
    with path.open("rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1) == b"\n"


def _off_grazing(lam: float, period: float, design: RouterDesign) -> float:
    """``lam`` (nm), moved by a millionth where a diffraction order grazes the background or the
    substrate exactly (a Rayleigh anomaly: ``(n P / lam)^2 = m^2 + k^2`` for integers, as at
    400 and 500 nm for a 2 µm period in vacuum). There the order's normal wavevector is 0 and the
    solve divides by it; a millionth of the wavelength changes nothing else."""
    for material in (design.background, design.substrate):
        ratio = (index_of(material, lam) * period * 1000.0 / lam) ** 2
        if abs(ratio - round(ratio)) < 1e-9 and _sum_of_two_squares(round(ratio)):
            return lam * (1.0 + 1e-6)
    return lam


def _sum_of_two_squares(n: int) -> bool:
    return any(math.isqrt(n - m * m) ** 2 == n - m * m for m in range(math.isqrt(n) + 1))


def _stack(torcwa, um, order, period, media, angles, design=None, layers=()):
    """A torcwa solve of light from ``media[0]`` into ``media[1]`` (permittivities) at
    ``angles`` (polar, azimuth), through the design's patterned ``layers`` (permittivities
    ``[x, y]``, from the top), the design's spacer of ``media[0]`` between them."""
    import torch

    sim = torcwa.rcwa(
        freq=1.0 / um,
        order=[order, order],
        L=[period, period],
        dtype=torch.complex128,
        device=torch.device("cpu"),
    )
    sim.add_input_layer(eps=complex(media[0]))
    sim.add_output_layer(eps=complex(media[1]))
    sim.set_incident_angle(*angles)
    for i, layer in enumerate(layers):
        if i and design.spacer > 0:
            sim.add_layer(thickness=design.spacer, eps=complex(media[0]))
        sim.add_layer(thickness=design.thicknesses[i], eps=layer)
    sim.solve_global_smatrix()
    return sim


def _flux(fields) -> Any:
    """``(y, x)`` time-averaged z Poynting flux ``0.5 Re(Ex Hy* - Ey Hx*)`` of torcwa's fields
    (``[x, y]`` tensors), a tensor."""
    (ex, ey, _), (hx, hy, _) = fields
    return (0.5 * (ex * hy.conj() - ey * hx.conj()).real).T


def band_efficiencies(
    transmission: Any, wavelengths: Any, quadrants: dict[str, int] | None = None
) -> dict[str, Any]:
    """Band efficiencies of a 2x2 router, as the leaderboard scores them: the mean transmission
    of 400-500, 500-600 and 600-700 nm into its own pixels (blue where the shortest wavelength
    peaks, red where the longest peaks, green the other two), from ``(2, 2, L)`` transmissions;
    ``quadrants`` names the blue and red ones (row-major index).

    ``quadrants`` given (``{"blue": i, "red": j}``, the pixels the design sorts to, as its
    normal-incidence solve found them): the efficiencies into those pixels, whatever this
    light does; at oblique incidence a router can send blue and red to one pixel, and then
    its efficiencies are low, not undefined."""
    t = np.asarray(transmission).reshape(4, -1)
    lam = np.asarray(wavelengths)
    if quadrants is not None:
        blue, red = int(quadrants["blue"]), int(quadrants["red"])
        if blue == red or not {blue, red} <= set(range(4)):
            raise FullwaveError(f"quadrants must name two different pixels 0-3, got {quadrants}")
    else:
        blue, red = int(t[:, 0].argmax()), int(t[:, -1].argmax())
    if blue == red:
        raise FullwaveError(
            f"blue ({lam[0]:g} nm: {t[blue, 0]:.3f}) and red ({lam[-1]:g} nm: "
            f"{t[red, -1]:.3f}) both peak in quadrant (row, col) {divmod(blue, 2)}: the design "
            "does not send them to different pixels, so it has no band efficiencies"
        )
    out: dict[str, Any] = {}
    for name, quads, inside in _bands(blue, red, lam):
        out[name] = float(t[quads][:, inside].sum(axis=0).mean()) if inside.any() else float("nan")
    out["quadrants"] = {"blue": blue, "red": red}
    return out


def _bands(blue: int, red: int, lam: np.ndarray) -> list[tuple[str, list[int], np.ndarray]]:
    """Each band's name, its pixels (green: the two that are neither blue nor red) and which of
    the wavelengths ``lam`` lie in it (400-500, 500-600, 600-700 nm)."""
    green = [q for q in range(4) if q not in (blue, red)]
    return [
        (name, quads, (lam >= low) & (lam <= high))
        for name, quads, low, high in (
            ("blue", [blue], 400, 500),
            ("green", green, 500, 600),
            ("red", [red], 600, 700),
        )
    ]


def band_purities(transmission: Any, wavelengths: Any, quadrants: dict[str, int]) -> dict[str, Any]:
    """Colour purity per band of a 2x2 router: of all the light (400-700 nm, the wavelengths
    weighted alike) that reaches a band's own pixels (``quadrants`` as
    :func:`band_efficiencies` returns them; green: the other two), the share that belongs to
    that band. 1 is a pixel that receives its own band only; a third is no sorting at all; NaN
    for a band none of ``wavelengths`` falls in (as :func:`band_efficiencies`)."""
    t = np.asarray(transmission).reshape(4, -1)
    lam = np.asarray(wavelengths)
    out: dict[str, Any] = {}
    for name, quads, inside in _bands(int(quadrants["blue"]), int(quadrants["red"]), lam):
        received = t[quads].sum(axis=0)
        if not inside.any():
            out[name] = float("nan")
        elif received.sum() > 0:
            out[name] = float(received[inside].sum() / received.sum())
        else:
            out[name] = 0.0
    return out
