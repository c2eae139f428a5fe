"""``splitcam train --recipe`` (splitcam.training.recipe): every shipped model has a recipe of
existing stage files; a recipe trains its stages in order, each from the one before, records
each stage's file in the provenance, and a second call skips what is done."""

from __future__ import annotations

import json

import pytest
from conftest import SMALL, experiment_file

from splitcam.io import checkpoints as ckpt_io
from splitcam.recon.loading import model_names
from splitcam.training import TrainConfig
from splitcam.training.config import ConfigError
from splitcam.training.models import provenance_of
from splitcam.training.recipe import read_recipe, recipe_names, run_recipe, stage_folder


def test_every_shipped_model_has_a_recipe_of_valid_stages():
    assert set(recipe_names()) == set(model_names())
    for name in recipe_names():
        recipe = read_recipe(name)
        assert recipe.model == name
        for stage in recipe.stages:
            TrainConfig.from_file(stage).validate()
    # The provenance of the shipped model has one segment per stage.
    for name in ("A", "B", "universal-photon"):
        from splitcam.recon.loading import load_model

        segments = load_model(name).meta["provenance"]["segments"]
        assert len(segments) == len(read_recipe(name).stages), name
    with pytest.raises(ConfigError, match="known: A, A-opt"):
        read_recipe("nonesuch")


def test_a_recipe_trains_its_stages_in_order_and_continues(image_folder, tmp_path):
    settings = {k: v for k, v in SMALL.items() if k != "run.threads"}
    (tmp_path / "cfg").mkdir()
    experiment_file(tmp_path / "cfg", "one", **settings)
    experiment_file(tmp_path / "cfg", "two", **{**settings, "optim.lr": 5e-4})
    recipe_file = tmp_path / "cfg" / "mine.toml"
    recipe_file.write_text('model = "mine"\nstages = ["one.toml", "two.toml"]\n')
    recipe = read_recipe(recipe_file)
    out = tmp_path / "runs"
    overrides = {"data.train": str(image_folder), "run.threads": 1}
    results = run_recipe(recipe, out, overrides, progress=False)
    assert len(results) == 2 and not any(r.failure or r.interrupted for r in results)
    one, two = (stage_folder(out, i, s) for i, s in enumerate(recipe.stages))
    assert one.name == "1-cfg-one" and two.name == "2-cfg-two"
    meta = ckpt_io.load(two).meta
    assert meta["init_from"]["name"] == str(one)
    segments = provenance_of(ckpt_io.load(two), two)["segments"]
    files = [s["config_file"] for s in segments]
    assert len(files) == 2 and files[0].endswith("one.toml") and files[1].endswith("two.toml")
    # Run again: both stages are done, nothing trains.
    stamp = (two / "checkpoint.json").stat().st_mtime_ns
    assert run_recipe(recipe, out, overrides, progress=False) == []
    assert (two / "checkpoint.json").stat().st_mtime_ns == stamp
    assert json.loads((two / "config.json").read_text())["optim"]["lr"] == 5e-4
