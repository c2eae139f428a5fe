"""The package layout is the architecture: each part imports only the parts before it.

Every import in every module, including imports inside functions, is checked: a lazy import
that points the wrong way would hide a dependency cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import splitcam

LAYERS = [
    "checks",
    "io",
    "patterns",
    "physics",
    "data",
    "recon",
    "design",
    "viz",
    "evaluation",
    "integrations",
    "training",
    "cli",
]
PACKAGE = Path(splitcam.__file__).parent


def _part(module: str) -> str | None:
    """The layer of a dotted module name inside splitcam (None for the package root)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "splitcam" else None


def _imports(path: Path, root: Path = PACKAGE) -> list[tuple[int, str]]:
    """``(line, absolute module)`` of every splitcam import in a file."""
    module = "splitcam." + ".".join(path.relative_to(root).with_suffix("").parts)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [f"{target}.{a.name}" for a in node.names] if not node.module else [target]
            found += [(node.lineno, n) for n in names]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
    return [(line, name) for line, name in found if name.startswith("splitcam")]


def test_dependencies_point_one_way():
    wrong = []
    for path in sorted(PACKAGE.rglob("*.py")):
        own = _part("splitcam." + ".".join(path.relative_to(PACKAGE).with_suffix("").parts))
        if own not in LAYERS:  # the package root, __main__, weights (data only)
            continue
        for line, target in _imports(path):
            other = _part(target)
            if other in LAYERS and LAYERS.index(other) > LAYERS.index(own):
                wrong.append(f"{path.relative_to(PACKAGE)}:{line} imports {target}")
    assert not wrong, "imports against the layering:\n" + "\n".join(wrong)


def test_every_module_belongs_to_a_layer():
    tops = {
        p.name.removesuffix(".py")
        for p in PACKAGE.iterdir()
        if (p.suffix == ".py" or (p / "__init__.py").is_file()) and p.name != "__pycache__"
    }
    assert tops - {"__init__", "__main__", "weights"} == set(LAYERS)


def test_the_checker_sees_a_wrong_way_import(tmp_path):
    """The check itself can fail: a function-level import of a later layer is reported."""
    fake = tmp_path / "splitcam"
    (fake / "physics").mkdir(parents=True)
    (fake / "physics" / "bad.py").write_text(
        "import splitcam.patterns\n\ndef f():\n    from ..training import train\n"
        "    from .. import methods\n"
    )
    found = _imports(fake / "physics" / "bad.py", root=fake)
    assert found == [(1, "splitcam.patterns"), (4, "splitcam.training"), (5, "splitcam.methods")]


def _code_files() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def test_noise_is_asked_through_its_interface():
    """No ``isinstance(..., Exposure)`` outside the noise module: the rest asks a NoiseModel."""
    wrong = []
    for path in _code_files():
        if path == PACKAGE / "physics" / "noise.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and getattr(node.func, "id", None) == "isinstance"
                and "Exposure" in ast.unparse(node.args[1])
            ):
                wrong.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    assert not wrong, f"isinstance on Exposure outside physics/noise.py: {wrong}"


def test_markdown_tables_have_one_writer():
    """Every Markdown table rule is made by evaluation.tables (markdown_table / markdown_rule)."""
    home = PACKAGE / "evaluation" / "tables.py"
    wrong = [
        str(path.relative_to(PACKAGE))
        for path in _code_files()
        if path != home
        and any(rule in path.read_text(encoding="utf-8") for rule in ("---|", '"-" *', "'-' *"))
    ]
    assert not wrong, f"Markdown table rules written outside evaluation/tables.py: {wrong}"


def test_no_function_body_is_longer_than_100_lines():
    """A function longer than a screenful does several things: name them (docstrings aside)."""
    long = []
    for path in _code_files():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            body = node.body
            if ast.get_docstring(node) is not None:
                body = body[1:]
            if body and body[-1].end_lineno - body[0].lineno + 1 > 100:
                long.append(f"{path.relative_to(PACKAGE)}:{node.name}")
    assert not long, f"functions over 100 lines: {long}"
