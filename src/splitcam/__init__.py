"""splitcam: design and evaluate colour image sensors built on metasurface colour splitters.

Layout of the package:

- :mod:`splitcam.patterns` — the pattern type, the library A–E + bayer, pattern files, measures.
- :mod:`splitcam.physics.sensor` — the differentiable image-formation model (Eq. 1, Eq. 2, adjoint).
- :mod:`splitcam.physics.noise` — seeded training noise and deterministic evaluation noise.
- :mod:`splitcam.data.imageio` / :mod:`splitcam.data.patches` — reading images and training patches.
- :mod:`splitcam.recon.networks` — the reconstruction network.
- :mod:`splitcam.evaluation.metrics` — PSNR, SSIM, CIEDE2000.
- :mod:`splitcam.cli` — the ``splitcam`` command (parses arguments, calls the library).
"""

__version__ = "0.1.0"
