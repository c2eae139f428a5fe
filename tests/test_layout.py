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


def test_no_function_body_is_longer_than_80_lines():
    """A function longer than a screenful does several things: name them. Lines of code are
    counted, from the first statement after the docstring to the last: a long docstring is
    documentation, not complexity (ruff's statement count misses long expressions and
    argument tables, which this sees)."""
    long = []
    for path in _code_files():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            body = node.body
            if ast.get_docstring(node) is not None:
                body = body[1:]
            if body and body[-1].end_lineno - body[0].lineno + 1 > 80:
                long.append(f"{path.relative_to(PACKAGE)}:{node.name}")
    assert not long, f"functions over 80 lines: {long}"


#: Where a pattern's name or file may become a Pattern below the CLI: the constructors users
#: call, the method registry, training's reading of its configuration, and results read back
#: from disk. Everything else takes a Pattern (``patterns.check_pattern`` says how to make one).
PATTERN_READERS = {
    "physics/sensor.py": {"SplitterSensor.__init__"},
    "recon/closed_form.py": {"ClosedFormFilters.__init__"},
    "recon/lmmse.py": {"LMMSE.fit"},
    "recon/peers.py": {"Demosaicnet.__init__"},
    "recon/registry.py": {"_given"},
    "training/setup.py": {"config_patterns"},
    "evaluation/report.py": {"_load"},
}

#: Besides the readers, what may take a pattern's name: the registry's entry points and their
#: helpers (names are labels in tables there), and constructors that hand it to a reader.
NAME_TAKERS = {
    "recon/registry.py": {
        "build_model",
        "build_method",
        "build_methods",
        "_given",
        "_pattern_key",
    },
    "integrations/deepinv.py": {"SplitterPhysics.__init__"},
}


def _pattern_reads(path: Path) -> list[str]:
    """``Class.function`` of every call of ``splitcam.patterns.get`` or ``.read`` in a module
    (under any name it is imported as, or as ``patterns.get``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    aliases = {
        a.asname or a.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("patterns")
        for a in node.names
        if a.name in ("get", "read")
    }
    found = []

    def visit(node: ast.AST, scope: list[str]) -> None:
        for child in ast.iter_child_nodes(node):
            inner = scope
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                inner = [*scope, child.name]
            if isinstance(child, ast.Call):
                f = child.func
                by_module = (
                    isinstance(f, ast.Attribute)
                    and f.attr in ("get", "read")
                    and isinstance(f.value, ast.Name)
                    and f.value.id == "patterns"
                )
                if by_module or (isinstance(f, ast.Name) and f.id in aliases):
                    found.append(".".join(scope) or "<module>")
            visit(child, inner)

    visit(tree, [])
    return found


def test_pattern_names_are_read_once_in_known_places():
    """Below the CLI, ``patterns.get`` is called only where :data:`PATTERN_READERS` allows."""
    wrong, calls = [], 0
    for path in _code_files():
        rel = str(path.relative_to(PACKAGE))
        if rel.startswith("cli/") or rel == "patterns/__init__.py":
            continue
        for where in _pattern_reads(path):
            calls += 1
            if where not in PATTERN_READERS.get(rel, set()):
                wrong.append(f"{rel}:{where}")
    assert not wrong, f"patterns.get outside the allowed readers: {wrong}"
    assert calls <= 10, f"{calls} calls of patterns.get below the CLI"


def test_the_pattern_reader_check_sees_every_spelling(tmp_path):
    """The check itself can fail: each way of calling ``patterns.get`` is found, in its scope."""
    module = tmp_path / "m.py"
    module.write_text(
        "from splitcam import patterns\nfrom splitcam.patterns import get as read\n\n"
        "class S:\n    def __init__(self, p):\n        self.p = patterns.get(p)\n\n"
        "def f(p):\n    return read(p)\n\nx = read('D')\ny = patterns.read('D')\n"
    )
    assert _pattern_reads(module) == ["S.__init__", "f", "<module>", "<module>"]


def _union(annotation: ast.expr | None) -> set[str]:
    """The members of an ``A | B`` annotation, also inside one subscript (``Sequence[...]``)."""
    if annotation is None:
        return set()
    if isinstance(annotation, ast.BinOp) and isinstance(annotation.op, ast.BitOr):
        return _union(annotation.left) | _union(annotation.right)
    if isinstance(annotation, ast.Subscript) and ast.unparse(annotation.value) in (
        "Sequence",
        "list",
        "tuple",
    ):
        return _union(annotation.slice)
    return {ast.unparse(annotation).removeprefix("patterns.")}


def test_only_constructors_and_the_registry_take_pattern_names():
    """A parameter typed ``Pattern | str`` belongs to a reader of :data:`PATTERN_READERS`, the
    registry or a constructor that hands it to one (:data:`NAME_TAKERS`); every other function
    takes a Pattern."""
    wrong = []
    for path in _code_files():
        rel = str(path.relative_to(PACKAGE))
        if rel.startswith("cli/") or rel == "patterns/__init__.py":
            continue
        allowed = PATTERN_READERS.get(rel, set()) | NAME_TAKERS.get(rel, set())
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for cls in [n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)] + [tree]:
            for node in getattr(cls, "body", []):
                if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                where = f"{cls.name}.{node.name}" if isinstance(cls, ast.ClassDef) else node.name
                if where in allowed or (node.name == "__init__" and _reads_through_super(cls)):
                    continue
                args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                for arg in args:
                    if {"Pattern", "str"} <= _union(arg.annotation):
                        wrong.append(f"{rel}:{where}({arg.arg})")
    assert not wrong, f"functions taking a pattern's name, not a Pattern: {wrong}"


def test_the_signature_check_sees_a_name_taker():
    tree = ast.parse("def f(a: Sequence[str | patterns.Pattern], b: dict[str, Pattern]): ...")
    a, b = tree.body[0].args.args
    assert {"Pattern", "str"} <= _union(a.annotation)
    assert not {"Pattern", "str"} <= _union(b.annotation)


def _reads_through_super(cls: ast.AST) -> bool:
    """A sensor class whose constructor hands its argument to SplitterSensor's."""
    return isinstance(cls, ast.ClassDef) and any(
        ast.unparse(b).endswith("SplitterSensor") for b in cls.bases
    )
