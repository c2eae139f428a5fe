"""Weights shipped with splitcam (safetensors + JSON; never pickles). Data only, no code:

- ``models/<name>.safetensors`` + ``.json``: the shipped networks (``splitcam models``).
- ``lmmse/<pattern>.safetensors`` + ``.json``: LMMSE statistics of each built-in pattern, fitted
  on the 432 BSDS500 training images (CBSD432) with :func:`splitcam.recon.lmmse.fit_lmmse`'s
  defaults; loaded by :func:`splitcam.recon.lmmse.shipped_lmmse`; regenerate with
  ``python scripts/fit_shipped_lmmse.py``.
- ``image_statistics.*``: the pattern-free statistics of the closed-form LMMSE.

Their paths are computed in one place, :mod:`splitcam.io.weights`.
"""
