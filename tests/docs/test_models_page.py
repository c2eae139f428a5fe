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


def _row(page: str, name: str) -> list[str]:
    line = next(x for x in page.splitlines() if x.startswith(f"| {name} |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_a_model_missing_from_the_evaluation_says_so(tmp_path, monkeypatch):
    """An sRGB model whose rows are missing from the evaluation's table (an evaluation under
    way, or never run) is marked as not evaluated, not as scored elsewhere in linear light;
    a photon network still points to the exposure study."""
    page = _page_module()
    table = page.TABLE.read_text(encoding="utf-8")
    kept = [x for x in table.splitlines() if not x.startswith("| net-C |")]
    assert len(kept) < len(table.splitlines())  # the committed table scores C
    partial = tmp_path / "table.md"
    partial.write_text("\n".join(kept) + "\n", encoding="utf-8")
    monkeypatch.setattr(page, "TABLE", partial)
    rendered = page.render()
    score, drop = _row(rendered, "C")[7], _row(rendered, "C")[9]
    assert "not in the evaluation" in score and "photons" not in score
    assert drop == "–"
    assert "photons, linear light" in _row(rendered, "bayer-photon")[7]
    assert _row(rendered, "E")[7][0].isdigit()  # the others keep their scores
