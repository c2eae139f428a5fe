"""Splitter patterns: the :class:`Pattern` type, the built-in library, pattern files, measures.

>>> from splitcam import patterns
>>> patterns.get("d").name
'D'
"""

from __future__ import annotations

from pathlib import Path

from .core import COLOURS, Pattern, PatternError, kernel_offsets
from .files import load, save
from .library import BUILTIN_FACTORIES, parse_router, router
from .measures import PatternMeasures, measure, pixel_response

__all__ = [
    "COLOURS",
    "Pattern",
    "PatternError",
    "PatternMeasures",
    "get",
    "kernel_offsets",
    "load",
    "measure",
    "names",
    "pixel_response",
    "router",
    "save",
]


def names() -> list[str]:
    """Names of the built-in patterns, in library order."""
    return list(BUILTIN_FACTORIES)


def get(name: str | Path | Pattern) -> Pattern:
    """A built-in pattern by name (case-insensitive), or a pattern loaded from a file path.

    >>> from splitcam import patterns
    >>> d = patterns.get("d")
    >>> d.name, d.period, d.kernel_size
    ('D', (2, 2), (1, 3))
    >>> d.layout.tolist()  # the splitter at each pixel of the 2x2 unit cell
    [[0, 1], [2, 3]]
    >>> patterns.get("router(eta=0.5;chi=0)").name  # a router with losses, by its parameters
    'router(eta=0.5,0.5,0.5;chi=0,0,0)'

    Raises:
        PatternError: Unknown name; the message lists the valid names.
    """
    if isinstance(name, Pattern):
        return name
    key = str(name)
    for builtin, factory in BUILTIN_FACTORIES.items():
        if builtin.lower() == key.strip().lower():
            return factory()
    modelled = parse_router(key)
    if modelled is not None:
        return modelled
    path = Path(key)
    if path.suffix.lower() in (".json", ".toml") or path.exists():
        return load(path)
    raise PatternError(
        f"unknown pattern {key!r}; valid names: {', '.join(names())} "
        f"(or the path of a .json/.toml pattern file, or router(eta=R,G,B;chi=R,G,B))"
    )
