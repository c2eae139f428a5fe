"""``splitcam train --recipe`` (splitcam.training.recipe): every shipped model is its own recipe
(its header records each stage's file, settings and steps), whose stages agree with the
configuration files they name except where the record says what ran differently; a model
exported from a chain of runs replays that chain; a recipe trains its stages in order, each from
the one before, and a second call skips what is done."""

from __future__ import annotations

import json
import re

import pytest
from conftest import SMALL, experiment_file

from splitcam.io import checkpoints as ckpt_io
from splitcam.recon.loading import load_model, model_names
from splitcam.training import TrainConfig
from splitcam.training.config import ConfigError
from splitcam.training.models import blend_models, export_model, provenance_of
from splitcam.training.recipe import (
    MACHINE_KEYS,
    blend_of,
    read_recipe,
    recipe_model,
    recipe_names,
    run_recipe,
    shipped_recipe,
    stage_folder,
)


def _flat(config: TrainConfig) -> dict:
    return {f"{s}.{k}": v for s, values in config.to_dict().items() for k, v in values.items()}


def _record(segment: dict) -> dict:
    """What a provenance segment states about its run, written out here as dotted settings."""
    recipe = segment["recipe"]
    return {
        "data.batch_size": segment["batch_size"],
        "data.patch_size": segment["patch_size"],
        "network.arch": recipe["arch"],
        "optim.lr": recipe["lr"],
        "optim.schedule": recipe["schedule"],
        "optim.warmup_steps": recipe["warmup_steps"],
        "optim.sigma_min": recipe["sigma"][0],
        "optim.sigma_max": recipe["sigma"][1],
        "pattern.learn": recipe["learn_pattern"],
    }


@pytest.mark.parametrize("name", model_names())
def test_every_shipped_model_is_its_own_recipe_agreeing_with_its_files(name):
    """A shipped model replays as the chain of stages its header records; one whose weights
    are a blend of two replays each end (such a chain, or a blend again), then the blend."""
    assert name in recipe_names()
    meta = load_model(name).meta
    _assert_replays(meta, read_recipe(name))  # by name, as --recipe reads it


def _assert_replays(meta: dict, recipe) -> None:
    """``recipe`` (or a blend's end inside one) against the header ``meta`` it was read from,
    the header's segments and configuration files read here again."""
    segments = meta["provenance"].get("segments", [])  # a blend's end records none
    if blend := blend_of(meta):  # its own weights' blend, or the one it was trained from
        # each end replays as its record says, then the blend at its weight; a model trained
        # on from the blend replays its segments that no end holds
        assert recipe.blend is not None and recipe.blend.weight == blend["weight"]
        for end, replayed in (("start", recipe.blend.start), ("end", recipe.blend.end)):
            _assert_replays(blend[end], replayed)
        held = _every_segment(blend)
        segments = [] if meta["provenance"].get("blend") else [s for s in segments if s not in held]
        if not segments:
            assert recipe.stages == ()
            return
    # One stage per run: consecutive segments of one file and settings are a run continued.
    files = [(s["config_file"], s["settings"]) for s in segments]
    starts = [i for i in range(len(files)) if i == 0 or files[i - 1] != files[i]]
    assert [stage.file for stage in recipe.stages] == [files[i][0] for i in starts]
    # Each stage replays the steps its segments trained, with no time limit.
    assert sum(stage.config.optim.steps for stage in recipe.stages) == sum(
        s["steps"] for s in segments
    )
    for stage, start in zip(recipe.stages, starts, strict=True):
        stage.config.validate()
        assert stage.config.run.time_limit is None
        record = _record(segments[start])
        mine, file = _flat(stage.config), _flat(TrainConfig.from_file(stage.file))
        # where the record speaks, the stage is the record
        assert {k: mine[k] for k in record} == record, stage.file
        # elsewhere it is its configuration file, bar where and on what it trained
        differ = {k for k in mine if mine[k] != file[k]} - set(MACHINE_KEYS)
        differ -= {"optim.steps", "run.time_limit", "optim.ema", "run.seed"}  # on the command line
        assert differ <= {k for k in record if record[k] != file[k]}, (stage.file, differ)


def _every_segment(blend: dict) -> list:
    """The segments of every chain a blend's record holds, written out here again."""
    out = []
    for end in (blend["start"], blend["end"]):
        out += end["provenance"].get("segments", [])
        inner = end["provenance"].get("blend") or end["provenance"].get("from_blend")
        out += _every_segment(inner) if inner else []
    return out


def test_a_shipped_recipe_needs_no_configuration_file(monkeypatch):
    """From an installed wheel (no experiments/ folder) the header is all a recipe reads."""

    def refuse(*args, **kwargs):
        raise AssertionError("read a configuration file")

    monkeypatch.setattr(TrainConfig, "from_file", refuse)
    recipe = read_recipe("D-photon")
    # the stages the header's description names, in order, the last a cool-down at 1e-4
    described = re.findall(r"experiments/\S+?\.toml", load_model("D-photon").meta["description"])
    assert [s.file for s in recipe.stages] == described
    assert described[-1].startswith("experiments/colour/D-photon")
    assert recipe.stages[-1].config.optim.lr == 1e-4


def test_recipes_refuse_what_they_cannot_replay(tmp_path):
    with pytest.raises(ConfigError, match="shipped: A, A-opt"):
        read_recipe("nonesuch")
    (tmp_path / "damaged.json").write_text("{}")
    with pytest.raises(ConfigError, match="--recipe .*damaged.json"):
        read_recipe(tmp_path / "damaged.json")
    meta = json.loads(json.dumps(load_model("C").meta))
    del meta["provenance"]["segments"][1]["settings"]
    with pytest.raises(ConfigError, match="segment 2 .* records no configuration file or settings"):
        shipped_recipe(meta, "C")
    bad = tmp_path / "bad.toml"
    bad.write_text('stages = ["missing.toml"]\n')
    with pytest.raises(ConfigError, match="missing.toml not found"):
        read_recipe(bad)


def test_a_recipe_trains_its_stages_in_order_and_the_model_replays_them(image_folder, tmp_path):
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
    # The model exported from the last stage is a recipe of the same two stages.
    exported = export_model(two, tmp_path / "models", name="mine")
    replay = shipped_recipe(json.loads(exported.read_text()), "mine")
    assert [s.file for s in replay.stages] == [s.file for s in recipe.stages]
    for mine, written in zip(replay.stages, recipe.stages, strict=True):
        a, b = _flat(mine.config), _flat(written.config)
        assert {k for k in a if a[k] != b[k]} <= set(MACHINE_KEYS)


def test_a_blend_replays_its_ends_once_each_shared_stage_then_the_blend_and_what_followed(
    image_folder, tmp_path, capsys
):
    """A model trained on from a blend of two chains that share their first stage: its recipe
    trains that stage once, the second chain's next, blends them at the recorded weight and
    storage, trains the last stage from the blend, and ends with the original's weights."""
    import torch

    from splitcam.training import train

    settings = {k: v for k, v in SMALL.items() if k != "run.threads"}
    cfg = tmp_path / "cfg"
    cfg.mkdir()
    for name, lr in (("one", 1e-3), ("two", 5e-4), ("three", 2e-4)):
        experiment_file(cfg, name, **{**settings, "optim.lr": lr})
    (cfg / "chain.toml").write_text('model = "mine"\nstages = ["one.toml", "two.toml"]\n')
    overrides = {"data.train": str(image_folder), "run.threads": 1}
    first = tmp_path / "first"
    run_recipe(read_recipe(cfg / "chain.toml"), first, overrides, progress=False)
    one, two = sorted(first.iterdir())
    ends = [export_model(run, tmp_path / "ends" / run.name, name="mine") for run in (one, two)]
    blended = blend_models(*ends, 0.25, tmp_path / "blend", name="mine", storage="float32")
    after = tmp_path / "after"
    config = TrainConfig.from_file(cfg / "three.toml").override(
        {**overrides, "run.out": str(after), "run.init_from": str(blended)}
    )
    config = config.override({"run.config_file": str(cfg / "three.toml")})
    train(config, progress=False)
    model_file = export_model(after, tmp_path / "model", name="mine")
    recipe = read_recipe(model_file)  # its file, as --recipe FILE.json reads it
    assert recipe.count() == (3, 1) and len(recipe.stages) == 1  # "one" trained once
    assert (recipe.blend.weight, recipe.blend.storage) == (0.25, "float32")
    assert [len(r.stages) for r in (recipe.blend.start, recipe.blend.end)] == [1, 2]
    again = tmp_path / "again"
    results = run_recipe(recipe, again, overrides, progress=False)
    assert len(results) == 3 and not any(r.failure or r.interrupted for r in results)
    made = recipe_model(recipe, again)
    assert made.parent == again and made.name.startswith("1-cfg-three-")
    original, replayed = ckpt_io.load(after), ckpt_io.load(made)
    for key, value in original.tensors.items():
        if key.startswith("model/"):
            torch.testing.assert_close(replayed.tensors[key], value, rtol=0, atol=0)
    # Run again: everything is done, nothing trains and the blend is not made again.
    stamp = next(again.glob("blend-*.json")).stat().st_mtime_ns
    assert run_recipe(recipe, again, overrides, progress=False) == []
    assert next(again.glob("blend-*.json")).stat().st_mtime_ns == stamp
    # The command says what it trains and where the model is.
    from splitcam.cli import main

    argv = ["train", "--recipe", str(model_file), "--data", str(image_folder), "--quiet"]
    assert main([*argv, "--out", str(again), "--threads", "1"]) == 0
    out = capsys.readouterr().out
    assert "recipe mine: 3 stages and 1 blend into" in out and f"the model: {made}" in out
