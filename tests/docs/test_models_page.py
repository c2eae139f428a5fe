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


def test_the_drop_column_is_the_evaluations_own_drop():
    """Each model's Kodak24-minus-McMaster on the page is the evaluation table's drop at σ 0
    (computed there from unrounded means), not the difference of the two rounded cells beside
    it, which can differ by 0.01 dB; the two still agree to that rounding."""
    page = _page_module()
    table = page.TABLE.read_text(encoding="utf-8").splitlines()
    start = next(i for i, x in enumerate(table) if x.startswith("### kodak24 minus mcmaster"))
    drops = {}
    for line in table[start + 1 :]:
        if line.startswith("### "):
            break
        if line.startswith("| net-"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            drops[cells[0][len("net-") :]] = cells[1]
    rendered = page.render()
    checked = 0
    for name, drop in drops.items():
        cell = _row(rendered, name)[9]
        kodak, rest = cell.split(" / ")
        mcmaster, shown = rest.split(" (")
        assert shown.split(")")[0] == drop, name
        assert abs(float(kodak) - float(mcmaster) - float(drop)) <= 0.0100001, name
        checked += 1
    assert checked >= 9  # A-E, bayer, A-opt, D-opt, D-opt-random
