"""``splitcam models``: export a run, list the models, and never replace a model unasked."""

from __future__ import annotations

import json
import re

from conftest import blocky_images, tiny_config

from splitcam.cli import main
from splitcam.io import weights as io_weights
from splitcam.recon.loading import load_model
from splitcam.training import train


def test_cli_models_export_list_and_evaluate(trained_run, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(io_weights, "MODELS_DIR", tmp_path / "shipped")
    (tmp_path / "shipped").mkdir()
    assert main(["models", "export", str(trained_run), "--name", "D", "--ship"]) == 0
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"\| D +\| D +\| physics \| srgb, gaussian \| 4 +\| 4 +\|", out), out
    assert (
        main(
            [
                "evaluate",
                "--model",
                "D",
                "--max-images",
                "1",
                "--sigmas",
                "5",
                "--out",
                str(tmp_path / "ev"),
                "--quiet",
            ]
        )
        == 0
    )
    summary = json.loads((tmp_path / "ev" / "summary.json").read_text())
    assert list(summary) == ["net-D"]
    assert main(["reconstruct", "--model", "Q", "--image", "x.png", "--out", "y.png"]) == 1
    assert "shipped models: D" in capsys.readouterr().err


def test_models_export_never_replaces_a_model_unasked(tmp_path, monkeypatch, capsys):
    """As the README showed it, `models export RUN --name D` replaced the shipped model D."""
    from splitcam.io import weights

    data = blocky_images(tmp_path / "img", 5)
    run = tmp_path / "run"
    train(tiny_config(data, run, **{"optim.steps": 2}), progress=False)
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    (shipped / "D.json").write_text("{}")
    monkeypatch.setattr(weights, "MODELS_DIR", shipped)
    monkeypatch.chdir(tmp_path)
    assert main(["models", "export", str(run), "--name", "D"]) == 0
    assert (tmp_path / "models" / "D.json").is_file()  # a user folder by default
    assert (shipped / "D.json").read_text() == "{}"
    assert main(["models", "export", str(run), "--name", "D"]) == 1  # exists now
    assert "--force" in capsys.readouterr().err
    assert main(["models", "export", str(run), "--name", "D", "--ship"]) == 1
    assert (shipped / "D.json").read_text() == "{}"
    assert main(["models", "export", str(run), "--name", "D", "--ship", "--force"]) == 0

    assert load_model("D").meta["name"] == "D"


def test_cli_models_blend_writes_a_candidate_and_never_ships_it(
    trained_run, tmp_path, monkeypatch, capsys
):
    """`models blend` of a model with itself gives the same weights (to float16); it writes
    into --out, refuses --ship (a blend ships through the gate) and an existing file unasked."""
    monkeypatch.chdir(tmp_path)
    assert main(["models", "export", str(trained_run), "--name", "D", "--out", "m"]) == 0
    args = ["models", "blend", "m/D.json", "m/D.json", "--weight", "0.25", "--name", "D"]
    assert main([*args, "--out", "blend"]) == 0
    one, two = load_model("m/D.json").network, load_model("blend/D.json").network
    for key, value in one.state_dict().items():
        assert (two.state_dict()[key] - value).abs().max() <= 1e-3 * value.abs().max() + 1e-6
    assert main([*args, "--out", "blend"]) == 1
    assert "exists; --force replaces it" in capsys.readouterr().err
    assert main([*args, "--ship"]) == 1
    assert "through the gate" in capsys.readouterr().err
    assert main(["models", "blend", "m/D.json", "--weight", "0.5", "--name", "D"]) == 1
