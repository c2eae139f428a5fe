"""splitcam.integrations: optional, and outside the library's import graph.

These run with or without deepinv installed.
"""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path

import pytest

import splitcam

PACKAGE = Path(splitcam.__file__).parent


def test_the_package_imports_without_any_integration_dependency(monkeypatch):
    monkeypatch.setitem(sys.modules, "deepinv", None)  # as if deepinv were not installed
    monkeypatch.delitem(sys.modules, "splitcam.integrations", raising=False)
    importlib.import_module("splitcam.integrations")


def test_without_deepinv_the_import_error_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "deepinv", None)
    monkeypatch.delitem(sys.modules, "splitcam.integrations.deepinv", raising=False)
    with pytest.raises(ImportError, match=r"pip install 'splitcam\[deepinv\]'"):
        importlib.import_module("splitcam.integrations.deepinv")


def _imported_modules(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the file's package
                parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
                base = list(parts[: len(parts) - node.level])
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            names |= {module} | {f"{module}.{a.name}" for a in node.names}
    return names


def test_nothing_in_the_library_imports_the_integrations():
    """Integrations sit on top: the library works the same whether they are installed or not."""
    wrong = [
        str(path.relative_to(PACKAGE))
        for path in sorted(PACKAGE.rglob("*.py"))
        if "integrations" not in path.relative_to(PACKAGE).parts
        and any(m.startswith("splitcam.integrations") for m in _imported_modules(path))
    ]
    assert not wrong, f"modules that import splitcam.integrations: {wrong}"
