"""``--init-from auto`` (splitcam.training.auto_init): the candidates are the network for any
pattern and the shipped networks of the pattern's period and light domain; the search shares
30 % of the time limit among them and the run continues from the probe that validated best; a
run the search cannot serve is refused with one line."""

from __future__ import annotations

import pytest
from conftest import tiny_config

from splitcam import patterns
from splitcam.io import checkpoints as ckpt_io
from splitcam.training import ConfigError
from splitcam.training.auto_init import candidates, choose_start


def test_candidates_share_the_period_and_the_light() -> None:
    assert candidates(patterns.get("C"), "srgb") == ["universal", "C", "E"]  # both 1x3
    linear = candidates(patterns.get("bayer"), "linear")
    assert linear[0] == "universal-photon" and "bayer-photon" in linear and "bayer" not in linear


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({}, "give --time-limit"),
        ({"run.time_limit": 1.0, "pattern.learn": True}, "one fixed pattern"),
        ({"run.time_limit": 1.0, "pattern.name": "random"}, "one fixed pattern"),
    ],
)
def test_a_run_the_search_cannot_serve_is_refused(image_folder, tmp_path, changes, message):
    config = tiny_config(image_folder, tmp_path / "r", **{"run.init_from": "auto", **changes})
    with pytest.raises(ConfigError, match=message):
        choose_start(config, lambda name: {})
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_init_from_auto_tries_each_start_and_continues_from_the_best(
    image_folder, tmp_path, capsys
):
    """--init-from auto trains universal and every shipped network of the pattern's period for
    an equal share of 30 % of the time limit, says what each reached, and the run continues
    from the probe that validated best for the rest of the limit."""
    from splitcam.cli import main
    from splitcam.recon.loading import load_model, model_names
    from splitcam.training.auto_init import candidates
    from splitcam.training.rundir import metrics_rows

    names = candidates(patterns.get("bayer"), "srgb")
    expected = ["universal"] + [
        n
        for n in model_names()
        if load_model(n).meta["network"]["arch"] == "physics"
        and tuple(load_model(n).meta["network"]["period"]) == (2, 2)
        and (load_model(n).meta["config"]["data"].get("domain") or "srgb") == "srgb"
    ]
    assert names == expected and "bayer" in names and "D" in names and "E" not in names
    run = tmp_path / "run"
    args = [
        "train",
        "--pattern",
        "bayer",
        "--init-from",
        "auto",
        "--data",
        str(image_folder),
        "--out",
        str(run),
        "--time-limit",
        "0.3",
        "--patch-size",
        "16",
        "--batch-size",
        "2",
        "--val-crop",
        "32",
        "--val-images",
        "2",
        "--threads",
        "2",
        "--quiet",
    ]
    assert main(args) == 0
    out = capsys.readouterr().out
    ends = {}
    for name in names:
        vals = [r["val_psnr"] for r in metrics_rows(run / "init-search" / name) if "val_psnr" in r]
        ends[name] = vals[-1]
        assert f"  {name}: validation" in out
    best = max(ends, key=ends.get)
    assert f"continuing from {best} " in out
    # The probes end at their limits by design: only the run itself may advise a resume.
    assert out.count("to train further") <= 1
    meta = ckpt_io.read_meta(run / "checkpoint.safetensors")
    assert meta["init_from"]["name"] == str(run / "init-search" / best)
    assert meta["config"]["run"]["time_limit"] == pytest.approx(0.3 * 0.7)
    chain = meta["init_from"]["provenance"]["segments"]
    assert chain[-1]["init_from"] == best
