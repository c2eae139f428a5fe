"""Defaults of pattern design, importable without torch (the CLI builds its parser from them)."""

from __future__ import annotations

from ..io.paper import PAPER_SIGMAS

#: Noise levels (8-bit units) the design averages over by default: the paper's test levels.
DEFAULT_SIGMAS = PAPER_SIGMAS
#: Adam steps and learning rate (on the logits) of :func:`design_pattern` by default.
DEFAULT_STEPS = 300
DEFAULT_LR = 0.1
#: ``mse``: minimise the closed-form MSE averaged over the sigmas (the high-noise levels weigh
#: most, their errors are largest); ``psnr``: maximise the closed-form PSNR averaged over the
#: sigmas (every level weighs the same in dB); ``network``: maximise the PSNR of a frozen network
#: for any pattern (:class:`~splitcam.recon.networks.UniversalReconNet`) on training patches,
#: one sigma of the list per step in turn.
OBJECTIVES = ("mse", "psnr", "network")
