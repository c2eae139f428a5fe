"""The checkpoint format (splitcam.io.checkpoints): damaged and foreign checkpoints are refused."""

from __future__ import annotations

import pytest
import torch
from conftest import tiny_config

from splitcam.io import checkpoints as ckpt_io
from splitcam.training import CheckpointError, ConfigError, load_system, train


def test_damaged_and_foreign_checkpoints_are_refused(image_folder, tmp_path):
    train(tiny_config(image_folder, tmp_path / "r", **{"optim.steps": 2}), progress=False)
    path = tmp_path / "r" / ckpt_io.CHECKPOINT_NAME
    data = path.read_bytes()
    # The header alone gives the same meta as the whole file (what sweep status reads).
    assert ckpt_io.read_meta(path) == ckpt_io.load(path).meta
    assert ckpt_io.read_meta(path)["step"] == 2
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="damaged"):
        ckpt_io.load(path)
    with pytest.raises(CheckpointError, match="damaged"):
        train(tiny_config(image_folder, tmp_path / "r"), resume=True, progress=False)
    path.write_bytes(b"\x00" * 64)
    with pytest.raises(CheckpointError, match="damaged"):
        ckpt_io.read_meta(path)
    with pytest.raises(CheckpointError, match="damaged"):
        load_system(tmp_path / "r")
    path.write_bytes(data)
    with pytest.raises(CheckpointError, match="network.features=8, got 16"):
        train(
            tiny_config(image_folder, tmp_path / "r", **{"network.features": 16}),
            resume=True,
            progress=False,
        )
    ckpt = ckpt_io.load(path)
    bigger = torch.nn.Conv2d(1, 1, 3)
    with pytest.raises(CheckpointError, match="another architecture"):
        ckpt_io.load_module(bigger, ckpt)
    with pytest.raises(CheckpointError, match="no checkpoint"):
        ckpt_io.load(tmp_path / "nothing")
    with pytest.raises(ConfigError, match="already holds a checkpoint"):
        train(tiny_config(image_folder, tmp_path / "r"), progress=False)
