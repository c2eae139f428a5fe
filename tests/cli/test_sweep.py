"""``splitcam sweep``: dry runs, ``--set``, and experiments whose model already ships."""

from __future__ import annotations

import pytest
from conftest import SWEEP_SMALL, experiment_file

from splitcam.cli import main
from splitcam.io import checkpoints as ckpt_io
from splitcam.io import weights as io_weights
from splitcam.training.models import export_model


@pytest.mark.slow
@pytest.mark.integration
def test_sweep_skips_an_experiment_whose_model_ships_with_its_budget(
    trained_run, run_images, tmp_path, monkeypatch, capsys
):
    """A shipped model of the experiment's name with the whole budget, and no run folder or
    snapshot: the sweep skips it instead of training it again from scratch; a bigger budget,
    or --retrain-shipped, trains it."""
    monkeypatch.setattr(io_weights, "MODELS_DIR", tmp_path / "shipped")
    export_model(trained_run, tmp_path / "shipped" / "d", name="d")  # 4 steps
    exps = tmp_path / "experiments"
    exps.mkdir()
    same = experiment_file(exps, "d", **SWEEP_SMALL)
    runs = tmp_path / "runs"
    common = ["--out", str(runs), "--data", str(run_images), "--threads", "1"]
    assert main(["sweep", str(same), *common, "--dry-run"]) == 0
    assert "d: skipped, ships with its whole budget" in capsys.readouterr().out
    assert main(["sweep", str(same), *common]) == 0
    assert "d: skipped" in capsys.readouterr().out and not (runs / "d").exists()
    bigger = ["--set", "optim.steps=6"]
    assert main(["sweep", str(same), *common, *bigger, "--dry-run"]) == 0
    assert "d: new" in capsys.readouterr().out
    assert main(["sweep", str(same), *common, "--retrain-shipped"]) == 0
    assert ckpt_io.load(runs / "d").meta["step"] == 4


def test_cli_sweep_dry_run_and_set(run_images, tmp_path, capsys):
    exps = tmp_path / "e"
    exps.mkdir()
    f = experiment_file(exps, "a", **{"optim.steps": 2})
    assert (
        main(
            [
                "sweep",
                str(f),
                "--out",
                str(tmp_path / "runs"),
                "--data",
                str(run_images),
                "--set",
                "optim.steps=7",
                "--dry-run",
            ]
        )
        == 0
    )
    assert "a: new" in capsys.readouterr().out
    assert main(["sweep", str(f), "--data", str(run_images), "--set", "optim.stepz=7"]) == 1
    assert "unknown setting 'optim.stepz'" in capsys.readouterr().err
