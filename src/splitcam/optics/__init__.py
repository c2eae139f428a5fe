"""Moved: the metasurface optics model is :mod:`splitcam.physics.optics`."""

raise ImportError(
    "splitcam.optics moved to splitcam.physics.optics (metasurface design: splitcam.design)"
)
