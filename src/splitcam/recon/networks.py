"""Reconstruction networks: raw single-channel sensor images to RGB.

Two architectures share the same convolutional trunk (head conv, ``blocks`` residual blocks, a
conv, a long skip from the head, tail conv; all 3x3, zero padding, biases, no output activation):

- :class:`ReconNet` (``arch="paper"``, the network of the paper's Fig. 2) first spreads the raw
  image over ``Ph * Pw`` channels by position class (:class:`PeriodicSampling`) and runs the trunk
  at full resolution.
- :class:`PackedReconNet` (``arch="packed"``) rearranges each period cell into channels
  (:func:`period_unshuffle`), runs the trunk at ``1 / (Ph * Pw)`` of the pixels and rearranges the
  ``3 * Ph * Pw`` output channels back (:func:`period_shuffle`).
- :class:`PhysicsReconNet` (``arch="physics"``) is the packed network given the physics: besides
  the packed raw image it receives the closed-form LMMSE estimate for the sensor's kernels and
  noise level (:func:`splitcam.recon.closed_form.lmmse_estimate`) and the noise level itself, and
  predicts the correction to that estimate (its last layer starts at zero, so an untrained
  network *is* the LMMSE). It is called as ``net(raw, sigma, kernels)`` (``uses_physics``); the
  other two are blind and take only ``raw``.

All store ``period``, report ``receptive_radius`` (what :func:`splitcam.recon.tiling.reconstruct`
needs to tile exactly) and round-trip through ``config()`` / :func:`build_network`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_count, check_period, check_raw
from ..physics.noise import NoiseLevels, NoiseModel
from ..physics.periodic import period_shuffle, period_unshuffle, phase_conv, phase_map
from .closed_form import ImageStatistics, lmmse_estimate, shipped_image_statistics
from .lmmse import DEFAULT_RADIUS

__all__ = [
    "ARCHITECTURES",
    "PackedReconNet",
    "PeriodicSampling",
    "PhysicsReconNet",
    "ReconNet",
    "UniversalReconNet",
    "build_network",
    "serves_any_pattern",
]


class PeriodicSampling(nn.Module):
    """Spread a raw image over one channel per position class of the period.

    Channel ``i * Pw + j`` holds the raw value at every pixel ``(y, x)`` with ``y % Ph == i`` and
    ``x % Pw == j`` and 0 elsewhere. Classes are counted from the top-left pixel of the input, so
    a crop must start at a multiple of the period to keep them.

    Args:
        period: ``(Ph, Pw)``.

    Shape:
        - Input: ``(N, 1, H, W)``, any ``H, W >= 1``.
        - Output: ``(N, Ph * Pw, H, W)``.
    """

    def __init__(self, period: tuple[int, int]) -> None:
        super().__init__()
        self.period = check_period(period)

    def forward(self, raw: torch.Tensor) -> torch.Tensor:
        ph, pw = self.period
        h, w = raw.shape[-2:]
        # A mask costs as much as the multiply it feeds, far less than one conv layer, so it is
        # rebuilt per call rather than cached for every tile size a tiled run produces.
        classes = torch.arange(ph * pw, device=raw.device)[:, None, None]
        mask = (phase_map(h, w, self.period, raw.device)[None] == classes).to(raw.dtype)
        return raw * mask

    def extra_repr(self) -> str:
        return f"period={self.period}"


def _conv3x3(in_channels: int, out_channels: int) -> nn.Conv2d:
    return nn.Conv2d(in_channels, out_channels, kernel_size=3, padding=1, bias=True)


def _reach(conv: nn.Conv2d) -> int:
    """Pixels of context one conv adds on each side (the larger of the two axes)."""
    return max((k - 1) // 2 * d for k, d in zip(conv.kernel_size, conv.dilation, strict=True))


class ResidualBlock(nn.Module):
    """``x + conv(relu(conv(x)))`` with 3x3 convs keeping ``features`` channels.

    Args:
        features: Channel count.

    Shape:
        - Input: ``(N, features, H, W)``.
        - Output: ``(N, features, H, W)``.
    """

    def __init__(self, features: int) -> None:
        super().__init__()
        self.conv1 = _conv3x3(features, features)
        self.conv2 = _conv3x3(features, features)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv2(F.relu(self.conv1(x)))

    @property
    def reach(self) -> int:
        return _reach(self.conv1) + _reach(self.conv2)


class _Trunk(nn.Module):
    """Head conv, residual blocks, a conv, long skip from the head, tail conv."""

    def __init__(self, in_channels: int, out_channels: int, features: int, blocks: int) -> None:
        super().__init__()
        self.head = _conv3x3(in_channels, features)
        self.blocks = nn.Sequential(*(ResidualBlock(features) for _ in range(blocks)))
        self.body_out = _conv3x3(features, features)
        self.tail = _conv3x3(features, out_channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        head = self.head(x)
        return self.tail(head + self.body_out(self.blocks(head)))

    @property
    def reach(self) -> int:
        # The skips only shorten paths, so the longest one runs through every conv.
        body = sum(block.reach for block in self.blocks)
        return _reach(self.head) + body + _reach(self.body_out) + _reach(self.tail)


class _Reconstructor(nn.Module):
    """What both reconstruction networks share: arguments, validation, ``config()``.

    Args:
        period: Splitter pattern period ``(Ph, Pw)``.
        features: Channels ``F`` of the hidden layers.
        blocks: Number ``K`` of residual blocks.

    Raises:
        ValueError: A bad period, ``features < 1`` or ``blocks < 0``.

    Shape:
        - Input: ``(N, 1, H, W)`` raw image, floating point, any ``H, W >= 1``.
        - Output: ``(N, 3, H, W)`` RGB.
    """

    arch = ""

    def __init__(self, period: tuple[int, int], features: int = 64, blocks: int = 10) -> None:
        super().__init__()
        self.period = check_period(period)
        self.features = check_count(features, "features", 1)
        self.num_blocks = check_count(blocks, "blocks", 0)

    def config(self) -> dict[str, Any]:
        """JSON-serialisable description that :func:`build_network` turns back into this net."""
        return {
            "arch": self.arch,
            "period": list(self.period),
            "features": self.features,
            "blocks": self.num_blocks,
        }


class ReconNet(_Reconstructor):
    """The paper's reconstruction network (Fig. 2): periodic sampling, then a residual CNN
    at full resolution. Arguments and shapes: see :class:`_Reconstructor`."""

    arch = "paper"

    def __init__(self, period: tuple[int, int], features: int = 64, blocks: int = 10) -> None:
        super().__init__(period, features, blocks)
        ph, pw = self.period
        self.sampling = PeriodicSampling(self.period)
        self.trunk = _Trunk(ph * pw, 3, self.features, self.num_blocks)

    def forward(self, raw: torch.Tensor) -> torch.Tensor:
        check_raw(raw)
        return self.trunk(self.sampling(raw))

    @property
    def receptive_radius(self) -> int:
        """Pixels of context on each side that can influence an output pixel."""
        return self.trunk.reach


class PackedReconNet(_Reconstructor):
    """Reconstruction at cell resolution: period cells packed into channels, then the trunk.

    The raw image is zero-padded at the bottom and right up to multiples of the period, each
    ``Ph x Pw`` cell becomes a ``Ph * Pw``-channel pixel, the trunk maps those to ``3 * Ph * Pw``
    channels, which are unpacked to RGB cells and cropped back to ``H x W``: the convolutions run
    on ``1 / (Ph * Pw)`` of the positions. Arguments and shapes: see :class:`_Reconstructor`.
    """

    arch = "packed"

    def __init__(self, period: tuple[int, int], features: int = 64, blocks: int = 10) -> None:
        super().__init__(period, features, blocks)
        ph, pw = self.period
        self.trunk = _Trunk(ph * pw, 3 * ph * pw, self.features, self.num_blocks)

    def forward(self, raw: torch.Tensor) -> torch.Tensor:
        check_raw(raw)
        cells = period_unshuffle(raw, self.period)
        rgb = period_shuffle(self.trunk(cells), self.period, raw.shape[-2:])
        return rgb

    @property
    def receptive_radius(self) -> int:
        """Pixels of context on each side that can influence an output pixel.

        ``L`` cells of context at cell resolution reach from the far corner of the output's cell
        to the far corner of a cell ``L`` cells away: ``(L + 1) * P - 1`` pixels along an axis of
        period ``P``; the larger axis is reported.
        """
        return (self.trunk.reach + 1) * max(self.period) - 1


class _WithStatistics(nn.Module):
    """The image statistics a network solves its LMMSE filters from, kept as (float64) buffers
    so a checkpoint carries them, and the check of the physics a network is called with.

    The statistics belong to a light domain (model.md §13): a network for raw images of
    linear radiance holds statistics of linear images (``shipped_image_statistics("linear")``),
    one for sRGB values (the default) the sRGB ones."""

    def _keep_statistics(self, statistics: ImageStatistics | None) -> None:
        stats = statistics if statistics is not None else shipped_image_statistics()
        self.register_buffer("stat_mean", stats.mean.clone())
        self.register_buffer("stat_second", stats.second.clone())

    def statistics(self) -> ImageStatistics:
        return ImageStatistics(self.stat_mean.double(), self.stat_second.double(), 0)

    def use_statistics(self, statistics: ImageStatistics) -> None:
        """Solve the LMMSE from ``statistics`` from now on (the buffers keep their device and
        dtype): e.g. a network whose weights come from one domain, trained on in another.

        Raises:
            ValueError: Statistics of another window size than the network's.
        """
        if tuple(statistics.second.shape) != tuple(self.stat_second.shape):
            raise ValueError(
                f"expected image statistics of shape {tuple(self.stat_second.shape)}, got "
                f"{tuple(statistics.second.shape)}"
            )
        with torch.no_grad():
            self.stat_mean.copy_(statistics.mean)
            self.stat_second.copy_(statistics.second)

    def _check_physics(self, raw: torch.Tensor, sigma: Any, kernels: Any) -> None:
        check_raw(raw)
        if sigma is None or kernels is None:
            raise ValueError(
                f"the {self.arch} network needs the noise level and the sensor's pixel kernels: "
                "call net(raw, sigma, kernels)"
            )


class PhysicsReconNet(_Reconstructor, _WithStatistics):
    """The packed network, given the physics: it corrects the closed-form LMMSE estimate.

    Inputs of the trunk, all at cell resolution: the packed raw image (``Ph * Pw`` channels), the
    packed LMMSE estimate for the sensor's current kernels and the noise level (``3 * Ph * Pw``),
    and the noise level as a constant map (``sigma / 25.5``). The trunk predicts a packed
    correction that is added to the estimate. The trunk's last layer starts at zero, so at
    initialisation the output *is* the LMMSE estimate, and training starts from the best linear
    reconstruction instead of from nothing. With a learned pattern the estimate follows the
    kernels (the filters are solved in closed form at every call, differentiably), so the joint
    optimisation trains through it.

    The image statistics the filters are solved from are kept as (float64) buffers, so a
    checkpoint carries them. Arguments as :class:`_Reconstructor`, plus ``radius``, the LMMSE
    filter radius.

    Shape:
        - raw: ``(N, 1, H, W)``; sigma: a number or ``(N,)``, or for the photon model an
          :class:`~splitcam.physics.noise.Exposure` or one per image (the noise-level input is
          then the per-pixel noise it implies, :func:`noise_level_map`); kernels
          ``(Ph, Pw, 3, kh, kw)``.
        - Output: ``(N, 3, H, W)``.
    """

    arch = "physics"
    uses_physics = True

    def __init__(
        self,
        period: tuple[int, int],
        features: int = 64,
        blocks: int = 10,
        radius: int = DEFAULT_RADIUS,
        statistics: ImageStatistics | None = None,
    ) -> None:
        super().__init__(period, features, blocks)
        ph, pw = self.period
        self.radius = check_count(radius, "radius", 0)
        p = ph * pw
        self.trunk = _Trunk(p + 3 * p + 1, 3 * p, self.features, self.num_blocks)
        nn.init.zeros_(self.trunk.tail.weight)
        nn.init.zeros_(self.trunk.tail.bias)
        self._keep_statistics(statistics)

    def forward(
        self,
        raw: torch.Tensor,
        sigma: float | torch.Tensor | None = None,
        kernels: torch.Tensor | None = None,
    ) -> torch.Tensor:
        self._check_physics(raw, sigma, kernels)
        if tuple(kernels.shape[:2]) != self.period:
            raise ValueError(
                f"expected kernels of period {self.period}, got {tuple(kernels.shape[:2])}"
            )
        estimate = lmmse_estimate(raw, kernels, sigma, self.statistics(), self.radius)
        cells = period_unshuffle(raw, self.period)
        level = noise_level_map(raw, sigma, self.period) / 25.5
        x = torch.cat([cells, period_unshuffle(estimate, self.period), level.to(cells.dtype)], 1)
        correction = period_shuffle(self.trunk(x), self.period, raw.shape[-2:])
        return estimate + correction

    @property
    def receptive_radius(self) -> int:
        """Pixels of context on each side that can influence an output pixel: the packed trunk's
        reach (see :class:`PackedReconNet`) over the estimate, which itself reads ``radius``
        pixels around each of its pixels."""
        return (self.trunk.reach + 1) * max(self.period) - 1 + self.radius

    def config(self) -> dict[str, Any]:
        return {**super().config(), "radius": self.radius}


class UniversalReconNet(_WithStatistics):
    """One network for any pattern: the physics network, told each pixel's kernel (model.md §16).

    Like :class:`PhysicsReconNet` it corrects the closed-form LMMSE estimate of the pattern it is
    given, but nothing in it depends on the period: the trunk runs on fixed 2x2 cells (half the
    resolution per axis, as the physics network does for a 2x2 pattern) and learns what each
    pixel measures from its inputs, all at cell resolution:

    - the raw image (4 channels) and the LMMSE estimate (12), each cell packed into channels;
    - the noise level: ``sigma / 25.5``, or for the photon model the per-pixel standard deviation
      it implies (:func:`noise_level_map`);
    - what the estimate leaves unexplained, ``raw - A(estimate)`` re-simulated through the
      pattern's own Eq. 2 kernels (4 channels): the data-consistency residual an unrolled solver
      would use, the same kind of input for every pattern;
    - each pixel's Eq. 2 gather kernel, zero-padded to ``kernel_size`` squared, through a small
      encoder shared by all pixels (``embed`` features per pixel, ``4 * embed`` per cell). The
      encoder runs once per phase of the pattern and the result is tiled over the image, so it
      costs nothing per pixel.

    The first 17 trunk inputs are those of a 2x2-period :class:`PhysicsReconNet` in the same
    order, so the trunk can start from a trained one (:meth:`load_physics_trunk`). The trunk's last
    layer starts at zero: an untrained network outputs the LMMSE estimate of any pattern.

    Called as ``net(raw, sigma, kernels)`` with pixel kernels ``(Ph, Pw, 3, kh, kw)`` of any
    period and odd ``kh, kw <= kernel_size``. Its ``period`` is ``None``; :meth:`tiling_period`
    gives the alignment tiling needs for one pattern.

    Args:
        features: Channels of the hidden layers.
        blocks: Residual blocks.
        radius: LMMSE filter radius.
        kernel_size: Largest kernel side it accepts (kernels are zero-padded to it).
        embed: Kernel features per pixel.
        statistics: Image statistics of the LMMSE (default: the shipped ones).
    """

    arch = "universal"
    uses_physics = True
    period = None
    #: The fixed cell the trunk packs: not a pattern's period.
    CELL = (2, 2)

    def __init__(
        self,
        features: int = 64,
        blocks: int = 10,
        radius: int = DEFAULT_RADIUS,
        kernel_size: int = 5,
        embed: int = 8,
        statistics: ImageStatistics | None = None,
    ) -> None:
        super().__init__()
        self.features = check_count(features, "features", 1)
        self.num_blocks = check_count(blocks, "blocks", 0)
        self.radius = check_count(radius, "radius", 0)
        self.kernel_size = check_count(kernel_size, "kernel_size", 1)
        if self.kernel_size % 2 == 0:
            raise ValueError(f"kernel_size must be odd, got {kernel_size}")
        self.embed = check_count(embed, "embed", 1)
        taps = 3 * self.kernel_size**2
        self.encoder = nn.Sequential(nn.Linear(taps, 64), nn.ReLU(), nn.Linear(64, self.embed))
        c = self.CELL[0] * self.CELL[1]
        self.trunk = _Trunk(c + 3 * c + 1 + c + self.embed * c, 3 * c, self.features, blocks)
        nn.init.zeros_(self.trunk.tail.weight)
        nn.init.zeros_(self.trunk.tail.bias)
        self._keep_statistics(statistics)

    def _check_kernels(self, kernels: torch.Tensor) -> None:
        if kernels.ndim != 5 or kernels.shape[2] != 3:
            raise ValueError(
                f"expected pixel kernels of shape (Ph, Pw, 3, kh, kw), got {tuple(kernels.shape)}"
            )
        kh, kw = kernels.shape[-2:]
        k = self.kernel_size
        if kh % 2 == 0 or kw % 2 == 0 or kh > k or kw > k:
            raise ValueError(
                f"the universal network takes odd kernels up to {k}x{k}, got {kh}x{kw}"
            )

    def kernel_features(self, kernels: torch.Tensor) -> torch.Tensor:
        """The encoder's features of each phase's kernel, ``(Ph, Pw, embed)``."""
        ph, pw, _, kh, kw = kernels.shape
        py, px = (self.kernel_size - kh) // 2, (self.kernel_size - kw) // 2
        padded = F.pad(kernels, (px, px, py, py))
        weight = self.encoder[0].weight
        return self.encoder(padded.reshape(ph, pw, -1).to(weight.dtype))

    def forward(
        self,
        raw: torch.Tensor,
        sigma: float | torch.Tensor | None = None,
        kernels: torch.Tensor | None = None,
    ) -> torch.Tensor:
        self._check_physics(raw, sigma, kernels)
        self._check_kernels(kernels)
        ph, pw, _, kh, kw = kernels.shape
        n, _, h, w = raw.shape
        cell = self.CELL
        estimate = lmmse_estimate(raw, kernels, sigma, self.statistics(), self.radius)
        with torch.autocast(raw.device.type, enabled=False):
            weight = kernels.to(estimate.dtype).reshape(ph * pw, 1, 3, kh, kw)
            residual = raw.to(estimate.dtype) - phase_conv(estimate, weight, (ph, pw))
            features = self.kernel_features(kernels)  # (Ph, Pw, E)
        # Each pixel's features by its phase (a gather), then packed like the rest.
        index = phase_map(h, w, (ph, pw), raw.device)
        per_pixel = features.reshape(ph * pw, -1)[index].permute(2, 0, 1)
        per_pixel = per_pixel.unsqueeze(0).expand(n, -1, -1, -1)
        level = noise_level_map(raw, sigma, cell) / 25.5
        dtype = raw.dtype
        x = torch.cat(
            [
                period_unshuffle(raw, cell),
                period_unshuffle(estimate, cell).to(dtype),
                level.to(dtype),
                period_unshuffle(residual, cell).to(dtype),
                period_unshuffle(per_pixel.to(dtype), cell),
            ],
            1,
        )
        if raw.is_contiguous(memory_format=torch.channels_last):
            x = x.contiguous(memory_format=torch.channels_last)
        correction = period_shuffle(self.trunk(x), cell, (h, w))
        return estimate + correction

    @property
    def receptive_radius(self) -> int:
        """Pixels of context on each side that can influence an output pixel: the trunk's reach
        at cell resolution (see :class:`PackedReconNet`) over the residual, which reads the
        estimate through a kernel, which reads ``radius`` raw pixels around each pixel."""
        return (self.trunk.reach + 1) * max(self.CELL) - 1 + self.kernel_size // 2 + self.radius

    def tiling_period(self, period: tuple[int, int]) -> tuple[int, int]:
        """The period tiles of a pattern of ``period`` must start at: a multiple of both the
        pattern's period and the trunk's cell, so every tile sees the same phases and cells."""
        return tuple(math.lcm(int(p), c) for p, c in zip(period, self.CELL, strict=True))

    def load_physics_trunk(self, state: Mapping[str, torch.Tensor]) -> None:
        """Start the trunk from a 2x2-period physics network's ``state_dict`` (``trunk.*``).

        Every layer but the head is copied; the head's weights for the physics network's 17
        inputs are copied and those of the extra inputs set to zero, so the trunk computes what
        the physics network computed until training uses the new inputs.
        """
        own = self.trunk.state_dict()
        source = {k[len("trunk.") :]: v for k, v in state.items() if k.startswith("trunk.")}
        missing = sorted(set(own) - set(source))
        if missing:
            raise ValueError(f"not a physics network's state: missing trunk.{missing[0]}")
        head = source["head.weight"]
        if head.shape[1] != 17 or head.shape[0] != own["head.weight"].shape[0]:
            raise ValueError(
                f"expected the head of a 2x2-period physics network with {self.features} "
                f"features (17 inputs), got {tuple(head.shape)}"
            )
        weight = torch.zeros_like(own["head.weight"])
        weight[:, :17] = head
        source["head.weight"] = weight
        self.trunk.load_state_dict(source)

    def config(self) -> dict[str, Any]:
        return {
            "arch": self.arch,
            "features": self.features,
            "blocks": self.num_blocks,
            "radius": self.radius,
            "kernel_size": self.kernel_size,
            "embed": self.embed,
        }


def serves_any_pattern(network: nn.Module) -> bool:
    """Whether a network reconstructs any pattern it is told the kernels of (it has no period of
    its own), rather than the one pattern it was trained for."""
    return isinstance(network, UniversalReconNet)


def noise_level_map(
    raw: torch.Tensor, sigma: float | torch.Tensor | NoiseModel | list[NoiseModel], period
) -> torch.Tensor:
    """The noise standard deviation (8-bit units) at cell resolution, ``(N, 1, H/Ph, W/Pw)``.

    Gaussian noise (a sigma, or a tensor of one per image): that constant. A
    :class:`~splitcam.physics.noise.NoiseModel`, or a list of one per image: each level's
    :meth:`~splitcam.physics.noise.NoiseModel.level_map` (the photon model's ``255 sqrt(a g +
    b)``, with the raw value as each pixel's signal, averaged over each period cell).
    """
    cells = period_unshuffle(raw, period)
    return NoiseLevels.of(sigma).level_map(cells)


#: Network classes by their ``config()["arch"]`` name.
ARCHITECTURES: dict[str, type[nn.Module]] = {
    ReconNet.arch: ReconNet,
    PackedReconNet.arch: PackedReconNet,
    PhysicsReconNet.arch: PhysicsReconNet,
    UniversalReconNet.arch: UniversalReconNet,
}


def build_network(
    config: Mapping[str, Any], *, statistics: ImageStatistics | None = None
) -> nn.Module:
    """Build an (untrained) network from a ``config()`` dictionary.

    Args:
        config: ``{"arch": "paper" | "packed", "period": [Ph, Pw], "features": F,
            "blocks": K}``; ``features`` and ``blocks`` default to 64 and 10.
        statistics: The image statistics of the LMMSE inside the ``physics`` and ``universal``
            networks (default: the shipped sRGB ones; ``shipped_image_statistics("linear")``
            for a network of the linear domain). The blind architectures use none and ignore
            it.

    Returns:
        The network, freshly initialised; load a state dict to restore weights.

    Raises:
        ValueError: ``config`` is not a mapping, names an unknown architecture, lacks the period,
            has unknown keys or a bad value.
    """
    if not isinstance(config, Mapping):
        raise ValueError(f"network config must be a mapping, got {type(config).__name__}")
    arch = config.get("arch")
    if not isinstance(arch, str) or arch not in ARCHITECTURES:
        known = ", ".join(repr(a) for a in ARCHITECTURES)
        raise ValueError(f"unknown network arch {arch!r}; expected one of {known}")
    if arch == UniversalReconNet.arch:
        fields = {"features", "blocks", "radius", "kernel_size", "embed"}
        unknown = sorted(set(config) - fields - {"arch", "period"})
        if unknown:
            raise ValueError(f"unknown network config field(s): {', '.join(map(str, unknown))}")
        kwargs = {k: config[k] for k in fields if k in config}
        return UniversalReconNet(**kwargs, statistics=statistics)
    extra = {"radius"} if arch == PhysicsReconNet.arch else set()
    unknown = sorted(set(config) - {"arch", "period", "features", "blocks"} - extra)
    if unknown:
        raise ValueError(f"unknown network config field(s): {', '.join(map(str, unknown))}")
    if "period" not in config:
        raise ValueError("network config needs a 'period' [Ph, Pw]")
    kwargs: dict[str, Any] = {k: config[k] for k in extra if k in config}
    if arch == PhysicsReconNet.arch:
        kwargs["statistics"] = statistics
    return ARCHITECTURES[arch](
        period=config["period"],
        features=config.get("features", 64),
        blocks=config.get("blocks", 10),
        **kwargs,
    )
