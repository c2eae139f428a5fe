"""Moved: the registry of reconstruction methods is :mod:`splitcam.recon.registry`."""

raise ImportError(
    "splitcam.methods moved to splitcam.recon.registry (build_method, build_model, "
    "build_methods, method_names; also importable from splitcam.recon)"
)
