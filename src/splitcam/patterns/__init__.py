"""Splitter patterns: the :class:`Pattern` type, the built-in library, pattern files, measures.

>>> from splitcam import patterns
>>> patterns.get("d").name
'D'
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .core import COLOURS, Pattern, PatternError, check_pattern, kernel_offsets
from .files import load, save
from .library import BUILTIN_FACTORIES, parse_router, router
from .measures import PatternMeasures, measure, pixel_response

__all__ = [
    "COLOURS",
    "NAMES",
    "Given",
    "PARSERS",
    "Pattern",
    "PatternError",
    "PatternMeasures",
    "builtin",
    "check_pattern",
    "get",
    "kernel_offsets",
    "load",
    "measure",
    "names",
    "pixel_response",
    "read",
    "router",
    "save",
]


#: The built-in patterns by lower-case name (:func:`names` gives their own spelling).
NAMES = {name.lower(): factory for name, factory in BUILTIN_FACTORIES.items()}


def _file(text: str) -> Pattern | None:
    path = Path(text)
    return load(path) if path.suffix.lower() in (".json", ".toml") or path.exists() else None


#: How :func:`get` reads text that is not a built-in name, tried in order: each parser returns
#: a :class:`Pattern`, or None for text not of its kind (and raises for text of its kind that
#: it cannot read). The keys are the syntax, shown when nothing reads the text.
PARSERS = {
    "router(eta=R,G,B;chi=R,G,B)": parse_router,
    "the path of a .json/.toml pattern file": _file,
}


def names() -> list[str]:
    """Names of the built-in patterns, in library order."""
    return list(BUILTIN_FACTORIES)


def builtin(name: str) -> Pattern:
    """The built-in pattern ``name`` (case-insensitive), for code that names a fixed one.

    Raises:
        PatternError: Not a built-in name.
    """
    factory = NAMES.get(name.strip().lower())
    if factory is None:
        raise PatternError(f"unknown pattern {name!r}; valid names: {', '.join(names())}")
    return factory()


def get(name: str | Path | Pattern) -> Pattern:
    """A built-in pattern by name (case-insensitive), or a pattern read by one of the
    :data:`PARSERS` (a router by its parameters, a pattern file); a :class:`Pattern` as it is.

    The one place a pattern's name or file becomes a :class:`Pattern`: the library's functions
    take patterns (:func:`check_pattern`), so a name is read once, where a user hands it over.

    >>> from splitcam import patterns
    >>> d = patterns.get("d")
    >>> d.name, d.period, d.kernel_size
    ('D', (2, 2), (1, 3))
    >>> d.layout.tolist()  # the splitter at each pixel of the 2x2 unit cell
    [[0, 1], [2, 3]]
    >>> patterns.get("router(eta=0.5;chi=0)").name  # a router with losses, by its parameters
    'router(eta=0.5,0.5,0.5;chi=0,0,0)'

    Raises:
        PatternError: Unknown name; the message lists the valid names and the other syntaxes.
    """
    if isinstance(name, Pattern):
        return name
    key = str(name)
    factory = NAMES.get(key.strip().lower())
    if factory is not None:
        return factory()
    for parser in PARSERS.values():
        found = parser(key)
        if found is not None:
            return found
    raise PatternError(
        f"unknown pattern {key!r}; valid names: {', '.join(names())} (or {' or '.join(PARSERS)})"
    )


@dataclass(frozen=True)
class Given:
    """A pattern as a user named it: the pattern, its label in tables, and the name or path as
    typed (what messages repeat back)."""

    pattern: Pattern
    label: str
    typed: str = ""

    def __str__(self) -> str:
        return self.typed or self.label


def read(spec: str | Path | Pattern | Given) -> Given:
    """:func:`get`, keeping the label a table gives the pattern: its own name (``D``, or
    ``zou`` for a file whose pattern is called so), except for a file whose pattern is named
    like a built-in one: then the file's name, so a table never passes an edited copy off as
    the built-in. A :class:`Given` is returned as it is, so a name read once travels read.

    >>> from splitcam import patterns
    >>> patterns.read("d").label
    'D'
    """
    if isinstance(spec, Given):
        return spec
    pattern = get(spec)
    builtins = set(NAMES)
    from_file = isinstance(spec, (str, Path)) and str(spec).strip().lower() not in builtins
    label = Path(spec).name if from_file and pattern.name.lower() in builtins else pattern.name
    return Given(pattern, label, str(spec) if isinstance(spec, (str, Path)) else "")
