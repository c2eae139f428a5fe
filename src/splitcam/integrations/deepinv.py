"""splitcam's sensor and noise as a ``deepinv`` physics operator, and ``deepinv`` solvers as
splitcam reconstruction methods.

`deepinv <https://deepinv.github.io>`_ is the PyTorch library for imaging inverse problems. Its
solvers (proximal gradient, ADMM, plug-and-play, unrolled networks, ...) run on any
:class:`deepinv.physics.LinearPhysics`; this module makes a splitter sensor one:

- :class:`SplitterPhysics`: ``A`` is the sensor's image formation (model.md §1, Eq. 1) and
  ``A_adjoint`` its exact adjoint, for any pattern of the library, a pattern file or a
  :class:`~splitcam.patterns.Pattern`. Built from a
  :class:`~splitcam.physics.sensor.LearnableSplitterSensor`, the kernels stay learnable: the
  sensor's logits are the physics' parameters, and gradients reach them through ``A``.
- :class:`SplitcamGaussianNoise`: the paper's noise ``N(0, (sigma/255)^2)`` (model.md §3),
  ``sigma`` in 8-bit units, drawn by :class:`splitcam.physics.noise.GaussianNoise`.
- :class:`SplitcamPhotonNoise`: the photon model at one exposure (model.md §11), drawn by
  :meth:`splitcam.physics.noise.Exposure.apply`.
- :class:`DeepinvReconstructor`: any ``deepinv`` reconstruction ``model(y, physics)`` as a
  splitcam :class:`~splitcam.recon.Reconstructor`, so :mod:`splitcam.evaluation` scores it on the
  same scenes and noise as every other method.

Images are ``(N, 3, H, W)`` in [0, 1] (any ``H, W >= 1``), measurements ``(N, 1, H, W)`` on the
raw scale of model.md §1 (a white scene gives up to 4 at a splitter pixel; noise is added on
that scale).

deepinv is an optional dependency (``pip install 'splitcam[deepinv]'``); importing this module
without it raises an ImportError that says so.

deepinv imports torchvision, whose compiled operators load only beside the torch they were
built for (a CUDA wheel of torchvision beside a CPU-only torch fails inside torchvision's own
import). This module checks that before importing deepinv and, where they do not load, raises
one ImportError naming the two versions and the install command of the matching torchvision.
"""

from __future__ import annotations

import importlib.util
import logging
from collections.abc import Callable
from typing import Any

import torch

from ..io.domains import SRGB
from ..patterns import Pattern
from ..physics.noise import (
    Exposure,
    GaussianNoise,
    NoiseModel,
    UniformSigma,
    check_level,
    check_sigma,
)
from ..physics.sensor import SplitterSensor
from ._torchvision import torchvision_mismatch

logger = logging.getLogger(__name__)

INSTALL_HINT = "pip install 'splitcam[deepinv]'"


def _import_deepinv() -> Any:
    """deepinv, or one line saying why not: not installed (with the extra that installs it), or
    installed beside a torchvision built for another torch (with the command that installs the
    matching one). Whether deepinv is there is asked first, without importing it (importing it
    imports torchvision)."""
    try:
        installed = importlib.util.find_spec("deepinv") is not None
    except ValueError:  # in sys.modules as None: import blocked
        installed = False
    if not installed:
        raise ImportError(
            f"splitcam.integrations.deepinv needs deepinv, an optional dependency: {INSTALL_HINT}"
        )
    problem = torchvision_mismatch()
    if problem is not None:
        raise ImportError(problem)
    import deepinv

    return deepinv


dinv = _import_deepinv()

__all__ = [
    "INSTALL_HINT",
    "DeepinvReconstructor",
    "SplitcamGaussianNoise",
    "SplitcamNoise",
    "SplitcamPhotonNoise",
    "SplitterPhysics",
    "noise_model",
]

NoiseLevel = float | NoiseModel | dinv.physics.NoiseModel | None


class SplitcamGaussianNoise(dinv.physics.NoiseModel):
    """splitcam's Gaussian noise (model.md §3) as a deepinv noise model: ``y = z + n``,
    ``n ~ N(0, (sigma_8bit / 255)^2)``, drawn by :class:`splitcam.physics.noise.GaussianNoise`
    with a fixed sigma (for one seed, the same draws as that class).

    :attr:`sigma` follows deepinv's convention, the standard deviation on the measurements' scale
    (``sigma_8bit / 255``), so deepinv code that reads ``physics.noise_model.sigma`` gets the
    right level; :attr:`sigma_8bit` is splitcam's. ``forward(z, sigma=s)`` (deepinv units) and
    :meth:`update_parameters` change the level; ``forward(z, seed=k)`` reseeds the generator.
    The noise is added to ``z`` (gradients pass through).

    Args:
        sigma: Noise level in 8-bit units (``>= 0``).
        seed: Seed of the generator (a CPU ``torch.Generator``; draws are moved to ``z``'s
            device, so every device sees the same noise).
    """

    def __init__(self, sigma: float = 0.0, *, seed: int = 0) -> None:
        super().__init__()
        self.model = GaussianNoise(check_sigma(sigma), seed=seed)
        self._initial_state = self.model.generator.get_state()

    @property
    def sigma_8bit(self) -> float:
        return self.model.sampler.lo

    @property
    def sigma(self) -> torch.Tensor:
        """The noise standard deviation on the measurements' scale, ``sigma_8bit / 255``."""
        return torch.tensor(self.sigma_8bit / 255.0)

    def update_parameters(
        self, sigma: float | torch.Tensor | None = None, sigma_8bit: float | None = None, **kwargs
    ) -> None:
        """Set the level: ``sigma`` in deepinv's units (``sigma_8bit / 255``) or ``sigma_8bit``.

        Raises:
            ValueError: Both given, a level per sample (a tensor of several values), or a level
                :func:`~splitcam.physics.noise.check_sigma` refuses.
        """
        if sigma is not None and sigma_8bit is not None:
            raise ValueError("give sigma (deepinv units) or sigma_8bit, not both")
        if sigma is not None:
            if isinstance(sigma, torch.Tensor):
                if sigma.numel() != 1:
                    raise ValueError(
                        f"expected one noise level for the batch, got {sigma.numel()} values"
                    )
                sigma = float(sigma)
            sigma_8bit = check_sigma(sigma) * 255.0
        if sigma_8bit is not None:
            level = check_sigma(sigma_8bit)
            self.model.sampler = UniformSigma(level, level)

    def rng_manual_seed(self, seed: int | None = None) -> None:
        if seed is not None:
            self.model.generator.manual_seed(seed)

    def reset_rng(self) -> None:
        """Back to the generator's state at construction."""
        self.model.generator.set_state(self._initial_state)

    def forward(self, x: torch.Tensor, seed: int | None = None, **kwargs: Any) -> torch.Tensor:
        self.update_parameters(**kwargs)
        self.rng_manual_seed(seed)
        return self.model(x)[0]

    def extra_repr(self) -> str:
        return f"sigma_8bit={self.sigma_8bit:g}"


class SplitcamNoise(dinv.physics.NoiseModel):
    """A splitcam :class:`~splitcam.physics.noise.NoiseModel` as a deepinv noise model: the
    photon model at one exposure (model.md §11), or any other level of that interface.

    For the photon model:

    The measurement ``z`` (raw units, model.md §1) becomes ``e = z N / 3`` photo-electrons;
    shot noise, read noise, full well and ADC follow as :meth:`Exposure.apply
    <splitcam.physics.noise.Exposure.apply>` draws them (for one seed, the same draws), and the
    result is back on the raw scale. Like that method, the noise is not differentiable (the
    output carries no gradient) and negative inputs count as no light.

    :attr:`gain` and :attr:`sigma` are the raw-scale noise variance ``gain * z + sigma^2``
    (shot, read and quantisation noise, saturation ignored), deepinv's Poisson-Gaussian
    convention: ``gain = 3 / N`` (0 without shot noise); for any level, its
    :meth:`~splitcam.physics.noise.NoiseModel.variance_coefficients`.

    Args:
        exposure: A :class:`~splitcam.physics.noise.NoiseModel` (an
            :class:`~splitcam.physics.noise.Exposure`, for example), or the photo-electrons
            ``N`` of an Exposure with the settings in ``sensor``.
        seed: Seed of the generator (CPU).
        **sensor: ``read_noise``, ``full_well``, ``gain``, ``bits``, ``shot`` of
            :class:`~splitcam.physics.noise.Exposure` when ``exposure`` is a number.
    """

    def __init__(self, exposure: NoiseModel | float, *, seed: int = 0, **sensor: Any) -> None:
        super().__init__()
        if not isinstance(exposure, NoiseModel):
            exposure = Exposure(exposure, **sensor)
        elif sensor:
            raise ValueError("give the sensor settings in the Exposure, not beside it")
        self.exposure = exposure
        self.generator = torch.Generator().manual_seed(seed)
        self._initial_state = self.generator.get_state()

    @property
    def gain(self) -> torch.Tensor:
        return torch.tensor(self.exposure.variance_coefficients()[0])

    @property
    def sigma(self) -> torch.Tensor:
        return torch.tensor(self.exposure.variance_coefficients()[1] ** 0.5)

    def rng_manual_seed(self, seed: int | None = None) -> None:
        if seed is not None:
            self.generator.manual_seed(seed)

    def reset_rng(self) -> None:
        self.generator.set_state(self._initial_state)

    def forward(self, x: torch.Tensor, seed: int | None = None, **kwargs: Any) -> torch.Tensor:
        self.rng_manual_seed(seed)
        return self.exposure.apply(x, self.generator)

    def extra_repr(self) -> str:
        return f"exposure={self.exposure}"


#: The name under which the photon model's deepinv noise was first offered.
SplitcamPhotonNoise = SplitcamNoise


def noise_model(level: NoiseLevel, *, seed: int = 0) -> dinv.physics.NoiseModel:
    """The deepinv noise model of a splitcam noise level.

    ``None`` gives no noise (:class:`deepinv.physics.ZeroNoise`), a number a
    :class:`SplitcamGaussianNoise` of that sigma (8-bit units), a splitcam
    :class:`~splitcam.physics.noise.NoiseModel` (an
    :class:`~splitcam.physics.noise.Exposure`, say) a :class:`SplitcamNoise`; a deepinv
    :class:`~deepinv.physics.NoiseModel` is returned as it is.

    Raises:
        TypeError: A level that is neither a number nor one of these.
        ValueError: A negative or non-finite sigma
            (:func:`~splitcam.physics.noise.check_level`).
    """
    if level is None:
        return dinv.physics.ZeroNoise()
    if isinstance(level, dinv.physics.NoiseModel):
        return level
    level = check_level(level)
    if isinstance(level, NoiseModel):
        return SplitcamNoise(level, seed=seed)
    return SplitcamGaussianNoise(level, seed=seed)


_to_noise_model = noise_model  # for SplitterPhysics.set_noise_model, whose argument hides it


class SplitterPhysics(dinv.physics.LinearPhysics):
    """A splitter sensor as a deepinv linear operator: ``y = N(A x)``.

    ``A`` is the sensor's image formation (:func:`~splitcam.physics.sensor.splitter_forward`,
    model.md §1) and ``A_adjoint`` its exact adjoint
    (:func:`~splitcam.physics.sensor.splitter_adjoint`); both compute in the input's dtype and
    on its device (``physics.to(device)`` moves the sensor). The sensor is a sub-module
    (:attr:`splitter`), so a :class:`~splitcam.physics.sensor.LearnableSplitterSensor` keeps its
    logits as parameters of the physics: they appear in ``physics.parameters()`` and receive
    gradients through ``A``, which is how a deepinv trainer can learn the pattern jointly with a
    reconstruction.

    Everything deepinv derives from ``A`` and ``A_adjoint`` works: ``A_dagger`` (least squares),
    ``prox_l2``, ``compute_norm``, ``adjointness_test``, and every solver of
    :mod:`deepinv.optim`. ``kwargs`` that deepinv passes to ``A`` (such as ``seed`` or ``sigma``
    for the noise) are ignored by it.

    Args:
        sensor: A :class:`~splitcam.physics.sensor.SplitterSensor` (fixed, learnable or
            switching), or a pattern (library name, pattern file or
            :class:`~splitcam.patterns.Pattern`) to build a fixed one from.
        noise: ``None`` (no noise), a Gaussian sigma in 8-bit units, a photon-model
            :class:`~splitcam.physics.noise.Exposure`, or any deepinv noise model
            (:func:`noise_model`).
        seed: Seed of the noise generator (for splitcam's noise).
        **kwargs: Passed to :class:`deepinv.physics.LinearPhysics` (e.g. ``max_iter``,
            ``tol``, ``solver`` of its least-squares solves).

    Shape:
        - ``A`` / ``forward``: ``(N, 3, H, W)`` to ``(N, 1, H, W)``.
        - ``A_adjoint``: ``(N, 1, H, W)`` to ``(N, 3, H, W)``.
    """

    def __init__(
        self,
        sensor: SplitterSensor | Pattern | str,
        noise: NoiseLevel = None,
        *,
        seed: int = 0,
        **kwargs: Any,
    ) -> None:
        super().__init__(noise_model=noise_model(noise, seed=seed), **kwargs)
        self.splitter = sensor if isinstance(sensor, SplitterSensor) else SplitterSensor(sensor)

    @property
    def pattern(self) -> Pattern:
        """The pattern the sensor holds now (learned kernels included)."""
        return self.splitter.to_pattern()

    def A(self, x: torch.Tensor, **kwargs: Any) -> torch.Tensor:
        return self.splitter(x)

    def A_adjoint(self, y: torch.Tensor, **kwargs: Any) -> torch.Tensor:
        return self.splitter.adjoint(y)

    def set_noise_model(self, noise_model: NoiseLevel, seed: int = 0, **kwargs: Any) -> None:
        """Use this noise from now on: a splitcam level or a deepinv model (:func:`noise_model`)."""
        self.noise_model = _to_noise_model(noise_model, seed=seed)


class DeepinvReconstructor:
    """A deepinv reconstruction as a splitcam :class:`~splitcam.recon.Reconstructor`.

    ``reconstruct(raw, sigma)`` sets the physics' noise model to splitcam's model of ``sigma``
    (a Gaussian sigma in 8-bit units or an :class:`~splitcam.physics.noise.Exposure`), so
    noise-aware deepinv models read the level from ``physics.noise_model``, and returns
    ``model(raw, physics)`` without gradients. The evaluation protocol
    (:mod:`splitcam.evaluation.protocol`) then scores it on the same scenes and noise as every
    other method.

    Args:
        model: Any callable ``model(y, physics) -> x``: a deepinv solver (e.g.
            :class:`deepinv.optim.PGD`), network or function.
        physics: The :class:`SplitterPhysics` of the pattern whose raw images it reconstructs.
        name: Short label for tables.
        domain: The light domain of the raw images and estimates (``srgb`` or ``linear``,
            model.md §13).
    """

    def __init__(
        self,
        model: Callable[[torch.Tensor, SplitterPhysics], torch.Tensor],
        physics: SplitterPhysics,
        name: str = "deepinv",
        domain: str = SRGB,
    ) -> None:
        self.model = model
        self.physics = physics
        self.name = name
        self.domain = domain

    @property
    def pattern(self) -> Pattern:
        """The pattern the physics' sensor holds now (learned kernels included)."""
        return self.physics.pattern

    def reconstruct(self, raw: torch.Tensor, sigma: float | NoiseModel) -> torch.Tensor:
        self.physics.set_noise_model(check_level(sigma))
        with torch.no_grad():
            return self.model(raw, self.physics).to(raw.dtype)
