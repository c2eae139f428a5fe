"""Sensor noise. The paper's model (model.md §3): additive Gaussian noise in 8-bit units on the
raw image's scale. The physical model at equal exposure (model.md §11): :class:`Exposure`
(photo-electrons, shot and read noise, full well, ADC) and :class:`PhotonNoise` for training.

One interface, :class:`NoiseModel`, is all the rest of splitcam asks of noise at one level: the
sensor's simulation draws it (:meth:`NoiseModel.apply`, :meth:`NoiseModel.add`), the LMMSE
takes its covariance from :meth:`NoiseModel.variance_coefficients`, the networks their
noise-level input from :meth:`NoiseModel.level_map`, tables their label from
:meth:`NoiseModel.label`. :class:`Gaussian` (the paper's) and :class:`Exposure` (the photon
model) implement it; a plain number is shorthand for :class:`Gaussian` (:func:`as_noise`). A new
noise model (dark current, a measured read-noise curve) is a new subclass here and nothing else.

Training noise comes from :class:`GaussianNoise` and :class:`PhotonNoise`, which own seeded
generators (so a resumed run draws the same noise as an uninterrupted one): the noise levels on
the CPU, the noise itself on the device of the raw images (:class:`_TrainingDraws`). Both hand
on the level of each image as the :class:`NoiseModel` evaluation uses (:class:`Gaussian`,
:class:`Exposure`), so training and evaluation tell the LMMSE and the networks the same things.
Evaluation noise comes from :func:`evaluation_noise`, seeded from the image's name and sigma, so
that every pattern and every method is scored on identical noise. Nothing here touches Python's
``random`` or global RNGs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from numbers import Real
from typing import Any

import torch

from ..checks import check_count

__all__ = [
    "NoiseModel",
    "Gaussian",
    "as_noise",
    "level_heading",
    "level_key",
    "level_label",
    "parse_level_label",
    "Exposure",
    "GaussianNoise",
    "PhotonNoise",
    "add_exposure_noise",
    "add_evaluation_noise",
    "photon_noise",
    "check_level",
    "check_sigma",
    "evaluation_noise",
    "evaluation_seed",
]


def check_sigma(sigma: Any) -> float:
    """A noise level in 8-bit units: a finite number ``>= 0``.

    Raises:
        TypeError: Not a number.
        ValueError: Negative, infinite or NaN.
    """
    if isinstance(sigma, bool) or not isinstance(sigma, Real):
        raise TypeError(f"expected sigma as a number (8-bit units), got {type(sigma).__name__}")
    if not (math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"expected a finite sigma >= 0 (8-bit units), got {sigma}")
    return float(sigma)


class _TrainingDraws:
    """The two generators of a training noise.

    ``generator`` (always on the CPU) draws the noise level of each step: a few numbers, kept on
    the host so that nothing downstream (the LMMSE solve, the noise-level input) waits on the
    device for them. ``field`` draws the noise itself on ``device``: on an accelerator a batch's
    noise is drawn where the batch is, with no host copy; on the CPU it is ``generator`` itself,
    so CPU runs draw the same stream as before the device generator existed. A CPU and a CUDA
    generator give different streams from one seed: a run is reproducible on one kind of device.
    """

    def _seed(self, seed: int, device: torch.device | str | None) -> None:
        self.generator = torch.Generator().manual_seed(seed)
        device = torch.device(device if device is not None else "cpu")
        self.field = (
            self.generator if device.type == "cpu" else torch.Generator(device).manual_seed(seed)
        )

    @property
    def device(self) -> torch.device:
        """Where the noise is drawn."""
        return self.field.device

    def state_dict(self) -> dict[str, torch.Tensor]:
        state = {"generator": self.generator.get_state()}
        if self.field is not self.generator:
            state["field"] = self.field.get_state()
        return state

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> bool:
        """Continue from a :meth:`state_dict`; the device generator only from one saved on the
        same kind of device (otherwise it keeps its seed: the stream cannot continue across
        kinds). Returns whether the whole stream continues."""
        self.generator.set_state(state["generator"])
        if self.field is self.generator:
            return True
        field = state.get("field")
        if field is None or field.numel() != self.field.get_state().numel():
            return False
        self.field.set_state(field)
        return True


class GaussianNoise(_TrainingDraws):
    """``raw + n`` with ``n ~ N(0, (sigma / 255)^2)``; sigma fixed or drawn from ``U[lo, hi]``.

    Args:
        sigma: A fixed sigma, or a ``(lo, hi)`` range to draw from (the paper: ``(0, 30)``).
        per_sample: Draw one sigma per sample instead of one per batch (the paper's choice).
        seed: Seed of the generators that draw sigmas and noise.
        device: Where the noise is drawn (see :class:`_TrainingDraws`; default the CPU).

    Returns (when called on ``(N, 1, H, W)`` raw images): the noisy images and the
    :class:`Gaussian` of each image, the same objects evaluation uses (what the LMMSE solves
    for and the physics-informed networks are told).
    """

    def __init__(
        self,
        sigma: float | tuple[float, float] = (0.0, 30.0),
        *,
        per_sample: bool = False,
        seed: int = 0,
        device: torch.device | str | None = None,
    ) -> None:
        lo, hi = (sigma, sigma) if isinstance(sigma, (int, float)) else tuple(sigma)
        if not 0 <= lo <= hi < float("inf"):
            raise ValueError(f"expected 0 <= sigma_lo <= sigma_hi, got {sigma!r}")
        self.range = (float(lo), float(hi))
        self.per_sample = per_sample
        self._seed(seed, device)

    def __call__(self, raw: torch.Tensor) -> tuple[torch.Tensor, list[Gaussian]]:
        lo, hi = self.range
        n = raw.shape[0] if self.per_sample else 1
        sigma = lo + (hi - lo) * torch.rand(n, generator=self.generator, dtype=torch.float64)
        sigma = sigma.expand(raw.shape[0]) if n == 1 else sigma
        noise = torch.randn(
            raw.shape, generator=self.field, dtype=torch.float32, device=self.field.device
        )
        noise = noise.to(device=raw.device, dtype=raw.dtype)
        scale = (sigma / 255.0).to(device=raw.device, dtype=raw.dtype).view(-1, 1, 1, 1)
        # The levels as the float32 numbers the noise was scaled by, so that what the networks
        # are told is exactly what was drawn.
        return raw + scale * noise, [Gaussian(float(s)) for s in sigma.float()]


class NoiseModel(ABC):
    """Sensor noise at one level: what the simulation adds, the LMMSE assumes and the networks
    are told.

    Subclasses are frozen dataclasses (hashable: methods cache their filters per level) and
    implement :meth:`apply`, :meth:`variance_coefficients` and :meth:`label`. The raw values are
    in the units of model.md §1.
    """

    @abstractmethod
    def apply(self, raw: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """The noisy raw image of a clean one, drawn from ``generator`` (a CPU generator)."""

    @abstractmethod
    def variance_coefficients(self) -> tuple[float, float]:
        """``(a, b)``: the noise variance of a raw pixel of expected value ``g`` is ``a g + b``
        in raw units (what the LMMSE's noise covariance is built from)."""

    @abstractmethod
    def label(self) -> str:
        """The level's label in tables, metrics keys and file names (``"15"``, ``"N1000"``)."""

    def describe(self) -> str:
        """The level in words, for figure titles."""
        return f"noise {self.label()}"

    def file_label(self) -> str:
        """The level in the names of the files written for it."""
        return self.label()

    def seed(self, image_name: str) -> int:
        """The seed of this level's evaluation noise on one image: stable across runs, machines
        and methods, so every method is scored on the same draw."""
        digest = hashlib.sha256(f"splitcam-noise|{image_name}|{self.label()}".encode()).digest()
        return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)

    def add(self, raw: torch.Tensor, image_name: str) -> torch.Tensor:
        """The deterministic evaluation noise of one image (:meth:`apply` on :meth:`seed`)."""
        return self.apply(raw, torch.Generator().manual_seed(self.seed(image_name)))

    def level_map(self, cells: torch.Tensor) -> torch.Tensor:
        """The noise standard deviation (8-bit units) a network is told, ``(N, 1, h, w)``, from
        the raw image's period cells ``(N, P, h, w)``: ``255 sqrt(a g + b)`` with the raw value
        ``g`` (clamped at 0) as each pixel's signal, averaged over the cell."""
        a, b = self.variance_coefficients()
        return (255.0 * (a * cells.clamp_min(0) + b).sqrt()).mean(1, keepdim=True)

    def row_fields(self) -> dict[str, Any]:
        """The fields that identify this level in a results row
        (:class:`~splitcam.evaluation.tables.EvalRow`)."""
        return {"noise": self.label()}

    def sensor_settings(self) -> dict[str, Any] | None:
        """Settings every level of one evaluation must share (recorded in its
        ``evaluation.json``), or None."""
        return None


@dataclass(frozen=True)
class Gaussian(NoiseModel):
    """The paper's noise (model.md §3): ``raw + n``, ``n ~ N(0, (sigma / 255)^2)``, sigma in
    8-bit units. A plain number given as a noise level means this.

    >>> Gaussian(15).label(), Gaussian(15).variance_coefficients() == (0.0, (15 / 255) ** 2)
    ('15', True)
    """

    sigma: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigma", check_sigma(self.sigma))

    def apply(self, raw: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        if self.sigma == 0:
            return raw
        noise = torch.randn(tuple(raw.shape), generator=generator, dtype=torch.float64)
        return raw + (noise * (self.sigma / 255.0)).to(device=raw.device, dtype=raw.dtype)

    def variance_coefficients(self) -> tuple[float, float]:
        return 0.0, (self.sigma / 255.0) ** 2

    def label(self) -> str:
        return f"{self.sigma:g}"

    def describe(self) -> str:
        return f"sigma {self.sigma:g}"

    def file_label(self) -> str:
        return f"sigma{self.sigma:g}"

    def seed(self, image_name: str) -> int:
        return evaluation_seed(image_name, self.sigma)

    def level_map(self, cells: torch.Tensor) -> torch.Tensor:
        return torch.full(
            (cells.shape[0], 1, *cells.shape[-2:]),
            self.sigma,
            dtype=cells.dtype,
            device=cells.device,
        )

    def row_fields(self) -> dict[str, Any]:
        return {"sigma": self.sigma}


def as_noise(level: Any) -> NoiseModel:
    """A noise level as a :class:`NoiseModel`: one as it is, a number as :class:`Gaussian`.

    Raises:
        TypeError, ValueError: Neither a noise model nor a valid sigma (:func:`check_sigma`).
    """
    return level if isinstance(level, NoiseModel) else Gaussian(check_sigma(level))


def check_level(level: Any) -> float | NoiseModel:
    """A noise level: a :class:`NoiseModel` as it is, anything else through
    :func:`check_sigma` (a Gaussian sigma in 8-bit units)."""
    return level if isinstance(level, NoiseModel) else check_sigma(level)


def evaluation_seed(image_name: str, sigma: float) -> int:
    """A 63-bit seed from the image name and sigma (stable across runs, machines and methods)."""
    digest = hashlib.sha256(f"splitcam-eval|{image_name}|{float(sigma):g}".encode()).digest()
    return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)


def evaluation_noise(
    shape: tuple[int, ...],
    image_name: str,
    sigma: float,
    *,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str = "cpu",
) -> torch.Tensor:
    """The deterministic evaluation noise ``N(0, (sigma/255)^2)`` of one image at one sigma.

    The same for every pattern and method (it depends only on the name, sigma and shape), so
    differences in scores come from the methods, not from the draw.
    """
    sigma = check_sigma(sigma)
    gen = torch.Generator().manual_seed(evaluation_seed(image_name, sigma))
    noise = torch.randn(shape, generator=gen, dtype=torch.float64) * (float(sigma) / 255.0)
    return noise.to(device=device, dtype=dtype)


def add_evaluation_noise(raw: torch.Tensor, image_name: str, sigma: float) -> torch.Tensor:
    """``raw`` plus :func:`evaluation_noise` (returned unchanged for ``sigma == 0``):
    :meth:`Gaussian.add`."""
    return Gaussian(sigma).add(raw, image_name)


# --- photon-limited sensing (model.md §11) ---------------------------------------------------


@dataclass(frozen=True)
class Exposure(NoiseModel):
    """The physical sensor at one exposure: photo-electrons, shot and read noise, full well, ADC.

    Exposure is stated by ``photons`` (``N``): the mean photo-electrons that a lossless pixel
    without filter or splitter collects from a white scene (``f = 1`` in every colour). Its raw
    value in the units of model.md §1 is ``R + G + B = 3``, so a raw value ``g`` means
    ``e = g N / 3`` photo-electrons: every pattern sees the same photon flux, and a filter's lost
    light shows as lost signal. Noise, in order: shot noise ``Poisson(e)`` (``shot``), read noise
    ``N(0, read_noise^2)`` electrons (after ``Poisson(dark)`` dark electrons, whose mean a
    dark frame removes at the end: ``dark`` adds noise, not signal), saturation to
    ``[0, full_well]`` (``full_well`` not None),
    an ADC ``DN = round(e / gain)`` clipped to ``[0, 2^bits - 1]`` (``gain`` not None); the raw
    image handed on is ``DN * gain * 3 / N`` (or ``e * 3 / N`` without ADC), the same scale for
    every pattern. With ``shot=False``, no full well, no ADC and ``read_noise = N sigma / (3 *
    255)`` this is the Gaussian model of model.md §3.

    Raises:
        ValueError: Non-positive or non-finite ``photons``; negative ``read_noise``;
            non-positive ``full_well`` or ``gain``; ``bits < 1``.
    """

    photons: float
    read_noise: float = 2.0
    full_well: float | None = None
    gain: float | None = None
    bits: int = 12
    shot: bool = True
    dark: float = 0.0

    def __post_init__(self) -> None:
        def positive(name: str, value: Any) -> None:
            if (
                isinstance(value, bool)
                or not isinstance(value, Real)
                or not (math.isfinite(value) and value > 0)
            ):
                raise ValueError(f"expected {name} as a finite number > 0, got {value!r}")

        positive("photons (exposure)", self.photons)
        if (
            isinstance(self.read_noise, bool)
            or not isinstance(self.read_noise, Real)
            or not (math.isfinite(self.read_noise) and self.read_noise >= 0)
        ):
            raise ValueError(f"expected read_noise (electrons) >= 0, got {self.read_noise!r}")
        if self.full_well is not None:
            positive("full_well (electrons)", self.full_well)
        if self.gain is not None:
            positive("gain (electrons per DN)", self.gain)
        check_count(self.bits, "bits", 1)
        if (
            isinstance(self.dark, bool)
            or not isinstance(self.dark, Real)
            or not (math.isfinite(self.dark) and self.dark >= 0)
        ):
            raise ValueError(f"expected dark (electrons per exposure) >= 0, got {self.dark!r}")

    @property
    def electrons_per_unit(self) -> float:
        """Photo-electrons per unit of raw value: ``N / 3``."""
        return self.photons / 3.0

    def variance_coefficients(self) -> tuple[float, float]:
        """``(a, b)`` with the noise variance of a raw pixel of expected value ``g`` being
        ``a g + b`` in raw units (shot, dark, read and, with an ADC, uniform quantisation
        noise; saturation ignored): ``a = 3 / N`` (0 without shot noise),
        ``b = (3 read / N)^2 + (3 / N)^2 dark + (3 gain / N)^2 / 12``."""
        scale = 3.0 / self.photons
        a = scale if self.shot else 0.0
        b = (scale * self.read_noise) ** 2 + scale**2 * self.dark
        if self.gain is not None:
            b += (scale * self.gain) ** 2 / 12.0
        return a, b

    def apply(self, raw: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """The noisy raw image of a clean one (``raw``, values >= 0 in the units of model.md §1)."""
        e = raw.detach().to(torch.float64).clamp_min(0).cpu() * self.electrons_per_unit
        if self.shot:
            e = torch.poisson(e, generator=generator)
        if self.dark > 0:
            e = e + torch.poisson(torch.full_like(e, self.dark), generator=generator)
        if self.read_noise > 0:
            e = e + self.read_noise * torch.randn(e.shape, generator=generator, dtype=torch.float64)
        if self.full_well is not None:
            e = e.clamp(0, self.full_well)
        if self.gain is not None:
            dn = torch.round(e / self.gain).clamp(0, 2**self.bits - 1)
            e = dn * self.gain
        e = e - self.dark  # the dark frame's mean subtracted; its noise stays
        return (e / self.electrons_per_unit).to(device=raw.device, dtype=raw.dtype)

    def key(self) -> str:
        key = (
            f"N{self.photons:g}|r{self.read_noise:g}|fw{self.full_well}|g{self.gain}"
            f"|b{self.bits}|s{int(self.shot)}"
        )
        # Without dark current the key (and so every seed and stored result) is as before.
        return key + (f"|d{self.dark:g}" if self.dark else "")

    def label(self) -> str:
        return f"N{self.photons:g}"

    def describe(self) -> str:
        return f"{self.photons:g} photo-electrons"

    def seed(self, image_name: str) -> int:
        digest = hashlib.sha256(f"splitcam-photon|{image_name}|{self.key()}".encode()).digest()
        return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)

    def row_fields(self) -> dict[str, Any]:
        return {"photons": self.photons}

    def sensor_settings(self) -> dict[str, Any]:
        settings = {k: v for k, v in dataclasses.asdict(self).items() if k != "photons"}
        if not self.dark:
            del settings["dark"]  # as recorded before dark current was modelled
        return settings


def add_exposure_noise(raw: torch.Tensor, image_name: str, exposure: Exposure) -> torch.Tensor:
    """The deterministic photon-model noise of one image at one exposure (evaluation): the same
    draw for every method of one pattern, seeded from the image name and the exposure
    (:meth:`Exposure.add`)."""
    return exposure.add(raw, image_name)


class PhotonNoise(_TrainingDraws):
    """Training noise of the photon model: exposure ``N`` drawn log-uniformly from a range.

    The whole batch is made noisy at once on the generator's device (:func:`photon_noise`), one
    exposure per image: no loop over images and no host copy.

    Args:
        photons: ``(lo, hi)`` full-light photo-electrons (or one value).
        per_sample: One exposure per sample instead of one per batch.
        seed: Seed of the generators.
        device: Where the noise is drawn (see :class:`_TrainingDraws`; default the CPU).
        **sensor: ``read_noise``, ``full_well``, ``gain``, ``bits``, ``shot`` of
            :class:`Exposure`.

    Returns (when called on ``(N, 1, H, W)`` raw images): the noisy images and the
    :class:`Exposure` of each image (what the physics-informed network is told).
    """

    def __init__(
        self,
        photons: float | tuple[float, float] = (10.0, 1e4),
        *,
        per_sample: bool = False,
        seed: int = 0,
        device: torch.device | str | None = None,
        **sensor: Any,
    ) -> None:
        lo, hi = (photons, photons) if isinstance(photons, (int, float)) else tuple(photons)
        Exposure(lo, **sensor)  # validates the sensor settings and the range ends
        Exposure(hi, **sensor)
        if lo > hi:
            raise ValueError(f"expected photons lo <= hi, got {photons!r}")
        self.range = (float(lo), float(hi))
        self.sensor = sensor
        self.per_sample = per_sample
        self._seed(seed, device)

    def __call__(self, raw: torch.Tensor) -> tuple[torch.Tensor, list[Exposure]]:
        lo, hi = (math.log(v) for v in self.range)
        n = raw.shape[0] if self.per_sample else 1
        photons = torch.exp(
            lo + (hi - lo) * torch.rand(n, generator=self.generator, dtype=torch.float64)
        )
        photons = photons.expand(raw.shape[0]) if n == 1 else photons
        exposures = [Exposure(float(p), **self.sensor) for p in photons]
        return photon_noise(raw, exposures, self.field), exposures


def photon_noise(
    raw: torch.Tensor, exposures: list[Exposure], generator: torch.Generator
) -> torch.Tensor:
    """A batch made noisy by the photon model, one :class:`Exposure` per image, in one pass.

    The same model as :meth:`Exposure.apply` (shot, read noise, full well, ADC, in that order),
    applied to every image at once on ``generator``'s device in float64. The exposures must
    share their sensor settings (read noise, full well, gain, bits, shot): only the photons may
    differ, as in :class:`PhotonNoise`.

    Shape:
        raw: ``(N, 1, H, W)``, values >= 0 in the units of model.md §1; ``len(exposures) == N``;
        output: like ``raw``, on its device and in its dtype.
    """
    first = exposures[0]
    if len(exposures) != raw.shape[0] or any(
        dataclasses.replace(e, photons=first.photons) != first for e in exposures
    ):
        raise ValueError("expected one exposure per image, all with the same sensor settings")
    device = generator.device
    per_unit = torch.tensor(
        [e.electrons_per_unit for e in exposures], dtype=torch.float64, device=device
    ).view(-1, 1, 1, 1)
    e = raw.detach().to(device=device, dtype=torch.float64).clamp_min(0) * per_unit
    if first.shot:
        e = torch.poisson(e, generator=generator)
    if first.dark > 0:
        e = e + torch.poisson(torch.full_like(e, first.dark), generator=generator)
    if first.read_noise > 0:
        noise = torch.randn(e.shape, generator=generator, dtype=torch.float64, device=device)
        e = e + first.read_noise * noise
    if first.full_well is not None:
        e = e.clamp(0, first.full_well)
    if first.gain is not None:
        e = torch.round(e / first.gain).clamp(0, 2**first.bits - 1) * first.gain
    e = e - first.dark
    return (e / per_unit).to(device=raw.device, dtype=raw.dtype)


# The label of a noise level, the one convention of tables, metrics files and figures: "15" for
# a Gaussian sigma of 15 (8-bit units), "N1000" for a photon-model exposure of 1000
# photo-electrons. Everything that writes or reads such a label goes through these functions.


def level_label(level: float | NoiseModel) -> str:
    """``"15"`` for a Gaussian sigma, ``"N1000"`` for an :class:`Exposure` of 1000
    photo-electrons (in ``metrics.jsonl`` keys ``val_psnr_<label>`` and result tables).

    >>> level_label(15.0), level_label(0), level_label(Exposure(1000.0))
    ('15', '0', 'N1000')
    >>> parse_level_label("val_psnr_N1000")  # and back
    ('photons', 1000.0)
    """
    return as_noise(level).label()


def parse_level_label(label: str) -> tuple[str, float]:
    """``("sigma", 15.0)`` for ``"15"``, ``("photons", 1000.0)`` for ``"N1000"``; also accepts
    a metrics key such as ``"val_psnr_N1000"`` (the part after the last underscore). The label
    of another :class:`NoiseModel` reads as ``("other", nan)``.

    Raises:
        ValueError: Not a level label (empty).
    """
    text = str(label).rsplit("_", 1)[-1]
    if not text:
        raise ValueError(f"not a noise-level label (15 or N1000): {label!r}")
    kind, number = ("photons", text[1:]) if text.startswith("N") else ("sigma", text)
    try:
        return kind, float(number)
    except ValueError:
        return "other", math.nan


def level_key(label: str) -> tuple[int, float, str]:
    """Sort key: Gaussian levels first by sigma, then exposures by photo-electrons, then the
    labels of other noise models."""
    kind, value = parse_level_label(label)
    rank = {"sigma": 0, "photons": 1}.get(kind, 2)
    return (rank, 0.0 if rank == 2 else value, str(label))


def level_heading(label: str) -> str:
    """A table heading or legend entry: ``σ=15``, ``N=1000 e⁻``, or another model's label."""
    kind, value = parse_level_label(label)
    if kind == "other":
        return str(label).rsplit("_", 1)[-1]
    return f"N={value:g} e⁻" if kind == "photons" else f"σ={value:g}"
