"""Training configuration (splitcam.training.config): files, overrides, files that extend others
(``extends = "recipe.toml"``), and the experiment files of the repository, each resolving to
exactly the recipe it stands for."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO, tiny_config

from splitcam.training import train
from splitcam.training.config import ConfigError, TrainConfig, read_config_file
from splitcam.training.sweep import load_experiments

EXPERIMENTS = REPO / "experiments"


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_extends_merges_table_by_table(tmp_path):
    _write(
        tmp_path / "base" / "recipe.toml",
        '[pattern]\nname = "A"\nmix = ["A", "B"]\n[optim]\nsteps = 100\nlr = 2e-4\n'
        "[run]\nval_every = 7\n",
    )
    child = _write(
        tmp_path / "x.toml",
        'extends = "base/recipe.toml"\n[pattern]\nmix = ["C"]\n[optim]\nsteps = 5\n',
    )
    assert read_config_file(child) == {
        "pattern": {"name": "A", "mix": ["C"]},  # a list is one setting: replaced, not merged
        "optim": {"steps": 5, "lr": 2e-4},
        "run": {"val_every": 7},
    }
    cfg = TrainConfig.from_file(child)
    assert (cfg.pattern.name, cfg.pattern.mix, cfg.optim.steps, cfg.optim.lr) == (
        "A",
        ["C"],
        5,
        2e-4,
    )
    assert cfg.run.val_every == 7 and cfg.data.batch_size == TrainConfig().data.batch_size


def test_extends_is_relative_to_the_file_and_chains(tmp_path, monkeypatch):
    _write(tmp_path / "a" / "first.toml", "[optim]\nsteps = 1\nlr = 0.5\n[run]\nseed = 3\n")
    _write(tmp_path / "a" / "b" / "second.yaml", "extends: ../first.toml\noptim:\n  steps: 2\n")
    third = _write(
        tmp_path / "a" / "b" / "c" / "third.json",
        '{"extends": "../second.yaml", "run": {"seed": 4}}',
    )
    monkeypatch.chdir(tmp_path)  # not the files' folder: paths are relative to each file
    cfg = TrainConfig.from_file(third)
    assert (cfg.optim.steps, cfg.optim.lr, cfg.run.seed) == (2, 0.5, 4)


def test_extends_cycles_and_missing_files_name_the_files(tmp_path):
    a = _write(tmp_path / "a.toml", 'extends = "b.toml"\n')
    _write(tmp_path / "b.toml", 'extends = "./a.toml"\n')
    with pytest.raises(ConfigError, match=r"cycle: .*a\.toml -> .*b\.toml -> .*a\.toml"):
        read_config_file(a)
    itself = _write(tmp_path / "self.toml", 'extends = "self.toml"\n[optim]\nsteps = 1\n')
    with pytest.raises(ConfigError, match=r"self\.toml.*cycle"):
        TrainConfig.from_file(itself)
    lost = _write(tmp_path / "lost.toml", 'extends = "gone/recipe.toml"\n')
    with pytest.raises(
        ConfigError, match=r"lost\.toml.* extends 'gone/recipe\.toml'.*does not exist"
    ):
        TrainConfig.from_file(lost)
    for value in ("3", '["a.toml"]', '""'):
        bad = _write(tmp_path / "bad.toml", f"extends = {value}\n")
        with pytest.raises(ConfigError, match=r"bad\.toml.*extends must name a config file"):
            read_config_file(bad)
    broken = _write(tmp_path / "broken.toml", 'extends = "syntax.toml"\n')
    _write(tmp_path / "syntax.toml", "[optim\n")
    with pytest.raises(ConfigError, match=r"syntax\.toml.* is not valid"):
        read_config_file(broken)
    inner = _write(tmp_path / "inner.toml", '[optim]\nextends = "a.toml"\n')
    with pytest.raises(ConfigError, match="unknown setting.*'extends'"):  # top level only
        TrainConfig.from_file(inner)


#: What every shipped model's experiment trained with (``experiments/recipe/shipped.toml``),
#: written out here so that a change to a file or to the loader shows.
RECIPE = {
    "network.arch": "physics",
    "data.batch_size": 8,
    "data.patch_size": 64,
    "data.partial_periods": 0.0,
    "optim.steps": 26000,
    "optim.lr": 1e-3,
    "optim.schedule": "cosine",
    "optim.warmup_steps": 100,
    "run.val_every": 400,
    "run.checkpoint_every": 100,
}


OPTIMISED = {"pattern.learn": True, "pattern.design_steps": 300}


UNIVERSAL = {
    "pattern.name": "random",
    "pattern.mix": ["A", "B", "C", "D", "E", "bayer"],
    "pattern.mix_fraction": 0.4,
    "pattern.val_patterns": ["D", "E"],
    "network.arch": "universal",
    "data.partial_periods": 0.5,
    "optim.steps": 30000,
    "optim.loss": "log_mse",
    "optim.divergence_factor": 1000.0,
    "run.val_every": 1000,
    "run.checkpoint_every": 200,
}


EXPECTED = {
    "A": {"pattern.name": "A"},
    "B": {"pattern.name": "B"},
    "C": {"pattern.name": "C", "data.partial_periods": 0.5},
    "D": {"pattern.name": "D"},
    "E": {"pattern.name": "E", "data.partial_periods": 0.5},
    "bayer": {"pattern.name": "bayer"},
    "A-opt": {"pattern.name": "A", "pattern.init": "support", **OPTIMISED},
    "D-opt": {"pattern.name": "D", "pattern.init": "support", **OPTIMISED},
    "D-opt-random": {"pattern.name": "D", "pattern.init": "random", **OPTIMISED},
    "universal": UNIVERSAL,
    "universal-holdout": {**UNIVERSAL, "pattern.mix": ["A", "C", "D", "bayer"]},
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_each_experiment_resolves_to_its_recipe(name):
    expected = TrainConfig().override({**RECIPE, **EXPECTED[name]})
    cfg = TrainConfig.from_file(EXPERIMENTS / f"{name}.toml")
    assert cfg == expected
    cfg.validate()


def test_a_sweep_of_the_experiments_folder_is_the_experiments():
    """``splitcam sweep experiments/*.toml`` runs every experiment and nothing else: the shared
    recipe and the studies sit in sub-folders."""
    files = sorted(EXPERIMENTS.glob("*.toml"))
    assert {f.stem for f in files} == set(EXPECTED)
    assert (EXPERIMENTS / "recipe" / "shipped.toml").is_file()
    loaded = load_experiments(files, "runs", data="DIR")
    assert sorted(e.name for e in loaded) == sorted(EXPECTED)


def test_the_studies_load_with_the_paper_recipe():
    """The study configurations pin the paper's optimiser (Adam 1e-4, constant, no warm-up) and
    whole-period patches, which they were measured with, whatever today's defaults are."""
    studies = {p.stem: TrainConfig.from_file(p) for p in (EXPERIMENTS / "studies").glob("*.toml")}
    assert set(studies) == {"cpu_budget", "cmp_paper", "cmp_packed", "joint_packed"}
    for cfg in studies.values():
        cfg.validate()
        assert (cfg.optim.lr, cfg.optim.schedule, cfg.optim.warmup_steps) == (1e-4, "constant", 0)
        assert (cfg.data.batch_size, cfg.data.partial_periods, cfg.pattern.name) == (16, 0.0, "D")
    arch = {name: cfg.network.arch for name, cfg in studies.items()}
    assert arch == {
        "cpu_budget": "paper",
        "cmp_paper": "paper",
        "cmp_packed": "packed",
        "joint_packed": "packed",
    }
    assert studies["cpu_budget"].run.precision == "fp32"
    assert studies["joint_packed"].pattern.learn and studies["joint_packed"].optim.steps == 4533


def test_config_files_and_overrides(tmp_path, image_folder):
    toml = tmp_path / "c.toml"
    toml.write_text('[pattern]\nname = "A"\nlearn = true\n[optim]\nlr = 2e-4\n')
    cfg = TrainConfig.from_file(toml)
    assert cfg.pattern.name == "A" and cfg.pattern.learn and cfg.optim.lr == 2e-4
    assert cfg.data.batch_size == 8 and cfg.optim.sigma_max == 30  # defaults kept
    yaml_file = tmp_path / "c.yaml"
    yaml_file.write_text("network:\n  features: 32\n")
    assert TrainConfig.from_file(yaml_file).network.features == 32
    bad = [
        ('[pattern]\nnmae = "A"\n', "unknown setting.*'nmae'.*valid: design_steps, init, learn"),
        ("[optim]\nsteps = 1.5\n", "optim.steps: expected an integer, got 1.5"),
        ('[pattern]\nlearn = "False"\n', "pattern.learn: expected true or false"),
        ("[nope]\nx = 1\n", "unknown setting"),
        ("[optim\n", "not valid"),
    ]
    for text, message in bad:
        toml.write_text(text)
        with pytest.raises(ConfigError, match=message):
            TrainConfig.from_file(toml)
    with pytest.raises(ConfigError, match="pattern.init must be support, exact or random"):
        TrainConfig().override({"pattern.init": "zeros"}).validate()
    for scales in ([], [1.0, 1.0], [0.0], [1.5]):
        with pytest.raises(ConfigError, match="data.scales must be distinct factors"):
            TrainConfig().override({"data.scales": scales}).validate()
    with pytest.raises(ConfigError, match="no training data"):
        train(TrainConfig().override({"run.out": str(tmp_path / "x")}), progress=False)


def test_random_pattern_needs_the_universal_network(tmp_path) -> None:
    from splitcam.training import ConfigError

    config = tiny_config(tmp_path, tmp_path / "run", **{"pattern.name": "random"})
    with pytest.raises(ConfigError, match="--arch universal"):
        config.validate()


@pytest.mark.parametrize("name", ["A", "D", "A-opt", "D-opt"])
def test_the_noise_range_fine_tunings_change_only_the_range_and_budget(name):
    """experiments/sigma20/X.toml is the border fine-tuning of X (experiments/edges/X.toml)
    on σ 0-20 for 5000 steps with the weight average on, nothing else."""
    edges = TrainConfig.from_file(EXPERIMENTS / "edges" / f"{name}.toml")
    tuned = TrainConfig.from_file(EXPERIMENTS / "sigma20" / f"{name}.toml")
    changes = {"optim.sigma_max": 20.0, "optim.steps": 5000, "optim.ema": 0.999}
    assert tuned == edges.override(changes)
    assert tuned.run.init_from == name
    tuned.validate()


@pytest.mark.parametrize("name", ["A", "D", "A-opt", "D-opt"])
def test_the_half_size_fine_tunings_add_only_the_copies_and_a_budget(name):
    """experiments/scales/X.toml is experiments/sigma20/X.toml with copies at half size, for
    3000 steps, from the shipped X."""
    sigma20 = TrainConfig.from_file(EXPERIMENTS / "sigma20" / f"{name}.toml")
    tuned = TrainConfig.from_file(EXPERIMENTS / "scales" / f"{name}.toml")
    assert tuned == sigma20.override({"data.scales": [1.0, 0.5], "optim.steps": 3000})
    assert tuned.run.init_from == name
    tuned.validate()


def test_the_random_start_half_size_fine_tuning_is_its_border_recipe_on_sigma_0_20():
    """experiments/scales/D-opt-random.toml: the border fine-tuning of D-opt-random with σ 0-20,
    the weight average and copies at half size, for 3000 steps, from the shipped model."""
    edges = TrainConfig.from_file(EXPERIMENTS / "edges" / "D-opt-random.toml")
    tuned = TrainConfig.from_file(EXPERIMENTS / "scales" / "D-opt-random.toml")
    changes = {
        "optim.sigma_max": 20.0,
        "optim.ema": 0.999,
        "optim.steps": 3000,
        "data.scales": [1.0, 0.5],
    }
    assert tuned == edges.override(changes)
    assert tuned.run.init_from == "D-opt-random"
    tuned.validate()


@pytest.mark.parametrize(
    ("name", "minutes"),
    [("A", 2.3), ("D", 2.3), ("A-opt", 6.0), ("D-opt", 6.0), ("D-opt-random", 6.0)],
)
def test_the_gpu_fine_tunings_change_only_the_batch_rate_and_a_time_budget(name, minutes):
    """experiments/gpu/X.toml is experiments/scales/X.toml at batch 64 and peak rate 5e-4 on a
    CUDA device, ended by a time limit (the steps only a cap); nothing about the data or the
    noise changes."""
    scales = TrainConfig.from_file(EXPERIMENTS / "scales" / f"{name}.toml")
    tuned = TrainConfig.from_file(EXPERIMENTS / "gpu" / f"{name}.toml")
    changes = {
        "data.batch_size": 64,
        "optim.lr": 5e-4,
        "optim.warmup_steps": 200,
        "optim.steps": 1_000_000,
        "run.device": "cuda",
        "run.time_limit": minutes,
        "run.val_every": 1000 if minutes == 6.0 else 1500,
        "run.checkpoint_every": 1000,
    }
    assert tuned == scales.override(changes)
    assert tuned.run.init_from == name


def test_the_gpu_fine_tuning_of_b_brings_it_the_recipe_of_the_others():
    """experiments/gpu/B.toml: B's border fine-tuning with what A, D, A-opt and D-opt had since
    (σ 0-20, the weight average, copies at half size) and the GPU settings."""
    edges = TrainConfig.from_file(EXPERIMENTS / "edges" / "B.toml")
    tuned = TrainConfig.from_file(EXPERIMENTS / "gpu" / "B.toml")
    changes = {
        "data.batch_size": 64,
        "data.scales": [1.0, 0.5],
        "optim.lr": 5e-4,
        "optim.warmup_steps": 200,
        "optim.sigma_max": 20.0,
        "optim.ema": 0.999,
        "optim.steps": 1_000_000,
        "run.device": "cuda",
        "run.time_limit": 2.3,
        "run.val_every": 1500,
        "run.checkpoint_every": 1000,
    }
    assert tuned == edges.override(changes)
