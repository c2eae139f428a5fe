"""Reconstruction: the one interface (:class:`Reconstructor`: ``name``, ``pattern``,
``reconstruct(raw, sigma)``), the networks, the LMMSE filters, classical demosaicking and tiled
inference."""

from ..checks import check_raw
from .base import NetworkReconstructor, Reconstructor
from .demosaic import ClassicalDemosaic
from .lmmse import LMMSE, LMMSEStatistics, fit_lmmse, shipped_lmmse
from .networks import PackedReconNet, ReconNet, build_network
from .tiling import reconstruct

__all__ = [
    "LMMSE",
    "ClassicalDemosaic",
    "LMMSEStatistics",
    "NetworkReconstructor",
    "PackedReconNet",
    "ReconNet",
    "Reconstructor",
    "build_network",
    "check_raw",
    "fit_lmmse",
    "reconstruct",
    "shipped_lmmse",
]
