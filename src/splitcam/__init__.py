"""splitcam: design and evaluate colour image sensors built on metasurface colour splitters.

The package is layered; each part imports only the parts above it in this list (checked by
``tests/test_layout.py``):

1. :mod:`splitcam.patterns` — the :class:`~splitcam.patterns.Pattern` type, the library A–E +
   bayer, pattern files, design-principle measures.
2. :mod:`splitcam.physics` — image formation (Eq. 1, Eq. 2, adjoint; learnable kernels), noise,
   the imaging system, :func:`~splitcam.physics.simulate` (the one simulation of a test scene),
   and the period helpers (phase map, period (un)shuffle, per-phase convolution).
3. :mod:`splitcam.data` — image and raw files, training patches, test sets and their download.
4. :mod:`splitcam.recon` — the one reconstruction interface
   (:class:`~splitcam.recon.Reconstructor`: ``name``, ``pattern``, ``reconstruct(raw, sigma)``),
   the networks, LMMSE, classical demosaicking, tiled inference.
5. :mod:`splitcam.viz` — every figure (matplotlib ``Figure`` objects; no backend switching).
6. :mod:`splitcam.evaluation` — metrics, the evaluation protocol (also used by training
   validation), result tables, LMMSE screening, reports beside the paper's numbers.
7. :mod:`splitcam.training` — typed configuration, safetensors checkpoints (and loading a trained
   system), the training loop.
8. :mod:`splitcam.recon.registry` — the registry that turns a name (``lmmse``, ``malvar2004``, a run
   folder, ...) into a reconstruction method, for the CLI and Python alike.
9. :mod:`splitcam.cli` — the ``splitcam`` command: parses arguments, calls the library.

:mod:`splitcam.weights` holds shipped data (LMMSE fits), no code.
"""

__version__ = "0.1.0"
