"""Temporary: pattern design moved to :mod:`splitcam.design`."""

from ..design.kernels import *  # noqa: F403
from ..design.kernels import DesignResult, closed_form_psnr, design_pattern, network_psnr  # noqa: F401
from ..design.metasurface import MetasurfaceDesign, design_metasurface  # noqa: F401
