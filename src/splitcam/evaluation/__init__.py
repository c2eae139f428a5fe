"""Evaluation: metrics (:mod:`.metrics`), the protocol every score goes through
(:mod:`.protocol`), result tables (:mod:`.tables`), LMMSE screening of patterns
(:mod:`.screening`) and reports beside the paper's numbers (:mod:`.report`)."""

from .metrics import ciede2000, compute_all, psnr, ssim
from .protocol import evaluate, mean_psnr, score, simulate_and_reconstruct
from .tables import EvalRow, markdown_tables, summarise

__all__ = [
    "EvalRow",
    "ciede2000",
    "compute_all",
    "evaluate",
    "markdown_tables",
    "mean_psnr",
    "psnr",
    "score",
    "simulate_and_reconstruct",
    "ssim",
    "summarise",
]
