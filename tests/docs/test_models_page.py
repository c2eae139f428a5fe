"""docs/models.md is what docs/models.py writes from the shipped files (so a model that ships
without the page being regenerated fails here). That each model's header is a recipe whose
stages agree with their configuration files is tests/training/test_recipe.py's."""

from __future__ import annotations

from pathlib import Path

from conftest import load_script

ROOT = Path(__file__).resolve().parents[2]


def _page_module():
    return load_script(ROOT / "docs" / "models.py", "models_page")


def test_the_models_page_is_current():
    written = (ROOT / "docs" / "models.md").read_text(encoding="utf-8")
    assert written == _page_module().render(), "run python docs/models.py"
