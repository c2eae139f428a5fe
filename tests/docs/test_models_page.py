"""docs/models.md is what docs/models.py writes from the shipped files (so a model that ships
without the page being regenerated fails here). That each model's header is a recipe whose
stages agree with their configuration files is tests/training/test_recipe.py's."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _page_module():
    spec = importlib.util.spec_from_file_location("models_page", ROOT / "docs" / "models.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_models_page_is_current():
    written = (ROOT / "docs" / "models.md").read_text(encoding="utf-8")
    assert written == _page_module().render(), "run python docs/models.py"
