"""Scalar wave optics: from a metasurface above the sensor to the splitter kernels (model.md §12).

A metasurface over one period of ``Ph x Pw`` pixels (pitch ``p``), sampled at ``q`` points per
pixel and axis, sits a distance ``d`` above the photodiodes in a spacer of index ``n_s``. Its phase
at wavelength ``λ`` comes from a height map ``h(x, y) ∈ [0, h_max]`` of a dielectric of index
``n``: ``φ = 2π (n − n_s) h / λ``. Each pixel ``v`` of the period is its own splitter: the field
``exp(iφ)`` on ``v``'s aperture (0 elsewhere) is propagated over ``d`` by the angular spectrum
method in a zero-padded window of ``kh + 2·guard`` pixels, and the intensity over each pixel
(offset ``(a − kh//2, b − kw//2)`` from ``v``), divided by the power incident on the aperture, is
``T_v(λ; a, b)``. Light from different pixels adds in intensity (neighbouring image points are
mutually incoherent). Colour channel ``c`` weights the wavelengths by its spectrum ``S_c(λ)`` and
the photodiode's quantum efficiency ``Q(λ)``:
``w[v, c, a, b] = Σ_λ S_c Q T_v / Σ_λ S_c Q``.

Every step is a torch operation, so the kernels are differentiable in the height map, and the
result is a :class:`~splitcam.patterns.Pattern` that the rest of splitcam uses unchanged. Light
that leaves the kernel's window, or lives in evanescent components (they decay as
``exp(−2π d sqrt(f² − (n_s/λ)²))``), is lost, never created: every kernel sums to at most 1.

Known limits: scalar fields, a thin element (the phase is imparted at one plane), normal
incidence, no coupling between neighbouring meta-atoms; a full-wave solver is what a fabricated
design needs next. The window is periodic in the FFT: light leaving it re-enters at the opposite
edge, inside the guard band, which is outside the kernel (make ``guard`` larger for long
distances).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from ..checks import check_count
from ..patterns import Pattern
from .sensor import SplitterSensor

__all__ = [
    "MetasurfaceSensor",
    "Optics",
    "bayer_collection",
    "default_spectra",
    "flat_profile",
    "kernels_of",
    "lens_profile",
    "pattern_of",
    "profile",
    "rggb_collection",
]


def _gaussian(lam: np.ndarray, centre: float, width: float) -> np.ndarray:
    return np.exp(-0.5 * ((lam - centre) / width) ** 2)


def default_spectra(wavelengths: np.ndarray) -> np.ndarray:
    """``(3, L)`` channel spectra: Gaussian bands centred at 610 (R), 540 (G) and 460 nm (B),
    standard deviation 30 nm (roughly the spectral sensitivities of a CMOS sensor's colour
    channels). Replace them with measured curves through :class:`Optics`."""
    lam = np.asarray(wavelengths, dtype=np.float64)
    return np.stack([_gaussian(lam, c, 30.0) for c in (610.0, 540.0, 460.0)])


@dataclass
class Optics:
    """The geometry and materials of a metasurface colour router.

    Attributes (lengths in µm, wavelengths in nm):
        pitch: Pixel pitch ``p`` (default 1.0, as in published pixel-level routers).
        distance: Metasurface to photodiode distance ``d`` (default 2.0; 1-3 µm is typical).
        samples: Grid points per pixel and axis ``q`` (default 8).
        index: Refractive index ``n`` of the dielectric pillars (default 2.0, silicon nitride).
        spacer_index: Index ``n_s`` of the spacer (default 1.0; 1.46 for silica).
        max_height: ``h_max`` (default 1.2).
        wavelengths: Sampled wavelengths (default 400-700 nm every 20 nm).
        spectra: ``(3, L)`` channel spectra (default :func:`default_spectra`).
        quantum_efficiency: ``(L,)`` photodiode QE (default 1).
        kernel_size: ``(kh, kw)`` of the kernels (odd; default 3x3).
        guard: Pixels of padding around the kernel's window (default 2).

    Raises:
        ValueError: Negative distance, non-positive pitch or height, an index below 1, a grid too
            coarse to resolve the shortest wavelength in the spacer (``p/q > λ_min / (2 n_s)``),
            even kernel sizes, or spectra of the wrong shape.
    """

    pitch: float = 1.0
    distance: float = 2.0
    samples: int = 8
    index: float = 2.0
    spacer_index: float = 1.0
    max_height: float = 1.2
    wavelengths: np.ndarray = field(default_factory=lambda: np.arange(400.0, 701.0, 20.0))
    spectra: np.ndarray | None = None
    quantum_efficiency: np.ndarray | None = None
    kernel_size: tuple[int, int] = (3, 3)
    guard: int = 2

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pitch) and self.pitch > 0):
            raise ValueError(f"pitch must be > 0 µm, got {self.pitch}")
        if not (math.isfinite(self.distance) and self.distance >= 0):
            raise ValueError(f"distance must be >= 0 µm, got {self.distance}")
        if self.index < 1 or self.spacer_index < 1:
            raise ValueError(
                f"refractive indices must be >= 1, got index {self.index}, spacer "
                f"{self.spacer_index}"
            )
        if self.index <= self.spacer_index:
            raise ValueError(
                f"the pillars' index ({self.index:g}) must be above the spacer's "
                f"({self.spacer_index:g}): otherwise a height changes no phase"
            )
        if not (self.max_height > 0):
            raise ValueError(f"max_height must be > 0 µm, got {self.max_height}")
        check_count(self.samples, "samples per pixel", 1)
        self.wavelengths = np.asarray(self.wavelengths, dtype=np.float64).reshape(-1)
        if self.wavelengths.size == 0 or self.wavelengths.min() <= 0:
            raise ValueError("wavelengths must be positive (nm)")
        step = self.pitch / self.samples
        limit = self.wavelengths.min() * 1e-3 / (2 * self.spacer_index)
        if step > limit + 1e-12:
            need = math.ceil(self.pitch / limit)
            raise ValueError(
                f"grid too coarse: {step:.3f} µm between samples cannot resolve "
                f"{self.wavelengths.min():g} nm in the spacer (at most {limit:.3f} µm); use "
                f"samples >= {need}"
            )
        kh, kw = self.kernel_size
        if kh % 2 == 0 or kw % 2 == 0 or kh < 1 or kw < 1:
            raise ValueError(f"kernel_size must be odd, got {self.kernel_size}")
        if self.guard < 0:
            raise ValueError(f"guard must be >= 0 pixels, got {self.guard}")
        spectra = default_spectra(self.wavelengths) if self.spectra is None else self.spectra
        self.spectra = np.asarray(spectra, dtype=np.float64)
        if self.spectra.shape != (3, self.wavelengths.size) or self.spectra.min() < 0:
            raise ValueError(
                f"spectra must be (3, {self.wavelengths.size}) non-negative, got "
                f"{self.spectra.shape}"
            )
        qe = (
            np.ones_like(self.wavelengths)
            if self.quantum_efficiency is None
            else self.quantum_efficiency
        )
        self.quantum_efficiency = np.asarray(qe, dtype=np.float64).reshape(-1)
        if self.quantum_efficiency.shape != self.wavelengths.shape:
            raise ValueError("quantum_efficiency must have one value per wavelength")

    def phase(self, height: torch.Tensor) -> torch.Tensor:
        """``(L, H, W)`` phase of a height map ``(H, W)`` (µm) at every wavelength."""
        lam = torch.as_tensor(self.wavelengths * 1e-3, dtype=height.dtype, device=height.device)
        return 2 * math.pi * (self.index - self.spacer_index) * height[None] / lam[:, None, None]


def flat_profile(period: tuple[int, int], optics: Optics) -> torch.Tensor:
    """A height map of zeros: no metasurface (light simply diffracts)."""
    return torch.zeros(period[0] * optics.samples, period[1] * optics.samples, dtype=torch.float64)


def lens_profile(
    period: tuple[int, int],
    optics: Optics,
    wavelength: float = 540.0,
    focal: float | None = None,
) -> torch.Tensor:
    """A microlens over every pixel: the height whose phase at ``wavelength`` (nm) focuses a
    normally incident wave at ``focal`` µm (default: the distance), wrapped into ``[0, h_max]``
    modulo one wave of phase."""
    q, p = optics.samples, optics.pitch
    f = optics.distance if focal is None else focal
    lam = wavelength * 1e-3 / optics.spacer_index
    x = (np.arange(q) + 0.5) / q * p - p / 2
    r2 = x[:, None] ** 2 + x[None, :] ** 2
    phase = -2 * math.pi / lam * (np.sqrt(r2 + f**2) - f)
    one_wave = wavelength * 1e-3 / (optics.index - optics.spacer_index)  # height of 2π
    height = np.mod(phase / (2 * math.pi), 1.0) * one_wave
    height = np.minimum(height, optics.max_height)
    return torch.from_numpy(np.tile(height, period))


def _transfer(optics: Optics, size: int, dtype: torch.dtype) -> torch.Tensor:
    """``(L, M, M)`` angular-spectrum transfer functions over the distance (evanescent decay)."""
    dx = optics.pitch / optics.samples
    f = torch.fft.fftfreq(size, d=dx, dtype=torch.float64)
    f2 = f[:, None] ** 2 + f[None, :] ** 2
    k = torch.as_tensor(optics.spacer_index / (optics.wavelengths * 1e-3))[:, None, None]
    arg = k**2 - f2[None]
    kz = torch.sqrt(arg.clamp_min(0))
    decay = torch.sqrt((-arg).clamp_min(0))
    h = torch.exp(2j * math.pi * optics.distance * kz) * torch.exp(
        -2 * math.pi * optics.distance * decay
    )
    return h.to(torch.complex128 if dtype == torch.float64 else torch.complex64)


def kernels_of(height: torch.Tensor, period: tuple[int, int], optics: Optics) -> torch.Tensor:
    """The kernels ``(Ph * Pw, 3, kh, kw)`` that a height map makes, differentiable in it.

    Args:
        height: ``(Ph * q, Pw * q)`` heights in µm over one period (clamped to ``[0, h_max]``).
        period: ``(Ph, Pw)``.
        optics: Geometry and materials.
    """
    ph, pw = period
    q = optics.samples
    if tuple(height.shape) != (ph * q, pw * q):
        raise ValueError(
            f"expected a height map of shape {(ph * q, pw * q)}, got {tuple(height.shape)}"
        )
    kh, kw = optics.kernel_size
    win = max(kh, kw) + 2 * optics.guard  # pixels per side of the square window
    size = win * q
    height = height.clamp(0, optics.max_height)
    transfer = _transfer(optics, size, height.dtype).to(height.device)
    weights = torch.as_tensor(
        optics.spectra * optics.quantum_efficiency, dtype=height.dtype, device=height.device
    )
    weights = weights / weights.sum(1, keepdim=True)  # (3, L)
    centre = (win // 2) * q
    out = []
    for i in range(ph):
        for j in range(pw):
            phase = optics.phase(height[i * q : (i + 1) * q, j * q : (j + 1) * q])  # (L, q, q)
            field = torch.zeros(
                (len(optics.wavelengths), size, size), dtype=transfer.dtype, device=height.device
            )
            field[:, centre : centre + q, centre : centre + q] = torch.exp(1j * phase)
            u = torch.fft.ifft2(torch.fft.fft2(field) * transfer)
            power = (u.real**2 + u.imag**2).reshape(-1, win, q, win, q).sum((2, 4)) / (q * q)
            c0, c1 = win // 2 - kh // 2, win // 2 - kw // 2
            t = power[:, c0 : c0 + kh, c1 : c1 + kw]  # (L, kh, kw)
            out.append(torch.einsum("cl,lab->cab", weights, t))
    return torch.stack(out)


def pattern_of(
    height: torch.Tensor, period: tuple[int, int], optics: Optics, name: str = "metasurface"
) -> Pattern:
    """The :class:`~splitcam.patterns.Pattern` a height map makes (each pixel of the period its
    own splitter)."""
    kernels = kernels_of(height.detach(), period, optics).cpu().numpy()
    kernels = np.clip(kernels, 0, None)
    sums = kernels.sum((2, 3), keepdims=True)
    kernels = np.where(sums > 1, kernels / sums, kernels)  # rounding only: never above 1
    layout = np.arange(period[0] * period[1]).reshape(period)
    return Pattern(
        name=name,
        layout=layout,
        kernels=kernels,
        provenance="optics",
        description=f"scalar optics: pitch {optics.pitch:g} µm, distance {optics.distance:g} µm, "
        f"n {optics.index:g} in n_s {optics.spacer_index:g}",
        reference="splitcam.physics.optics (angular spectrum method)",
        metadata={
            "pitch": optics.pitch,
            "distance": optics.distance,
            "samples": optics.samples,
            "index": optics.index,
            "spacer_index": optics.spacer_index,
            "max_height": optics.max_height,
        },
    )


#: The colour of each pixel of a 2x2 Bayer-type router (RGGB): the target of that colour's light.
BAYER_TARGET = ((0, 1), (1, 2))


def rggb_collection(kernels: torch.Tensor, layout: Sequence[Sequence[int]]) -> torch.Tensor:
    """Per-colour collection efficiency ``(3,)`` of a 2x2 router's kernels, differentiable: the
    share of each colour's light falling on the period that reaches a pixel of that colour in an
    RGGB arrangement (R at (0, 0)).

    Args:
        kernels: ``(S, 3, kh, kw)`` splitter kernels (odd sizes, centre = own pixel).
        layout: ``2 x 2`` splitter index of each site.
    """
    kh, kw = kernels.shape[-2:]
    terms: list[list[torch.Tensor]] = [[], [], []]
    for i in range(2):
        for j in range(2):
            k = kernels[int(layout[i][j])]
            for a in range(kh):
                for b in range(kw):
                    target = BAYER_TARGET[(i + a - kh // 2) % 2][(j + b - kw // 2) % 2]
                    terms[target].append(k[target, a, b])
    return torch.stack([torch.stack(t).sum() / 4.0 for t in terms])


def bayer_collection(pattern: Pattern) -> list[float]:
    """Per-colour collection efficiency of a 2x2 router pattern (:func:`rggb_collection`): what
    measured routers report, e.g. Zou et al., Nat. Commun. 2022: 58/59/49 % peak for R/G/B."""
    if pattern.period != (2, 2):
        raise ValueError(f"a Bayer-type router has a 2x2 period, got {pattern.period}")
    kernels = torch.tensor(np.array(pattern.kernels))
    return [float(v) for v in rggb_collection(kernels, pattern.layout)]


class MetasurfaceSensor(SplitterSensor):
    """A sensor whose splitter kernels come from a learnable metasurface height map.

    The height is ``h_max * sigmoid(z)`` (``z`` the learned parameter, so the height stays in
    ``[0, h_max]``); every call to :meth:`weights` propagates it through :func:`kernels_of`, so
    gradients from the reconstruction loss reach the metasurface. Drop-in for
    :class:`~splitcam.physics.sensor.SplitterSensor` in an imaging system (``splitcam train
    --metasurface random``).

    Args:
        height: Starting height map ``(Ph * q, Pw * q)`` in µm.
        period: ``(Ph, Pw)``.
        optics: Geometry and materials (default :class:`Optics`).
    """

    def __init__(
        self, height: torch.Tensor, period: tuple[int, int], optics: Optics | None = None
    ) -> None:
        self.optics = optics or Optics()
        self._start_height = height.detach().to(torch.float64)
        self._period_of = tuple(period)
        super().__init__(
            pattern_of(self._start_height, self._period_of, self.optics, name="metasurface")
        )

    def _init_kernels(self, pattern: Pattern) -> None:
        frac = (self._start_height / self.optics.max_height).clamp(1e-3, 1 - 1e-3)
        self.height_logits = torch.nn.Parameter(torch.log(frac / (1 - frac)).float())

    def height(self) -> torch.Tensor:
        """The current height map (µm)."""
        return self.optics.max_height * torch.sigmoid(self.height_logits)

    def weights(self) -> torch.Tensor:
        return kernels_of(self.height(), self._period_of, self.optics)

    def to_pattern(self, name: str | None = None) -> Pattern:
        """The pattern of the height map this sensor holds (:func:`pattern_of`) on the sensor's
        ``layout`` buffer."""
        height = self.height().detach().double().cpu()
        made = pattern_of(height, self._period_of, self.optics, name=name or "metasurface")
        return dataclasses.replace(made, layout=self.layout.detach().cpu().numpy())

    def extra_repr(self) -> str:
        return (
            f"period={self._period_of}, pitch={self.optics.pitch}, distance={self.optics.distance}"
        )


PROFILES = ("flat", "lens", "random")


def profile(spec: str, period: tuple[int, int], optics: Optics, seed: int = 0) -> torch.Tensor:
    """A starting height map by name (``flat``, ``lens``, ``random``: uniform in
    ``[0, h_max]`` from ``seed``) or from a ``.npy`` file (µm, no pickles): the one place the
    CLI, ``train --metasurface`` and :func:`~splitcam.design.design_metasurface` read it.

    Raises:
        ValueError: An unreadable file or a map of the wrong shape for the period.
    """
    shape = (period[0] * optics.samples, period[1] * optics.samples)
    if spec == "flat":
        height = flat_profile(period, optics)
    elif spec == "lens":
        height = lens_profile(period, optics)
    elif spec == "random":
        gen = torch.Generator().manual_seed(seed)
        height = torch.rand(shape, generator=gen, dtype=torch.float64) * optics.max_height
    else:
        try:
            height = torch.from_numpy(np.load(spec, allow_pickle=False)).to(torch.float64)
        except (OSError, ValueError) as exc:
            raise ValueError(f"cannot read the height map {spec!r}: {exc}") from None
    if tuple(height.shape) != shape:
        raise ValueError(f"expected a height map of shape {shape}, got {tuple(height.shape)}")
    if not bool(torch.isfinite(height).all()):
        raise ValueError(f"the height map {spec!r} holds NaN or infinite heights")
    low, high = float(height.min()), float(height.max())
    if low < 0 or high > optics.max_height + 1e-9:
        raise ValueError(
            f"the height map {spec!r} spans {low:g}..{high:g} µm; heights must lie in "
            f"[0, {optics.max_height:g}] µm (the pillars' maximum height, --max-height)"
        )
    return height
