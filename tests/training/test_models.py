"""Trained models as files (splitcam.training.models): export, 16-bit storage, repeatable bytes,
provenance."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
import torch
from conftest import small_config, tiny_config

from splitcam.evaluation.protocol import mean_psnr
from splitcam.recon.loading import load_model
from splitcam.recon.registry import build_method, build_model
from splitcam.training import load_system, train
from splitcam.training.config import ConfigError
from splitcam.training.models import export_model
from splitcam.training.recipe import shipped_recipe


def _images(n=2, size=24):
    g = torch.Generator().manual_seed(9)
    x = torch.rand(n, 3, size + 4, size + 4, generator=g)
    x = torch.nn.functional.avg_pool2d(x, 5, stride=1)
    return [(f"img{i}", x[i]) for i in range(n)]


@pytest.mark.parametrize("storage", ["float16", "float32"])
def test_export_round_trip_matches_the_run(trained_run, tmp_path, storage):
    """A model reconstructs like its run: exactly in float32, within a hair in float16 (the
    difference is measured on the PSNR, which must move by far less than 0.01 dB)."""
    path = export_model(trained_run, tmp_path / "mine", storage=storage)
    meta = json.loads(path.read_text())
    assert meta["name"] == "mine" and meta["storage"] == storage
    assert meta["provenance"]["total_steps"] == 4
    assert meta["provenance"]["segments"][0]["batch_size"] == 4
    assert [row["step"] for row in meta["provenance"]["validation"]] == [0, 2, 4]
    system = load_model(path)
    run_system = load_system(trained_run)
    for key, value in run_system.network.state_dict().items():
        mine = system.network.state_dict()[key]
        tol = 0 if storage == "float32" or not value.is_floating_point() else 1e-3
        torch.testing.assert_close(mine, value, rtol=tol, atol=tol)
    images = _images()
    ours = mean_psnr(build_model(path), images, [0.0, 10.0])
    theirs = mean_psnr(
        build_method(str(trained_run / "checkpoint.safetensors")), images, [0.0, 10.0]
    )
    for sigma in ours:
        assert abs(ours[sigma] - theirs[sigma]) < (1e-9 if storage == "float32" else 0.01)
    if storage == "float16":  # half the bytes of the weights (the statistics stay float64)
        full = export_model(trained_run, tmp_path / "full", storage="float32")
        assert (
            path.with_suffix(".safetensors").stat().st_size
            < full.with_suffix(".safetensors").stat().st_size
        )


def test_export_is_byte_for_byte_repeatable(trained_run, tmp_path):
    """The same weights give the same file: safetensors writes its metadata map in hash order
    (before the header was made canonical, 8 exports of one run gave files with different bytes
    about every other time), so shipped checksums moved with every re-export."""
    from safetensors.torch import load_file

    blobs = set()
    for i in range(8):
        meta = json.loads(export_model(trained_run, tmp_path / f"m{i}").read_text())
        blob = (tmp_path / f"m{i}.safetensors").read_bytes()
        assert hashlib.sha256(blob).hexdigest() == meta["sha256"]
        blobs.add(blob)
    assert len(blobs) == 1
    loaded = load_file(str(tmp_path / "m0.safetensors"))  # still plain safetensors
    system = load_model(tmp_path / "m0")
    for key, value in system.network.state_dict().items():
        torch.testing.assert_close(loaded[key].to(value.dtype), value, rtol=0, atol=0)


def test_provenance_records_each_thread_count_of_a_resumed_run(run_images, tmp_path):
    """A run trained on 1 thread, then resumed on 2: the exported provenance says both, from the
    run's changes.jsonl (the checkpoint alone only knows the last count). Threads are a CPU's:
    the runs are on the CPU also where a GPU is visible."""
    cpu = {"run.device": "cpu"}
    out = tmp_path / "t"
    train(
        small_config(run_images, out, **{**cpu, "optim.steps": 2, "run.threads": 1}), progress=False
    )
    config = small_config(run_images, out, **{**cpu, "optim.steps": 4, "run.threads": 2})
    train(config, resume=True, progress=False)
    meta = json.loads(export_model(out, tmp_path / "m", name="m").with_suffix(".json").read_text())
    segment = meta["provenance"]["segments"][-1]
    assert segment["threads"] == [[0, 1], [2, 2]]
    assert "1 thread, 2 from step 2)" in segment["device"]
    assert torch.backends.cpu.get_cpu_capability() in segment["device"]
    assert meta["provenance"]["total_steps"] == 4
    # One thread count all along: said once, in the singular.
    once = tmp_path / "once"
    train(
        small_config(run_images, once, **{**cpu, "optim.steps": 2, "run.threads": 1}),
        progress=False,
    )
    meta = json.loads(export_model(once, tmp_path / "o").read_text())
    assert meta["provenance"]["segments"][-1]["device"].endswith("; 1 thread)")


def test_budgets_keep_cpu_and_gpu_minutes_apart():
    """A model trained on CPUs, then on a GPU: the table says the minutes of each and every
    batch size, since a GPU minute does far more steps than a CPU minute."""
    from splitcam.training.models import model_summary, training_budget, training_minutes

    def meta(*segments):
        segs = [{"device": d, "train_seconds": s, "batch_size": b} for d, s, b in segments]
        prov = {"segments": segs, "total_steps": 100, "train_seconds": sum(s[1] for s in segments)}
        return {"provenance": prov, "pattern": {"name": "A"}, "network": {"arch": "physics"}}

    cpu = ("cpu (AMD EPYC, AVX512; 1 thread)", 9720.0, 8)
    gpu = ("cuda (NVIDIA H100 80GB HBM3)", 138.0, 64)
    both = meta(cpu, gpu)
    assert training_minutes(both) == "162 min CPU + 2.3 min GPU"
    assert training_minutes(meta(cpu)) == "162 min"
    assert training_minutes(meta(gpu)) == "2.3 min GPU"
    assert training_minutes(meta(("cuda:1 (NVIDIA A100)", 1200.0, 64))) == "20 min GPU"
    row = model_summary("A", both)
    assert row["batch"] == "8/64" and row["train time"] == "162 min CPU + 2.3 min GPU"
    assert training_budget(both).startswith("100 steps of batch 8/64, 162 min CPU + 2.3 min GPU")


def test_a_model_exported_without_a_description_is_described_by_its_provenance(
    trained_run, tmp_path
):
    """`splitcam models export` without --description composes the line from the header: the
    network, the pattern, the light and noise, and each stage's recipe and steps, as the
    provenance records them; a description given is kept as given."""
    meta = json.loads(export_model(trained_run, tmp_path / "m").read_text())
    segments = meta["provenance"]["segments"]
    stage = segments[0].get("config_file") or segments[0]["run"]
    assert meta["description"] == (
        f"{meta['network']['arch']} network for pattern {meta['pattern']['name']}, trained in "
        f"srgb light with gaussian noise; stages: {stage} ({segments[0]['steps']} steps)"
    )
    given = export_model(trained_run, tmp_path / "g", description="mine, by hand")
    assert json.loads(given.read_text())["description"] == "mine, by hand"


def test_every_shipped_model_has_a_description():
    from splitcam.recon.loading import model_names

    empty = [n for n in model_names() if not load_model(n).meta.get("description")]
    assert empty == []


def test_a_model_file_names_no_folder_of_the_machine_it_trained_on(
    trained_run, tmp_path, monkeypatch
):
    """The run trained on photos in an absolute folder; under the data root the model records
    it as the folder's name there (which ``dataset_folder`` resolves anywhere), outside it as
    the folder's name alone; the run's own settings keep the path (a resume needs it)."""
    from splitcam.io import checkpoints as ckpt_io

    train_dir = str(ckpt_io.load(ckpt_io.resolve(trained_run)).meta["config"]["data"]["train"])
    assert train_dir.startswith("/")
    data = Path(train_dir)
    monkeypatch.setenv("SPLITCAM_DATA", str(data.parent))
    config = json.loads(export_model(trained_run, tmp_path / "in").read_text())["config"]
    assert config["data"]["train"] == data.name
    assert not str(config["run"]["out"]).startswith("/")
    monkeypatch.setenv("SPLITCAM_DATA", str(tmp_path / "elsewhere"))
    monkeypatch.chdir(tmp_path)
    config = json.loads(export_model(trained_run, tmp_path / "out").read_text())["config"]
    assert config["data"]["train"] == data.name
    again = ckpt_io.load(ckpt_io.resolve(trained_run)).meta["config"]["data"]["train"]
    assert again == train_dir


def test_no_shipped_file_names_a_folder_of_the_machine_it_was_made_on():
    """Every shipped model's settings and stages and every shipped statistics' source are written
    relative to the data root or a working folder (``portable_path``)."""
    from splitcam.io.weights import LMMSE_DIR, MODELS_DIR
    from splitcam.recon.closed_form import SHIPPED_PATHS
    from splitcam.training.recipe import MACHINE_KEYS

    found = []
    for path in sorted(Path(MODELS_DIR).glob("*.json")):
        config = json.loads(path.read_text())["config"]
        for key in MACHINE_KEYS:
            section, name = key.split(".")
            value = config.get(section, {}).get(name)
            if isinstance(value, str) and value.startswith("/"):
                found.append(f"{path.name}: {key} = {value}")
        for seg in json.loads(path.read_text())["provenance"]["segments"]:
            if str((seg.get("data") or {}).get("train", "")).startswith("/"):
                found.append(f"{path.name}: segment {seg.get('run')} trained on {seg['data']}")
    stats = [Path(p).with_suffix(".json") for p in SHIPPED_PATHS.values()]
    for path in stats + sorted(Path(LMMSE_DIR).glob("*.json")):
        source = json.loads(path.read_text()).get("info", {}).get("source", "")
        if str(source).startswith("/"):
            found.append(f"{path.name}: source = {source}")
    assert found == []


def test_a_blend_lies_on_the_line_between_its_two_models(trained_run, run_images, tmp_path):
    """`blend_models` against the weights computed here from the two loaded models: each
    trained weight is (1 - w) start + w end, exactly in float32 storage; the ends of the line
    are the two models themselves; what is not trained is kept; the header records the blend."""
    from splitcam.training.models import blend_models

    other = tmp_path / "other"
    train(small_config(run_images, other, **{"run.seed": 5}), progress=False)
    start = export_model(trained_run, tmp_path / "start", storage="float32")
    end = export_model(other, tmp_path / "end", storage="float32")
    first, second = load_model(start).network, load_model(end).network
    trained = {n for n, _ in second.named_parameters()}
    assert any(
        not torch.equal(first.state_dict()[k], second.state_dict()[k]) for k in trained
    )  # two different networks
    for weight in (0.0, 0.3, 1.0):
        path = blend_models(start, end, weight, tmp_path / f"b{weight}", storage="float32")
        blended = load_model(path)
        for key, value in blended.network.state_dict().items():
            a, b = first.state_dict()[key], second.state_dict()[key]
            expected = a + weight * (b - a) if key in trained else b
            torch.testing.assert_close(value, expected, rtol=1e-6, atol=1e-7)
        # two runs of 4 steps from scratch: the blend has seen the steps of both
        prov = blended.meta["provenance"]
        assert prov["total_steps"] == 8 and len(prov["segments"]) == 2
        blend = prov["blend"]
        assert blend["weight"] == weight
        assert [blend["start"]["name"], blend["end"]["name"]] == ["start", "end"]
        assert blended.meta["pattern"] == load_model(end).meta["pattern"]
        # --recipe replays a blend's two ends (tests/training/test_recipe.py): these two ran
        # from no configuration file, and the refusal names the end it cannot replay
        with pytest.raises(ConfigError, match="b, its blend's start: segment 1 .* no config"):
            shipped_recipe(blended.meta, "b")
        # each end's stages are recorded whole
        for end_meta, record in (
            (load_model(start).meta, blend["start"]),
            (load_model(end).meta, blend["end"]),
        ):
            assert record["provenance"]["segments"] == end_meta["provenance"]["segments"]
            assert "validation" not in record["provenance"]
        assert blended.meta["description"].endswith(
            f"with the model start ({load_model(start).meta['meta_sha256'][:8]}): "
            f"{weight:g} of these weights and {1 - weight:g} of its"
        )


def test_networks_of_any_pattern_blend_whatever_pattern_they_drew_last(tiny_universal, tmp_path):
    """A network of any pattern records the last pattern it drew; two of them blend (their
    kind agrees), and a network of one pattern does not blend with one of any."""
    from splitcam.recon.loading import ModelError
    from splitcam.training.models import blend_models

    model, data = tiny_universal
    settings = {"pattern.name": "random", "network.arch": "universal", "optim.steps": 3}
    train(tiny_config(data, tmp_path / "run", **settings, **{"run.seed": 7}), progress=False)
    other = export_model(tmp_path / "run", tmp_path / "other")
    assert load_model(model).meta["pattern"] != load_model(other).meta["pattern"]
    blended = load_model(blend_models(model, other, 0.5, tmp_path / "b", storage="float32"))
    one, two = load_model(model).network.state_dict(), load_model(other).network.state_dict()
    key = next(k for k, _ in load_model(model).network.named_parameters())
    torch.testing.assert_close(blended.network.state_dict()[key], (one[key] + two[key]) / 2)
    fixed = tmp_path / "fixed"
    train(tiny_config(data, fixed, **{"optim.steps": 2}), progress=False)
    with pytest.raises(ModelError, match="different networks|different patterns"):
        blend_models(model, export_model(fixed, tmp_path / "fixed-model"), 0.5, tmp_path / "c")


def test_a_network_trained_on_from_a_blend_keeps_the_blend_on_record(
    trained_run, run_images, tmp_path
):
    """Its provenance's segments are no chain (the blend's two ends are in them), so a run
    from a blend records the blend, which its recipe replays before its own stage."""
    from splitcam.training.models import blend_models

    start = export_model(trained_run, tmp_path / "start")
    blended = blend_models(start, start, 0.5, tmp_path / "blend")
    assert load_model(blended).meta["provenance"]["validation"] == []  # never validated
    run = tmp_path / "after"
    train(small_config(run_images, run, **{"run.init_from": str(blended)}), progress=False)
    after = load_model(export_model(run, tmp_path / "after-model")).meta
    assert after["provenance"]["from_blend"]["weight"] == 0.5
    assert after["provenance"]["total_steps"] == 8
    # the ends ran from no configuration file: the refusal names the blend's end
    with pytest.raises(ConfigError, match="after, its blend's start: segment 1"):
        shipped_recipe(after, "after")


def test_a_blend_refuses_models_of_different_patterns_light_or_a_weight_off_the_line(
    trained_run, run_images, tmp_path
):
    from splitcam.recon.loading import ModelError
    from splitcam.training.models import blend_models

    other = tmp_path / "other"
    train(small_config(run_images, other, **{"pattern.name": "bayer"}), progress=False)
    start = export_model(trained_run, tmp_path / "start")
    end = export_model(other, tmp_path / "end")
    with pytest.raises(ModelError, match="different patterns"):
        blend_models(start, end, 0.5, tmp_path / "b")
    # the shipped Bayer networks: one in photo-electrons in linear light, one in sRGB values
    with pytest.raises(ModelError, match="linear light with photon noise and bayer in srgb"):
        blend_models("bayer-photon", "bayer", 0.5, tmp_path / "b")
    with pytest.raises(ModelError, match=r"in \[0, 1\]"):
        blend_models(start, start, 1.5, tmp_path / "b")
    assert not (tmp_path / "b.json").exists()
