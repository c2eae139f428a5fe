"""Sensor noise. The paper's model (model.md §3): additive Gaussian noise in 8-bit units on the
raw image's scale. The physical model at equal exposure (model.md §11): :class:`Exposure`
(photo-electrons, shot and read noise, dark current, full well, ADC).

One interface, :class:`NoiseModel`, is all the rest of splitcam asks of noise at one level: the
sensor's simulation draws it (:meth:`NoiseModel.apply`, :meth:`NoiseModel.add`), training draws
a batch of levels at once (:meth:`NoiseModel.apply_batch`), the LMMSE takes its covariance from
:meth:`NoiseModel.variance_coefficients`, the networks their noise-level input from
:meth:`NoiseModel.level_map`, tables their label from :meth:`NoiseModel.label`, files record it
with :meth:`NoiseModel.to_dict` (:func:`noise_from_dict` reads it back). :class:`Gaussian` (the
paper's) and :class:`Exposure` (the photon model) implement it; a plain number is shorthand for
:class:`Gaussian` (:func:`as_noise`). A new noise model (a measured read-noise curve, ...) is a
new subclass, in any module, plus an entry in :data:`NOISE_MODELS` for files to record it and
one in :data:`splitcam.training.noise.TRAINING_NOISE` to train under it.

Training noise is one class, :class:`TrainingNoise`: each step's levels come from a level
sampler (:class:`UniformSigma`, :class:`LogUniformExposure`, or any function ``(n, generator)
-> levels``) and the noise from the levels' own batch draw. It owns seeded generators (so a
resumed run draws the same noise as an uninterrupted one): the levels on the CPU, the noise on
the device of the raw images (:class:`_TrainingDraws`). :func:`GaussianNoise` and
:func:`PhotonNoise` build it for the two shipped models. Evaluation noise comes from
:meth:`NoiseModel.add`, seeded from the image's name and the level, so that every pattern and
every method is scored on identical noise. Nothing here touches Python's ``random`` or global
RNGs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

import torch

from ..checks import check_count

__all__ = [
    "NoiseModel",
    "NoiseLevels",
    "Gaussian",
    "as_noise",
    "level_heading",
    "level_key",
    "level_label",
    "parse_level_label",
    "Exposure",
    "GaussianNoise",
    "LogUniformExposure",
    "NOISE_MODELS",
    "PhotonNoise",
    "TrainingNoise",
    "UniformSigma",
    "noise_from_dict",
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

    @classmethod
    def apply_batch(
        cls, raw: torch.Tensor, levels: Sequence[NoiseModel], generator: torch.Generator
    ) -> torch.Tensor:
        """A training batch made noisy, one level per image (``levels``, all of this class),
        drawn from ``generator`` on its device. The default applies each image's level in
        turn (:meth:`apply`); a model overrides it to draw the whole batch at once.

        Shape:
            raw: ``(N, 1, H, W)``; ``len(levels) == N``; output like ``raw``.
        """
        if len(levels) != raw.shape[0]:
            raise ValueError(f"expected one noise level per image, got {len(levels)}")
        return torch.cat([lv.apply(raw[i : i + 1], generator) for i, lv in enumerate(levels)])

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

    def to_dict(self) -> dict[str, Any]:
        """The level as JSON-ready fields, with its kind (``model``: its key in
        :data:`NOISE_MODELS`), so that files can record any noise model
        (:func:`noise_from_dict` reads it back)."""
        kind = next((k for k, c in NOISE_MODELS.items() if c is type(self)), None)
        if kind is None:
            raise TypeError(f"{type(self).__name__} is not in NOISE_MODELS: add it to be saved")
        return {"model": kind, **dataclasses.asdict(self)}


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

    @classmethod
    def apply_batch(
        cls, raw: torch.Tensor, levels: Sequence[NoiseModel], generator: torch.Generator
    ) -> torch.Tensor:
        """The training draw: float32 noise on ``generator``'s device, scaled per image."""
        if len(levels) != raw.shape[0]:
            raise ValueError(f"expected one noise level per image, got {len(levels)}")
        noise = torch.randn(
            raw.shape, generator=generator, dtype=torch.float32, device=generator.device
        )
        noise = noise.to(device=raw.device, dtype=raw.dtype)
        sigma = torch.tensor([lv.sigma for lv in levels], dtype=torch.float64)
        scale = (sigma / 255.0).to(device=raw.device, dtype=raw.dtype).view(-1, 1, 1, 1)
        return raw + scale * noise

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


class NoiseLevels(list):
    """The noise levels of a batch as one object: one :class:`NoiseModel` per image, or one for
    the whole batch. :meth:`of` reads every form a caller may give (a number, a noise model, a
    1-D tensor of sigmas, a list of either); what the LMMSE and the networks need of a batch is
    asked of it (:meth:`variance_coefficients`, :meth:`level_map`), so no other module converts
    levels.

    >>> levels = NoiseLevels.of([5, Exposure(100.0)])
    >>> [lv.label() for lv in levels], levels.shared is None
    (['5', 'N100'], True)
    """

    @classmethod
    def of(cls, levels: Any) -> NoiseLevels:
        """A batch's levels from a number or noise model (one for the batch), a tensor of
        sigmas (8-bit units), or a list or tuple of numbers and noise models.

        Raises:
            TypeError, ValueError: A level that is neither a noise model nor a valid sigma, or
                no level at all.
        """
        if isinstance(levels, NoiseLevels):
            return levels
        if isinstance(levels, torch.Tensor):
            levels = levels.detach().reshape(-1).to("cpu", torch.float64).tolist()
        if isinstance(levels, (list, tuple)):
            if not levels:
                raise ValueError("expected one or more noise levels, got none")
            return cls(as_noise(lv) for lv in levels)
        return cls([as_noise(levels)])

    @property
    def shared(self) -> NoiseModel | None:
        """The batch's one level, where every image has the same; else None."""
        return self[0] if all(lv == self[0] for lv in self[1:]) else None

    def for_batch(self, n: int) -> NoiseLevels:
        """These levels checked against a batch of ``n`` images: one, or one per image.

        Raises:
            ValueError: Neither.
        """
        if len(self) not in (1, n):
            raise ValueError(f"expected 1 or {n} noise levels, got {len(self)}")
        return self

    def variance_coefficients(self) -> torch.Tensor:
        """``(len, 2)`` float64: each level's ``(a, b)``
        (:meth:`NoiseModel.variance_coefficients`)."""
        return torch.tensor([lv.variance_coefficients() for lv in self], dtype=torch.float64)

    def level_map(self, cells: torch.Tensor) -> torch.Tensor:
        """The noise level a network is told, ``(N, 1, h, w)``, from the raw image's period
        cells ``(N, P, h, w)``: each image's :meth:`NoiseModel.level_map` (one map where the
        batch shares one level; Gaussian sigmas as one tensor)."""
        n = cells.shape[0]
        self.for_batch(n)
        shared = self.shared
        if shared is not None:
            return shared.level_map(cells)
        if all(isinstance(lv, Gaussian) for lv in self):
            sigma = torch.tensor([lv.sigma for lv in self], dtype=torch.float64)
            sigma = sigma.to(dtype=cells.dtype, device=cells.device)
            return sigma.view(n, 1, 1, 1).expand(n, 1, *cells.shape[-2:])
        return torch.cat([lv.level_map(cells[i : i + 1]) for i, lv in enumerate(self)])


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
    light shows as lost signal. Noise, in order: shot noise ``Poisson(e)`` (``shot``) and
    ``Poisson(dark)`` dark electrons (whose mean a dark frame removes at the end: ``dark`` adds
    noise, not signal), saturation of the collected electrons at ``full_well`` (the well
    fills before readout, so the read noise added after it is not clipped by the well), read
    noise ``N(0, read_noise^2)`` electrons, an ADC ``DN = round(e / gain) + black`` clipped to
    ``[0, 2^bits - 1]`` (``gain`` not None; ``black``: the black level, a pedestal of DN that
    a camera adds so that read noise below 0 e⁻ is not clipped, subtracted again after the
    ADC; with 0, the default, the ADC clips dark pixels at 0 DN and raises their mean); the
    raw image handed on is ``(DN - black) * gain * 3 / N`` (or ``e * 3 / N`` without ADC), the
    same scale for every pattern. With ``shot=False``, no full well, no ADC and
    ``read_noise = N sigma / (3 * 255)`` this is the Gaussian model of model.md §3.

    Raises:
        ValueError: Non-positive or non-finite ``photons``; negative ``read_noise``;
            non-positive ``full_well`` or ``gain``; ``bits < 1``; a ``black`` level that is
            not a whole number of DN in ``[0, 2^bits - 1)`` or is given without an ADC.
    """

    photons: float
    read_noise: float = 2.0
    full_well: float | None = None
    gain: float | None = None
    bits: int = 12
    shot: bool = True
    dark: float = 0.0
    black: int = 0

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
        if (
            isinstance(self.black, bool)
            or not isinstance(self.black, Integral)
            or not 0 <= self.black < 2**self.bits - 1
        ):
            raise ValueError(
                f"expected black (level, DN) a whole number in [0, {2**self.bits - 1}), "
                f"got {self.black!r}"
            )
        if self.black and self.gain is None:
            raise ValueError("a black level is a pedestal of the ADC: give the gain too")

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
        """The noisy raw image of a clean one (``raw``, values >= 0 in the units of model.md §1),
        drawn on the CPU (:meth:`apply_batch` with one exposure for the whole tensor)."""
        out = self._electrons(raw.detach().cpu(), self.electrons_per_unit, generator)
        return out.to(device=raw.device, dtype=raw.dtype)

    @classmethod
    def apply_batch(
        cls, raw: torch.Tensor, levels: Sequence[NoiseModel], generator: torch.Generator
    ) -> torch.Tensor:
        """The whole batch at once, one exposure per image, on ``generator``'s device in
        float64. The exposures must share their sensor settings (read noise, dark current, full
        well, gain, bits, shot): only the photons may differ.

        Shape:
            raw: ``(N, 1, H, W)``, values >= 0 in the units of model.md §1; ``len(levels) ==
            N``; output: like ``raw``, on its device and in its dtype.
        """
        first = levels[0]
        if len(levels) != raw.shape[0] or any(
            dataclasses.replace(e, photons=first.photons) != first for e in levels
        ):
            raise ValueError("expected one exposure per image, all with the same sensor settings")
        per_unit = torch.tensor(
            [e.electrons_per_unit for e in levels], dtype=torch.float64, device=generator.device
        ).view(-1, 1, 1, 1)
        out = first._electrons(raw.detach().to(generator.device), per_unit, generator)
        return out.to(device=raw.device, dtype=raw.dtype)

    def _electrons(
        self, raw: torch.Tensor, per_unit: float | torch.Tensor, generator: torch.Generator
    ) -> torch.Tensor:
        """The photon model, once: shot, dark, full well, read noise, ADC, in that order, in
        float64 on ``raw``'s device (``generator``'s); ``per_unit``: electrons per raw unit,
        one number or one per image. Returns raw units, float64."""
        e = raw.to(torch.float64).clamp_min(0) * per_unit
        if self.shot:
            e = torch.poisson(e, generator=generator)
        if self.dark > 0:
            e = e + torch.poisson(torch.full_like(e, self.dark), generator=generator)
        if self.full_well is not None:  # the well holds the collected electrons: before readout
            e = e.clamp(max=self.full_well)
        if self.read_noise > 0:
            noise = torch.randn(e.shape, generator=generator, dtype=torch.float64, device=e.device)
            e = e + self.read_noise * noise
        if self.gain is not None:
            dn = (torch.round(e / self.gain) + self.black).clamp(0, 2**self.bits - 1)
            e = (dn - self.black) * self.gain
        e = e - self.dark  # the dark frame's mean subtracted; its noise stays
        return e / per_unit

    def key(self) -> str:
        key = (
            f"N{self.photons:g}|r{self.read_noise:g}|{self._well_key()}|g{self.gain}"
            f"|b{self.bits}|s{int(self.shot)}"
        )
        # Without dark current or black level the key (and so every seed and stored result) is
        # as before.
        return (
            key
            + (f"|d{self.dark:g}" if self.dark else "")
            + (f"|k{self.black}" if self.black else "")
        )

    def _well_key(self) -> str:
        """``fwNone`` without a full well, as before; with one, a new spelling: results stored
        when the well clipped the read noise at zero are not reused."""
        return "fwNone" if self.full_well is None else f"well{self.full_well}"

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
        for name in ("dark", "black"):
            if not settings[name]:
                del settings[name]  # as recorded before they were modelled
        return settings


def add_exposure_noise(raw: torch.Tensor, image_name: str, exposure: Exposure) -> torch.Tensor:
    """The deterministic photon-model noise of one image at one exposure (evaluation): the same
    draw for every method of one pattern, seeded from the image name and the exposure
    (:meth:`Exposure.add`)."""
    return exposure.add(raw, image_name)


def photon_noise(
    raw: torch.Tensor, exposures: Sequence[Exposure], generator: torch.Generator
) -> torch.Tensor:
    """A batch made noisy by the photon model, one :class:`Exposure` per image
    (:meth:`Exposure.apply_batch`)."""
    return Exposure.apply_batch(raw, exposures, generator)


#: The noise models a file can record, by the ``model`` key of :meth:`NoiseModel.to_dict`.
#: A new noise model that files should record is one entry here.
NOISE_MODELS: dict[str, type[NoiseModel]] = {"gaussian": Gaussian, "photon": Exposure}


def noise_from_dict(fields: dict[str, Any]) -> NoiseModel:
    """The level :meth:`NoiseModel.to_dict` wrote.

    Raises:
        ValueError: An unknown ``model`` (the message lists :data:`NOISE_MODELS`) or bad fields.
    """
    fields = dict(fields)
    kind = fields.pop("model", None)
    if kind not in NOISE_MODELS:
        raise ValueError(f"unknown noise model {kind!r}; known: {', '.join(NOISE_MODELS)}")
    try:
        return NOISE_MODELS[kind](**fields)
    except TypeError as exc:
        raise ValueError(f"noise model {kind}: {exc}") from None


# --- training: one noise, levels from a sampler ----------------------------------------------


@dataclass(frozen=True)
class UniformSigma:
    """The paper's training levels: Gaussian sigma (8-bit units) drawn from ``U[lo, hi]``."""

    lo: float = 0.0
    hi: float = 30.0

    def __post_init__(self) -> None:
        if not 0 <= self.lo <= self.hi < float("inf"):
            raise ValueError(f"expected 0 <= sigma_lo <= sigma_hi, got {(self.lo, self.hi)!r}")

    def __call__(self, n: int, generator: torch.Generator) -> list[Gaussian]:
        sigma = self.lo + (self.hi - self.lo) * torch.rand(
            n, generator=generator, dtype=torch.float64
        )
        # The levels as float32 numbers: what the networks are told is what the noise is.
        return [Gaussian(float(s)) for s in sigma.float()]


@dataclass(frozen=True)
class LogUniformExposure:
    """The photon model's training levels: exposure ``N`` drawn log-uniformly from
    ``[lo, hi]``, the other sensor settings (``read_noise``, ``full_well``, ...) fixed."""

    lo: float = 10.0
    hi: float = 1e4
    sensor: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        Exposure(self.lo, **self.sensor)  # validates the sensor settings and the range ends
        Exposure(self.hi, **self.sensor)
        if self.lo > self.hi:
            raise ValueError(f"expected photons lo <= hi, got {(self.lo, self.hi)!r}")

    def __call__(self, n: int, generator: torch.Generator) -> list[Exposure]:
        lo, hi = math.log(self.lo), math.log(self.hi)
        photons = torch.exp(
            lo + (hi - lo) * torch.rand(n, generator=generator, dtype=torch.float64)
        )
        return [Exposure(float(p), **self.sensor) for p in photons]


class TrainingNoise(_TrainingDraws):
    """Training noise: each step's levels from ``sampler`` (a function ``(n, generator) ->
    [NoiseModel] * n``, e.g. :class:`UniformSigma`), the noise itself drawn by the levels' own
    :meth:`NoiseModel.apply_batch`, so any noise model trains through this one class.

    Args:
        sampler: Draws the levels on the CPU generator.
        per_sample: One level per sample instead of one per batch (the paper's choice).
        seed: Seed of the generators.
        device: Where the noise is drawn (see :class:`_TrainingDraws`; default the CPU).

    Returns (when called on ``(N, 1, H, W)`` raw images): the noisy images and the level of
    each image, the objects evaluation uses (what the LMMSE solves for and the networks are
    told).
    """

    def __init__(
        self,
        sampler: Callable[[int, torch.Generator], list[NoiseModel]],
        *,
        per_sample: bool = False,
        seed: int = 0,
        device: torch.device | str | None = None,
    ) -> None:
        self.sampler = sampler
        self.per_sample = per_sample
        self._seed(seed, device)

    def __call__(self, raw: torch.Tensor) -> tuple[torch.Tensor, list[NoiseModel]]:
        n = raw.shape[0] if self.per_sample else 1
        levels = list(self.sampler(n, self.generator))
        levels = levels * raw.shape[0] if n == 1 else levels
        return type(levels[0]).apply_batch(raw, levels, self.field), levels


def GaussianNoise(  # noqa: N802 - the paper's training noise, by the name it always had
    sigma: float | tuple[float, float] = (0.0, 30.0),
    *,
    per_sample: bool = False,
    seed: int = 0,
    device: torch.device | str | None = None,
) -> TrainingNoise:
    """:class:`TrainingNoise` of :class:`UniformSigma` (one sigma, or a ``(lo, hi)`` range)."""
    lo, hi = (sigma, sigma) if isinstance(sigma, (int, float)) else tuple(sigma)
    return TrainingNoise(UniformSigma(lo, hi), per_sample=per_sample, seed=seed, device=device)


def PhotonNoise(  # noqa: N802 - the photon model's training noise, by the name it always had
    photons: float | tuple[float, float] = (10.0, 1e4),
    *,
    per_sample: bool = False,
    seed: int = 0,
    device: torch.device | str | None = None,
    **sensor: Any,
) -> TrainingNoise:
    """:class:`TrainingNoise` of :class:`LogUniformExposure` (``sensor``: the
    :class:`Exposure` settings besides the photons)."""
    lo, hi = (photons, photons) if isinstance(photons, (int, float)) else tuple(photons)
    sampler = LogUniformExposure(float(lo), float(hi), dict(sensor))
    return TrainingNoise(sampler, per_sample=per_sample, seed=seed, device=device)


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
