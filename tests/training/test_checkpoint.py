"""Loading a run's system (splitcam.training.checkpoint): headers that lack a key, NaN weights."""

from __future__ import annotations

import json

import pytest
from conftest import tiny_config

from splitcam.cli import main
from splitcam.io import checkpoints as ckpt_io
from splitcam.training import CheckpointError, load_system, train


def test_checkpoint_headers_without_network_and_nan_weights_are_named(image_folder, tmp_path):
    from safetensors.torch import save_file

    train(tiny_config(image_folder, tmp_path / "r", **{"optim.steps": 1}), progress=False)
    ckpt = ckpt_io.load(tmp_path / "r")
    header = {k: v for k, v in ckpt.meta.items() if k != "network"}
    bad = tmp_path / "no_network.safetensors"
    save_file(ckpt.tensors, str(bad), metadata={"splitcam": json.dumps(header)})
    with pytest.raises(CheckpointError, match="no_network.safetensors.*no 'network'"):
        load_system(bad)
    header = {k: v for k, v in ckpt.meta.items() if k != "pattern"}
    save_file(ckpt.tensors, str(bad), metadata={"splitcam": json.dumps(header)})
    with pytest.raises(CheckpointError, match="no_network.safetensors.*no 'pattern'"):
        load_system(bad)
    # Resuming needs more of the header: each missing key is named, with the file.
    for missing in ("config", "step", "optimizer"):
        run = tmp_path / f"lacks_{missing}"
        run.mkdir()
        header = {k: v for k, v in ckpt.meta.items() if k != missing}
        save_file(
            ckpt.tensors,
            str(run / ckpt_io.CHECKPOINT_NAME),
            metadata={"splitcam": json.dumps(header)},
        )
        with pytest.raises(CheckpointError, match=f"lacks_{missing}.*no '{missing}' in its header"):
            train(tiny_config(image_folder, run, **{"optim.steps": 2}), resume=True, progress=False)
    assert main(["train", "--out", str(tmp_path / "lacks_config"), "--resume", "--quiet"]) == 1
    tensors = dict(ckpt.tensors)
    key = next(k for k in tensors if k.startswith("model/network") and k.endswith("weight"))
    tensors[key] = tensors[key].clone()
    tensors[key].view(-1)[0] = float("nan")
    nan = tmp_path / "nan.safetensors"
    save_file(tensors, str(nan), metadata={"splitcam": json.dumps(ckpt.meta)})
    with pytest.raises(CheckpointError, match=f"nan.safetensors.*NaN.*{key}"):
        load_system(nan)
