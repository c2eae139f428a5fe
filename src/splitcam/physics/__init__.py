"""The physics of a splitter sensor: image formation (Eq. 1, Eq. 2, adjoint), noise, the
imaging system, the light domains (display values or linear radiance), and the tensor helpers
for anything laid out on a pattern's period."""

from .light import (
    DOMAINS,
    check_domain,
    decode_scene,
    encode_estimate,
    linear_to_srgb,
    srgb_to_linear,
)
from .noise import GaussianNoise, add_evaluation_noise, check_sigma, evaluation_noise
from .periodic import period_shuffle, period_unshuffle, phase_conv, phase_map
from .sensor import (
    LearnableSplitterSensor,
    SplitterSensor,
    SwitchingSensor,
    pixel_gather,
    pixel_kernels,
    splitter_adjoint,
    splitter_forward,
)
from .system import ImagingSystem, simulate

__all__ = [
    "DOMAINS",
    "GaussianNoise",
    "ImagingSystem",
    "LearnableSplitterSensor",
    "SplitterSensor",
    "SwitchingSensor",
    "add_evaluation_noise",
    "check_domain",
    "check_sigma",
    "decode_scene",
    "encode_estimate",
    "evaluation_noise",
    "linear_to_srgb",
    "period_shuffle",
    "period_unshuffle",
    "phase_conv",
    "phase_map",
    "pixel_gather",
    "pixel_kernels",
    "simulate",
    "splitter_adjoint",
    "splitter_forward",
    "srgb_to_linear",
]
