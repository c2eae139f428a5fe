"""Colour the training photos never show: chroma augmentation and colour dead-leaves scenes.

A reconstruction network (and the LMMSE fitted on the same photos) learns the colour statistics
of its training photos. The BSDS500 photos are muted, and their channels strongly correlated;
on saturated scenes with sharp colour edges (the McMaster set) that prior breaks, by 4-6 dB
between Kodak24 and McMaster for every shipped network. Two ways to show the network colour
without new photos, applied to a batch of patches after it is cut:

- **Chroma augmentation** (:func:`augment_chroma`): a patch's channels permuted, then its chroma
  rotated by a random hue angle and scaled by a random factor in an opponent space (luma and
  two colour differences, the BT.601 YCbCr matrix), clipped to [0, 1]: a larger factor pushes
  colours to the gamut's edge. Luma, and so the texture, is kept; the colour of each pixel
  moves away from grey and away from the photos' typical hues.
- **Colour dead leaves** (:func:`dead_leaves`): the standard synthetic model of natural image
  statistics (occluding discs with radii drawn from ``p(r) ~ r^-3``, scale-invariant like
  photographs), each disc of a colour drawn uniformly from the RGB cube, so colours are free
  and independent of texture; disc edges are antialiased.

:class:`ColourMix` applies both to a batch with the random choices drawn on the patch sampler's
own CPU generator, a fixed number of draws per batch: the same seed gives the same batches on
any device, and a resumed run continues the sequence (the sampler's state is checkpointed).
``space="linear"`` moves chroma in linear light (for networks trained on photons in linear
radiance): the patch is decoded to linear values, augmented there, and encoded back, so the
sampler still hands out display values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ..physics.light import linear_to_srgb, srgb_to_linear

__all__ = [
    "ColourMix",
    "augment_chroma",
    "chroma_detail",
    "chroma_moved_copies",
    "colourfulness",
    "dead_leaves",
    "opponent_to_rgb",
    "rgb_to_opponent",
    "swap_chroma",
]

# BT.601 luma weights: Y = 0.299 R + 0.587 G + 0.114 B, Cb = (B - Y) / 1.772, Cr = (R - Y) / 1.402.
_LUMA = (0.299, 0.587, 0.114)
_CB, _CR = 1.772, 1.402
#: The six orders of three channels, indexed by a draw in 0..5 (0: unchanged).
PERMUTATIONS = ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))
#: Smallest disc radius in pixels; the largest is half the patch side.
MIN_RADIUS = 1.5
#: Discs painted per dead-leaves patch: enough for their areas to sum to this many times the
#: patch's, so that about exp(-3) = 5 % of the background is left uncovered.
COVERAGE = 3.0


def rgb_to_opponent(rgb: torch.Tensor) -> torch.Tensor:
    """Luma and the two colour differences (Y, Cb, Cr) of ``(..., 3, H, W)`` RGB values."""
    r, g, b = rgb.unbind(-3)
    y = _LUMA[0] * r + _LUMA[1] * g + _LUMA[2] * b
    return torch.stack([y, (b - y) / _CB, (r - y) / _CR], dim=-3)


def opponent_to_rgb(ycc: torch.Tensor) -> torch.Tensor:
    """The inverse of :func:`rgb_to_opponent`."""
    y, cb, cr = ycc.unbind(-3)
    r = y + _CR * cr
    b = y + _CB * cb
    g = (y - _LUMA[0] * r - _LUMA[2] * b) / _LUMA[1]
    return torch.stack([r, g, b], dim=-3)


def colourfulness(rgb: torch.Tensor) -> float:
    """Hasler and Suesstrunk's colourfulness of an image (2003), the published measure that
    correlates best with how colourful people rate a photo.

    With ``rg = R - G`` and ``yb = (R + G) / 2 - B`` over the pixels, in 8-bit units:
    ``M = sqrt(std(rg)^2 + std(yb)^2) + 0.3 sqrt(mean(rg)^2 + mean(yb)^2)``. About 15 is
    "slightly colourful", 33 "moderately", 45 "averagely", 59 "quite", 82 "highly", above 109
    "extremely" colourful (the paper's scale).

    Args:
        rgb: ``(3, H, W)`` display values in [0, 1].
    """
    r, g, b = (255.0 * rgb.double()).unbind(0)
    rg, yb = r - g, 0.5 * (r + g) - b
    spread = math.hypot(float(rg.std(unbiased=False)), float(yb.std(unbiased=False)))
    return spread + 0.3 * math.hypot(float(rg.mean()), float(yb.mean()))


def chroma_detail(rgb: torch.Tensor) -> float:
    """How much of an image's finest detail is colour: the energy of the chroma's detail at the
    scale of two pixels over the luma's.

    Each plane's detail is what is left of it after its mean over each 2x2 block (a trailing odd
    row or column left out), in the opponent space of :func:`rgb_to_opponent`; the ratio is
    ``(E[dCb^2] + E[dCr^2]) / E[dY^2]``. A JPEG that stores its chroma at half resolution (4:2:0,
    as every BSD photo is) has almost none: the decoder's interpolation is all that is left.
    Grey images give 0; a flat image (no luma detail) gives ``inf`` unless it is flat in colour
    too (then 0).

    Args:
        rgb: ``(3, H, W)`` values in [0, 1], both sides at least 2.
    """
    height, width = (side - side % 2 for side in rgb.shape[-2:])
    if height == 0 or width == 0:
        raise ValueError(f"chroma_detail needs an image of at least 2x2, got {tuple(rgb.shape)}")
    planes = rgb_to_opponent(rgb.double()[:, :height, :width])
    blocks = planes.reshape(3, height // 2, 2, width // 2, 2)
    energy = (blocks - blocks.mean(dim=(2, 4), keepdim=True)).square().mean(dim=(1, 2, 3, 4))
    colour = float(energy[1] + energy[2])
    return colour / float(energy[0]) if energy[0] > 0 else (math.inf if colour > 0 else 0.0)


def augment_chroma(
    rgb: torch.Tensor, angle: torch.Tensor, scale: torch.Tensor, order: torch.Tensor
) -> torch.Tensor:
    """Patches with their channels reordered, then their chroma rotated and scaled.

    Args:
        rgb: ``(B, 3, H, W)`` values in [0, 1].
        angle: ``(B,)`` hue rotation in radians.
        scale: ``(B,)`` chroma factor (1: unchanged saturation).
        order: ``(B,)`` index into :data:`PERMUTATIONS`.

    Returns:
        ``(B, 3, H, W)`` in [0, 1] (clipped): luma kept, ``(Cb, Cr)`` of every pixel rotated by
        ``angle`` and multiplied by ``scale``. Angle 0, scale 1 and order 0 return ``rgb``
        (up to rounding).
    """
    perms = torch.tensor(PERMUTATIONS, device=rgb.device)[order.to(rgb.device)]
    index = perms.view(-1, 3, 1, 1).expand_as(rgb)
    ycc = rgb_to_opponent(torch.gather(rgb, 1, index))
    angle, scale = angle.to(rgb), scale.to(rgb)
    cos, sin = (scale * angle.cos()).view(-1, 1, 1), (scale * angle.sin()).view(-1, 1, 1)
    cb, cr = ycc[:, 1], ycc[:, 2]
    turned = torch.stack([ycc[:, 0], cos * cb - sin * cr, sin * cb + cos * cr], dim=1)
    return opponent_to_rgb(turned).clamp(0.0, 1.0)


def swap_chroma(rgb: torch.Tensor, hit: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """Patches ``hit`` keep their luma and take the chroma of the next patch of the batch
    (the last takes the first's), multiplied by ``scale``; clipped to [0, 1].

    Shape:
        rgb: ``(B, 3, H, W)``; hit: ``(B,)`` bool; scale: ``(B,)``; output: like ``rgb``.
    """
    ycc = rgb_to_opponent(rgb)
    donor = ycc.roll(-1, dims=0)[:, 1:] * scale.to(rgb).view(-1, 1, 1, 1)
    moved = opponent_to_rgb(torch.cat([ycc[:, :1], donor], dim=1)).clamp(0.0, 1.0)
    return torch.where(hit.view(-1, 1, 1, 1), moved, rgb)


def dead_leaves(
    colours: torch.Tensor, centres: torch.Tensor, radii: torch.Tensor, size: tuple[int, int]
) -> torch.Tensor:
    """Colour dead-leaves images: discs painted back to front over the first one's colour.

    Args:
        colours: ``(B, K, 3)`` disc colours in [0, 1]; disc 0 is the background.
        centres: ``(B, K, 2)`` centres (row, column) in pixels.
        radii: ``(B, K)`` radii in pixels.
        size: ``(H, W)`` of the images.

    Returns:
        ``(B, 3, H, W)``: each pixel the colour of the last disc covering it, blended with the
        one beneath over the disc's antialiased edge (coverage ``clamp(r - d + 0.5, 0, 1)`` at
        distance ``d`` from the centre).
    """
    b, k, _ = colours.shape
    dev = colours.device
    rows = torch.arange(size[0], device=dev, dtype=colours.dtype).view(1, -1, 1)
    cols = torch.arange(size[1], device=dev, dtype=colours.dtype).view(1, 1, -1)
    image = colours[:, 0].view(b, 3, 1, 1).expand(b, 3, *size).clone()
    for i in range(1, k):
        cy, cx = centres[:, i, 0].view(b, 1, 1), centres[:, i, 1].view(b, 1, 1)
        distance = ((rows - cy).square() + (cols - cx).square()).sqrt()
        cover = (radii[:, i].view(b, 1, 1) - distance + 0.5).clamp(0.0, 1.0).unsqueeze(1)
        image = image + cover * (colours[:, i].view(b, 3, 1, 1) - image)
    return image


def disc_count(height: int, width: int) -> int:
    """Discs that cover a ``height`` x ``width`` patch :data:`COVERAGE` times on average, for
    radii drawn by :func:`power_law_radii` between :data:`MIN_RADIUS` and half the longer side
    (mean disc area ``2 pi a^2 ln(b / a) / (1 - (a / b)^2)`` for radii in ``[a, b]``)."""
    a, b = MIN_RADIUS, max(height, width, 4) / 2
    mean_area = 2 * math.pi * a * a * math.log(b / a) / (1 - (a / b) ** 2)
    return 1 + math.ceil(COVERAGE * height * width / mean_area)


def power_law_radii(unit: torch.Tensor, smallest: float, largest: float) -> torch.Tensor:
    """Radii with density ``~ r^-3`` on ``[smallest, largest]`` from uniform draws ``unit``
    (the inverse of the distribution function)."""
    lo, hi = smallest**-2, largest**-2
    return (lo - unit * (lo - hi)).rsqrt()


@dataclass(frozen=True)
class ColourMix:
    """Chroma augmentation and dead-leaves scenes mixed into batches of patches.

    Args:
        chroma: Probability that a patch is chroma-augmented (0: never).
        chroma_max: Chroma factors are uniform in ``[1, chroma_max]``.
        permute: Reorder the channels of an augmented patch at random (one of 6 orders).
        leaves: Probability that a patch is replaced by a dead-leaves scene (0: never; drawn
            after, and instead of, the chroma augmentation).
        space: ``srgb`` (move chroma in the display values) or ``linear`` (in linear light).
        swap: Probability that a patch keeps its luma and takes the chroma of the next patch of
            the batch, scaled by a factor in ``[1, chroma_max]`` (drawn after the chroma
            moves, before the dead leaves): colour edges where the luma has none, and luma
            edges with no colour edge, as saturated scenes have and muted photos rarely.
    """

    chroma: float = 0.0
    chroma_max: float = 2.2
    permute: bool = True
    leaves: float = 0.0
    space: str = "srgb"
    swap: float = 0.0

    def __post_init__(self) -> None:
        for name in ("chroma", "leaves", "swap"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {value}")
        if not self.chroma_max >= 1.0:
            raise ValueError(f"chroma_max must be >= 1, got {self.chroma_max}")
        if self.space not in ("srgb", "linear"):
            raise ValueError(f"space must be srgb or linear, got {self.space!r}")

    @property
    def active(self) -> bool:
        """Whether it changes anything (an inactive mix draws nothing)."""
        return self.chroma > 0 or self.leaves > 0 or self.swap > 0

    def __call__(self, batch: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """The batch with the mix applied; every draw on ``generator`` (CPU), a fixed number
        per batch of a given shape.

        Shape:
            batch: ``(B, 3, H, W)`` display values in [0, 1]; output: the same.
        """
        if not self.active:
            return batch
        b, _, h, w = batch.shape
        dev = batch.device
        # In linear light the whole batch is decoded once, moved, and encoded once; patches no
        # lever touched are handed back as they came, bit for bit.
        linear = self.space == "linear"
        values = srgb_to_linear(batch) if linear else batch
        touched = torch.zeros(b, dtype=torch.bool)
        if self.chroma > 0:
            hit = torch.rand(b, generator=generator) < self.chroma
            angle = torch.rand(b, generator=generator) * (2 * math.pi)
            scale = 1 + torch.rand(b, generator=generator) * (self.chroma_max - 1)
            order = torch.randint(len(PERMUTATIONS), (b,), generator=generator)
            if not self.permute:
                order = torch.zeros_like(order)
            if bool(hit.any()):
                pick = hit.nonzero().squeeze(1).to(dev)
                moved = augment_chroma(values[pick], angle[hit], scale[hit], order[hit])
                values = values.index_copy(0, pick, moved)
            touched |= hit
        if self.swap > 0:
            hit = torch.rand(b, generator=generator) < self.swap
            scale = 1 + torch.rand(b, generator=generator) * (self.chroma_max - 1)
            if bool(hit.any()) and b > 1:
                values = swap_chroma(values, hit.to(dev), scale.to(dev))
                touched |= hit
        if self.leaves > 0:
            hit = torch.rand(b, generator=generator) < self.leaves
            k = disc_count(h, w)
            colours = torch.rand((b, k, 3), generator=generator)
            centres = torch.rand((b, k, 2), generator=generator) * torch.tensor(
                [float(h), float(w)]
            )
            radii = power_law_radii(
                torch.rand((b, k), generator=generator), MIN_RADIUS, max(h, w, 4) / 2
            )
            if bool(hit.any()):
                pick = hit.nonzero().squeeze(1)
                scenes = dead_leaves(*(t[pick].to(dev) for t in (colours, centres, radii)), (h, w))
                values = values.index_copy(0, pick.to(dev), scenes.to(values.dtype))
            touched |= hit
        if not bool(touched.any()):
            return batch
        if linear:
            values = linear_to_srgb(values).clamp(0.0, 1.0)
        return torch.where(touched.to(dev).view(-1, 1, 1, 1), values, batch)


def chroma_moved_copies(
    images: list[torch.Tensor],
    generator: torch.Generator,
    *,
    chroma_max: float = 2.2,
    space: str = "srgb",
) -> list[torch.Tensor]:
    """A chroma-moved copy of each whole image, as :class:`ColourMix` moves a patch at
    probability 1 (channels reordered, hue turned, chroma scaled by 1 to ``chroma_max``),
    drawn in order on ``generator``: e.g. the photos whose statistics give an LMMSE a prior
    with colour the photos never show.

    Shape:
        each image: ``(3, H, W)`` display values in [0, 1]; each copy the same.
    """
    mix = ColourMix(chroma=1.0, chroma_max=chroma_max, space=space)
    return [mix(image[None], generator)[0] for image in images]
