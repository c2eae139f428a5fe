"""Reconstruction: the one interface (:class:`Reconstructor`: ``name``, ``pattern``,
``reconstruct(raw, sigma)``), the networks, the LMMSE filters, classical demosaicking, tiled
inference, loading trained networks (:mod:`.loading`) and the registry that turns a name into a
method (:mod:`.registry`: :func:`build_method`)."""

from ..checks import check_raw
from .base import NetworkReconstructor, Reconstructor
from .demosaic import ClassicalDemosaic
from .lmmse import LMMSE, LMMSEStatistics, fit_lmmse, shipped_lmmse
from .loading import LoadedNetwork, load_model, load_network, model_names
from .networks import PackedReconNet, ReconNet, build_network
from .registry import build_method, build_methods, build_model, method_names
from .tiling import reconstruct

__all__ = [
    "LMMSE",
    "ClassicalDemosaic",
    "LMMSEStatistics",
    "LoadedNetwork",
    "NetworkReconstructor",
    "PackedReconNet",
    "ReconNet",
    "Reconstructor",
    "build_method",
    "build_methods",
    "build_model",
    "build_network",
    "check_raw",
    "fit_lmmse",
    "load_model",
    "load_network",
    "method_names",
    "model_names",
    "reconstruct",
    "shipped_lmmse",
]
