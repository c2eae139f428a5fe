"""Loading models (splitcam.recon.loading): shipped names, damaged or edited files, ambiguous
names."""

from __future__ import annotations

import json

import pytest
import torch
from conftest import blocky_images, tiny_config

from splitcam.cli import main
from splitcam.io import weights as io_weights
from splitcam.recon.loading import ModelError, load_model, model_names
from splitcam.recon.registry import build_method, build_model
from splitcam.training import train
from splitcam.training.models import export_model


def test_shipped_names_resolve_and_unknown_names_list_them(trained_run, tmp_path, monkeypatch):
    monkeypatch.setattr(io_weights, "MODELS_DIR", tmp_path)
    export_model(trained_run, tmp_path / "D", name="D")
    export_model(trained_run, tmp_path / "D-opt", name="D-opt")
    assert model_names() == ["D", "D-opt"]
    method = build_method("D-opt")
    assert method.name == "net-D-opt"
    with pytest.raises(ModelError, match="shipped models: D, D-opt"):
        load_model("Q")
    with pytest.raises(ValueError, match=r"shipped model \(D, D-opt\)"):
        build_method("nonsense")
    # Deterministic: the same reconstruction twice.
    raw = torch.rand(1, 1, 20, 20, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        assert torch.equal(method.reconstruct(raw, 5.0), build_method("D").reconstruct(raw, 5.0))


def test_damaged_model_files_are_refused(trained_run, tmp_path):
    path = export_model(trained_run, tmp_path / "m")
    blob = bytearray(path.with_suffix(".safetensors").read_bytes())
    blob[-3] ^= 0xFF
    path.with_suffix(".safetensors").write_bytes(bytes(blob))
    with pytest.raises(ModelError, match="checksum"):
        load_model(path)
    path.write_text("{not json")
    with pytest.raises(ModelError, match="not valid JSON"):
        load_model(path)


def test_a_name_that_is_both_a_shipped_model_and_a_folder_is_refused(
    photo, tmp_path, monkeypatch, capsys
):
    """`--checkpoint D` with ./D a run folder (sweep names them so): an error showing both, and
    each still reachable by its unambiguous name."""
    from splitcam.recon.loading import ModelError, model_names
    from splitcam.recon.registry import build_method

    assert "D" in model_names()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "D").mkdir()
    with pytest.raises(ModelError, match=r"shipped model D and the run folder ./D"):
        build_method("D")
    path, _ = photo
    args = ["reconstruct", "--image", str(path), "--out", str(tmp_path / "r.png")]
    assert main([*args, "--checkpoint", "D"]) == 1
    err = capsys.readouterr().err
    assert "ambiguous" in err and "--model D" in err and "./D" in err
    assert main([*args, "--model", "D", "--quiet"]) == 0  # the shipped one, by its flag


def test_an_edited_model_file_is_refused_and_old_files_are_fingerprinted_by_their_fields(
    tmp_path,
):
    """An edited `radius` cost 5.2 dB without an error; now the fields carry a checksum."""

    from splitcam.io.tensorfiles import meta_checksum
    from splitcam.recon.loading import ModelError, load_model
    from splitcam.training.models import export_model

    data = blocky_images(tmp_path / "img", 5)
    train(tiny_config(data, tmp_path / "run", **{"optim.steps": 2}), progress=False)
    path = export_model(tmp_path / "run", tmp_path / "m")
    meta = json.loads(path.read_text())
    assert meta["meta_sha256"] == meta_checksum(meta)
    first = build_model(path).fingerprint
    edited = {**meta, "network": {**meta["network"], "radius": 2}}
    path.write_text(json.dumps(edited))
    with pytest.raises(ModelError, match="changed after it was written"):
        load_model(path)
    # The checksum deleted: refused, since every file of this version carries one.
    del edited["meta_sha256"]
    path.write_text(json.dumps(edited))
    with pytest.raises(ModelError, match="lacks the checksum of its fields"):
        load_model(path)
    # A file from before the field checksum (version 1): loads, and its fingerprint follows
    # every field, so an edit of any field is another model.
    old = {**meta, "version": 1}
    del old["meta_sha256"]
    path.write_text(json.dumps(old))
    before = build_model(path).fingerprint
    for field, value in [("network", {**meta["network"], "radius": 2}), ("description", "x")]:
        path.write_text(json.dumps({**old, field: value}))
        assert build_model(path).fingerprint not in (before, first)
    # The shipped files all carry it.
    from splitcam.io.weights import MODELS_DIR

    for shipped in MODELS_DIR.glob("*.json"):
        stored = json.loads(shipped.read_text())
        assert stored["meta_sha256"] == meta_checksum(stored), shipped.name
        assert stored["version"] == 2, shipped.name
