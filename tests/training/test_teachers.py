"""Shipped per-pattern networks as a second target (splitcam.training.teachers,
``optim.teacher_weight``)."""

from __future__ import annotations

import pytest
import torch
from conftest import tiny_config

from splitcam import patterns
from splitcam.io import checkpoints as ckpt_io
from splitcam.physics.noise import GaussianNoise
from splitcam.physics.sensor import SplitterSensor
from splitcam.physics.system import ImagingSystem
from splitcam.recon.loading import load_model
from splitcam.recon.networks import UniversalReconNet
from splitcam.training import train
from splitcam.training.config import ConfigError
from splitcam.training.teachers import Teachers


def test_the_teacher_sees_the_students_raw_image():
    D, rgbw = patterns.get("D"), patterns.get("rgbw")
    teachers = Teachers.shipped([D, rgbw], "srgb", torch.device("cpu"))
    assert teachers.names == ["D"]  # rgbw has no shipped network of its own
    assert Teachers.shipped([D], "linear", torch.device("cpu")).names == ["D"]
    student = UniversalReconNet(features=8, blocks=1)
    system = ImagingSystem(SplitterSensor(D), student)
    teachers.watch(student)
    seen = []
    student.register_forward_pre_hook(lambda module, args: seen.append(args))
    noise = GaussianNoise(10.0, seed=0)
    system(torch.rand(2, 3, 16, 16), noise)
    raw, sigma, kernels = seen[0]
    shipped = load_model("D").network
    torch.testing.assert_close(teachers.estimate(D), shipped(raw, sigma, kernels))
    assert teachers.estimate(rgbw) is None


def test_a_teacher_changes_the_update(image_folder, tmp_path):
    settings = {"pattern.name": "D", "optim.steps": 1, "optim.warmup_steps": 0}
    train(tiny_config(image_folder, tmp_path / "plain", **settings), progress=False)
    taught = {**settings, "optim.teacher_weight": 1.0}
    train(tiny_config(image_folder, tmp_path / "taught", **taught), progress=False)
    plain = ckpt_io.load(tmp_path / "plain").section("model")
    other = ckpt_io.load(tmp_path / "taught").section("model")
    assert any(not torch.equal(plain[k], other[k]) for k in plain)
    with pytest.raises(ConfigError, match="shipped per-pattern"):
        train(
            tiny_config(image_folder, tmp_path / "x", **{**taught, "pattern.name": "rgbw"}),
            progress=False,
        )
