"""splitcam inside other libraries, each behind an optional dependency.

- :mod:`splitcam.integrations.deepinv` — the splitter sensor as a ``deepinv`` physics operator
  (:class:`~splitcam.integrations.deepinv.SplitterPhysics`), splitcam's Gaussian and photon noise
  as ``deepinv`` noise models, and any ``deepinv`` reconstruction as a splitcam
  :class:`~splitcam.recon.Reconstructor`. Needs ``pip install 'splitcam[deepinv]'``; importing
  it without deepinv raises an ImportError that says so.

This package imports none of them itself, so ``import splitcam.integrations`` always works. The
integrations use the physics, reconstruction and evaluation layers; nothing in splitcam imports
them (only tests and examples do).
"""

__all__: list[str] = []
