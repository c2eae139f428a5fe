"""splitcam: design and evaluate colour image sensors built on metasurface colour splitters.

The package is layered; each part imports only the parts above it in this list (checked by
``tests/test_layout.py``):

1. :mod:`splitcam.checks` — the argument checks every part uses (counts, periods, image tensors).
2. :mod:`splitcam.io` — atomic file writes, the tensor-file and checkpoint formats, where the
   shipped weights lie, the light-domain names.
3. :mod:`splitcam.patterns` — the :class:`~splitcam.patterns.Pattern` type, the library (A–E,
   filter arrays, routers), pattern files, random patterns, design-principle measures.
4. :mod:`splitcam.physics` — image formation (Eq. 1, Eq. 2, adjoint; learnable kernels), noise
   (Gaussian and photon) and the noise-level labels, linear light, scalar metasurface optics,
   :func:`~splitcam.physics.simulate` (the one simulation of a test scene).
5. :mod:`splitcam.data` — image and raw files, training patches, test sets and their download.
6. :mod:`splitcam.recon` — the one reconstruction interface
   (:class:`~splitcam.recon.Reconstructor`: ``name``, ``pattern``, ``reconstruct(raw, sigma)``),
   the networks, LMMSE, classical demosaicking, tiled inference, loading trained networks and
   the registry that turns a name into a method (:func:`~splitcam.recon.build_method`).
7. :mod:`splitcam.design` — pattern and metasurface design (one optimisation loop).
8. :mod:`splitcam.viz` — every figure (matplotlib ``Figure`` objects; no backend switching).
9. :mod:`splitcam.evaluation` — metrics, the evaluation protocol (also used by training
   validation), result tables, LMMSE screening, the exposure study, reports beside the paper.
10. :mod:`splitcam.integrations` — splitcam in other libraries (deepinv), optional extras;
    nothing in the package imports it.
11. :mod:`splitcam.training` — typed configuration, the training loop and its run folders,
    exporting models with their provenance, sweeps.
12. :mod:`splitcam.cli` — the ``splitcam`` command: one module per command; parsing imports no
    torch.

:mod:`splitcam.weights` holds shipped data (networks, LMMSE fits, image statistics), no code.
"""

__version__ = "0.1.0"
