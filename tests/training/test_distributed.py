"""torchrun with 2 CPU processes (gloo): different patches per rank, identical models, resume."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from splitcam import patterns
from splitcam.io import checkpoints as ckpt_io


@pytest.fixture
def images(tmp_path):
    rng = np.random.default_rng(1)
    folder = tmp_path / "images"
    folder.mkdir()
    for i in range(6):
        img = np.kron(rng.random((4, 4, 3)), np.ones((10, 10, 1)))
        Image.fromarray((img * 255).astype(np.uint8)).save(folder / f"im{i}.png")
    return folder


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _torchrun(images, out, steps, *extra):
    torchrun = shutil.which("torchrun", path=os.path.dirname(sys.executable))
    if torchrun is None:
        pytest.skip("torchrun not installed beside this Python")
    argv = [
        torchrun,
        "--nproc_per_node",
        "2",
        "--master_addr",
        "127.0.0.1",
        "--master_port",
        str(_free_port()),
        "-m",
        "splitcam",
        "train",
        "--data",
        str(images),
        "--patch-size",
        "16",
        "--batch-size",
        "2",
        "--features",
        "4",
        "--blocks",
        "1",
        "--steps",
        str(steps),
        "--log-every",
        "1",
        "--checkpoint-every",
        "2",
        "--threads",
        "1",
        "--device",
        "cpu",
        "--out",
        str(out),
        "--quiet",
        *extra,
    ]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # Every rank ends the same way (a final barrier, then the process group's teardown): no
    # rank aborts at exit with gloo threads still running.
    assert "terminate called" not in proc.stderr, proc.stderr[-3000:]
    return proc


@pytest.mark.slow
@pytest.mark.integration
def test_two_processes_train_in_sync_and_resume(images, tmp_path):
    out = tmp_path / "ddp"
    _torchrun(images, out, 3, "--learn-pattern", "--pattern", "A", "--pattern-lr", "0.05")
    ckpt = ckpt_io.load(out)
    assert ckpt.meta["world_size"] == 2 and ckpt.meta["step"] == 3
    replicas = ckpt.meta["replicas"]
    a, b = replicas["model_fingerprints"]
    assert a == b  # identical network and pattern on both ranks
    s0, s1 = replicas["batch_sums"]
    assert s0 != s1  # each rank drew its own patches
    assert {"rng/sampler/0", "rng/sampler/1"} <= ckpt.tensors.keys()
    learned = patterns.load(out / "pattern.toml")
    assert not learned.equals(patterns.get("A"), atol=1e-4)
    np.testing.assert_allclose(learned.kernels.sum(axis=(2, 3)), 1.0, atol=1e-6)
    # Only rank 0 writes logs: one line per step.
    lines = (out / "metrics.jsonl").read_text().splitlines()
    assert len([line for line in lines if '"loss"' in line]) == 3
    _torchrun(images, out, 5, "--resume")
    resumed = ckpt_io.load(out)
    assert resumed.meta["step"] == 5
    a, b = resumed.meta["replicas"]["model_fingerprints"]
    assert a == b
