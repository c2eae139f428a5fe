"""Weights shipped with splitcam (safetensors + JSON; never pickles). Data only, no code:

- ``lmmse/<pattern>.safetensors`` + ``.json``: LMMSE statistics of each built-in pattern, fitted
  on the 432 BSDS500 training images (CBSD432) with :func:`splitcam.recon.lmmse.fit_lmmse`'s
  defaults; loaded by :func:`splitcam.recon.lmmse.shipped_lmmse`; regenerate with
  ``python scripts/fit_shipped_lmmse.py``.
"""

from pathlib import Path

HERE = Path(__file__).resolve().parent
