"""Names a package imports on first use: the one mechanism behind the packages whose
``__init__`` must stay light (``splitcam.data``, ``splitcam.design``, ``splitcam.training``), so
that the CLI's parsers and ``splitcam.data.registry`` import no torch.

>>> getattr_, dir_ = lazy_exports("json", {"JSONDecoder": "decoder"}, ["encoder"])
>>> getattr_("JSONDecoder").__name__, getattr_("encoder").__name__
('JSONDecoder', 'json.encoder')
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, exports: dict[str, str], submodules: Iterable[str] = ()
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` (PEP 562) of ``package``: each name of
    ``exports`` is imported from its submodule (``exports[name]``, relative to the package) on
    first use and then kept in the package's namespace; ``submodules`` are imported the same way
    by name.

    Usage, in a package's ``__init__``::

        __getattr__, __dir__ = lazy_exports(__name__, {"train": "trainer"})
    """
    modules = tuple(submodules)

    def __getattr__(name: str) -> Any:
        if name in exports:
            value = getattr(importlib.import_module(f".{exports[name]}", package), name)
        elif name in modules:
            value = importlib.import_module(f".{name}", package)
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        namespace = vars(sys.modules[package]) if package in sys.modules else {}
        return sorted({*namespace, *exports, *modules})

    return __getattr__, __dir__
