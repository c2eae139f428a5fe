"""splitcam.integrations: optional, and outside the library's import graph.

These run with or without deepinv installed.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import re
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


def test_with_deepinv_beside_a_torchvision_for_another_torch_the_error_names_the_fix(monkeypatch):
    """deepinv installed, torchvision built for another torch: the one line of the check, before
    deepinv (which imports torchvision) is imported."""
    from importlib.machinery import ModuleSpec

    import splitcam.integrations._torchvision as check

    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: ModuleSpec(name, None) if name == "deepinv" else real_find_spec(name, *a),
    )
    line = "torchvision 9.9 cannot load its operators beside torch X; install: pip install Y"
    monkeypatch.setattr(check, "torchvision_mismatch", lambda: line)
    monkeypatch.setitem(sys.modules, "deepinv", None)  # importing it would be a bug here
    monkeypatch.delitem(sys.modules, "splitcam.integrations.deepinv", raising=False)
    with pytest.raises(ImportError, match=re.escape(line)):
        importlib.import_module("splitcam.integrations.deepinv")
