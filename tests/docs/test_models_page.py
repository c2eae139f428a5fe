"""docs/models.md is what docs/models.py writes from the shipped files (so a model that ships
without the page being regenerated fails here), and each shipped model's recipe states the
chain its provenance records: every segment names its configuration file, and the files of its
segments in order (consecutive segments of one file are one stage continued) are the recipe's
stages."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from splitcam.recon.loading import load_model, model_names
from splitcam.training.recipe import read_recipe

ROOT = Path(__file__).resolve().parents[2]


def _page_module():
    spec = importlib.util.spec_from_file_location("models_page", ROOT / "docs" / "models.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_models_page_is_current():
    written = (ROOT / "docs" / "models.md").read_text(encoding="utf-8")
    assert written == _page_module().render(), "run python docs/models.py"


@pytest.mark.parametrize("name", model_names())
def test_each_recipe_states_the_chain_its_provenance_records(name):
    segments = load_model(name).meta["provenance"]["segments"]
    assert all(s.get("config_file") for s in segments), "python scripts/name_stage_files.py"
    chain = [s["config_file"] for s in segments]
    chain = [f for i, f in enumerate(chain) if i == 0 or chain[i - 1] != f]
    assert chain == [str(p.relative_to(ROOT)) for p in read_recipe(name).stages]
