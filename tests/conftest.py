"""Shared test settings: the tests directory is importable (naive_reference), data paths."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
sys.path.insert(0, str(TESTS))
SHARED_DATA = TESTS.parent.parent / "shared" / "data"


@pytest.fixture
def shared_data() -> Path:
    """``../shared/data`` beside the repository; tests using it skip where it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture
def photo(tmp_path):
    """A random 10x12 RGB photo ``photo.png`` in ``tmp_path``, and its pixels."""
    import numpy as np
    from PIL import Image

    rng = np.random.default_rng(0)
    arr = rng.integers(0, 256, size=(10, 12, 3), dtype=np.uint8)
    path = tmp_path / "photo.png"
    Image.fromarray(arr).save(path)
    return path, arr


#: A training run small enough for a test: 16-pixel patches, an 8-feature one-block network,
#: validation on 2 held-out images.
TINY_SETTINGS = {
    "data.val_split": 2,
    "data.val_max_images": 2,
    "data.val_crop": 32,
    "data.patch_size": 16,
    "data.batch_size": 4,
    "network.features": 8,
    "network.blocks": 1,
    "optim.steps": 6,
    "optim.lr": 1e-3,
    "optim.warmup_steps": 5,
    "run.log_every": 1,
    "run.val_every": 3,
    "run.checkpoint_every": 3,
    "run.threads": 1,
}


def blocky_images(folder: Path, count: int, seed: int = 0) -> Path:
    """``count`` smooth random 48x48 colour images (learnable in a few steps) in ``folder``."""
    import numpy as np
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for i in range(count):
        img = np.kron(rng.random((6, 6, 3)), np.ones((8, 8, 1)))
        Image.fromarray((img * 255).astype(np.uint8)).save(folder / f"im{i}.png")
    return folder


def tiny_config(folder: Path, out: Path, **changes):
    """A :class:`TrainConfig` of :data:`TINY_SETTINGS` on ``folder`` into ``out``."""
    from splitcam.training import TrainConfig

    settings = {**TINY_SETTINGS, "data.train": str(folder), "run.out": str(out), **changes}
    return TrainConfig().override(settings)
