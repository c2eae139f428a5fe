"""Shared test settings and fixtures for every folder below ``tests/``.

The tests directory is put on ``sys.path``, so any test module, in any subfolder, can import
``conftest`` (the helpers below), ``naive_reference`` and ``mirror``. Fixtures that train a run
are session-scoped: trained once, read by the tests of every folder.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
sys.path.insert(0, str(TESTS))
REPO = TESTS.parent


#: The data root the tests read photos from (the test sets and the training photos), found the
#: way the package finds it: ``$SPLITCAM_DATA`` or the download cache
#: (:func:`splitcam.data.registry.data_root`). Tests that need it skip where it is absent.
def _data_root() -> Path:
    from splitcam.data.registry import data_root

    return data_root()


SHARED_DATA = _data_root()


def fresh_modules(code: str) -> set[str]:
    """The modules a fresh interpreter has loaded after running ``code``."""
    import subprocess

    script = f"import sys\n{code}\nprint(' '.join(sys.modules))"
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    return set(result.stdout.split())


@pytest.fixture(autouse=True)
def _no_data_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """A user's SPLITCAM_DATA or SPLITCAM_MIRROR must not change what the tests see."""
    from splitcam.data import registry

    monkeypatch.delenv(registry.DATA_ENV, raising=False)
    monkeypatch.delenv(registry.MIRROR_ENV, raising=False)


@pytest.fixture(scope="session", autouse=True)
def _own_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The precision choices the tests measure go to a folder of the session's, not the user's
    cache (:mod:`splitcam.recon.precision`)."""
    import os

    from splitcam.recon.precision import CACHE_ENV

    os.environ[CACHE_ENV] = str(tmp_path_factory.mktemp("cache"))


@pytest.fixture
def shared_data() -> Path:
    """The data root (:data:`SHARED_DATA`); tests using it skip where it is absent."""
    if not (SHARED_DATA / "kodak24").is_dir() and not (SHARED_DATA / "train").is_dir():
        pytest.skip(f"no datasets under {SHARED_DATA} (set SPLITCAM_DATA; splitcam data download)")
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


def random_images(n: int = 2, size: tuple[int, int] = (20, 24)) -> list:
    """``[(f"img{i}", (3, H, W) uniform noise)]``, the same every call (seed 0)."""
    import torch

    gen = torch.Generator().manual_seed(0)
    return [(f"img{i}", torch.rand(3, *size, generator=gen)) for i in range(n)]


def write_photos(folder: Path, n: int = 2, size: tuple[int, int] = (40, 44)) -> Path:
    """:func:`random_images` as 8-bit PNG files ``img<i>.png`` in a new ``folder``."""
    import numpy as np
    from PIL import Image

    folder.mkdir()
    for name, img in random_images(n, size=size):
        array = (img.permute(1, 2, 0).numpy() * 255).astype(np.uint8)
        Image.fromarray(array).save(folder / f"{name}.png")
    return folder


class Spy:
    """A method that records the raw images it is given and returns a fixed guess."""

    def __init__(self, name: str, pattern: str = "D") -> None:
        from splitcam import patterns

        self.name = name
        self.pattern = patterns.get(pattern)
        self.seen: list = []

    def reconstruct(self, raw, sigma: float):
        self.seen.append(raw.clone())
        return raw.expand(-1, 3, -1, -1) / 4


def blocky_images(folder: Path, count: int, seed: int = 0, blocks: int = 6) -> Path:
    """``count`` smooth random colour images of ``blocks`` x ``blocks`` blocks of 8x8 pixels
    (48x48 by default; learnable in a few steps) in ``folder``."""
    import numpy as np
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for i in range(count):
        img = np.kron(rng.random((blocks, blocks, 3)), np.ones((8, 8, 1)))
        Image.fromarray((img * 255).astype(np.uint8)).save(folder / f"im{i}.png")
    return folder


def odd_photos(folder: Path, count: int, size: tuple[int, int], seed: int = 0) -> Path:
    """``count`` smooth photos of odd sides, ``size`` and its transpose in turn (held out whole,
    they end part-way through periods), each a different mix of sines plus a little noise."""
    import numpy as np
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for i in range(count):
        h, w = size if i % 2 else size[::-1]
        y, x = np.mgrid[0:h, 0:w] / (h / 2)
        base = np.stack([np.sin(x * (i + 1)), np.cos(y * 2), np.sin(x + y)], -1)
        img = 127 + 90 * base + rng.normal(0, 4, (h, w, 3))
        Image.fromarray(img.clip(0, 255).astype(np.uint8)).save(folder / f"p{i:02d}.png")
    return folder


def tiny_config(folder: Path, out: Path, **changes):
    """A :class:`TrainConfig` of :data:`TINY_SETTINGS` on ``folder`` into ``out``."""
    from splitcam.training import TrainConfig

    settings = {**TINY_SETTINGS, "data.train": str(folder), "run.out": str(out), **changes}
    return TrainConfig().override(settings)


#: A 4-step run of :data:`TINY_SETTINGS`: what model files, sweeps and the model commands use.
SMALL = {
    **TINY_SETTINGS,
    "optim.steps": 4,
    "optim.warmup_steps": 2,
    "run.val_every": 2,
    "run.checkpoint_every": 2,
}

#: An experiment file's settings: SMALL without the thread count (the sweep sets it).
SWEEP_SMALL = {k: v for k, v in SMALL.items() if k != "run.threads"}


def initial_state(config) -> dict:
    """The state dict (``model/`` keys, as a checkpoint holds them) a run of ``config`` starts
    from: the system built as :func:`splitcam.training.setup.prepare` builds it, after the same
    seeding (a run of zero steps is refused)."""
    import torch

    from splitcam.training import seeds
    from splitcam.training.setup import build_system

    torch.manual_seed(seeds.global_seed(config))
    return {f"model/{k}": v for k, v in build_system(config).state_dict().items()}


def small_config(folder: Path, out: Path, **changes):
    """A :class:`TrainConfig` of :data:`SMALL` on ``folder`` into ``out``."""
    return tiny_config(folder, out, **{**SMALL, **changes})


def experiment_file(folder: Path, name: str, **settings) -> Path:
    """An experiment file ``folder/NAME.toml`` holding ``settings`` (``section.field`` keys)."""
    import json

    lines = []
    sections: dict[str, dict] = {}
    for key, value in settings.items():
        section, _, field = key.partition(".")
        sections.setdefault(section, {})[field] = value
    for section, fields in sections.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in fields.items()]
    path = folder / f"{name}.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="session")
def image_folder(tmp_path_factory) -> Path:
    """Eight smooth random colour images (learnable in a few steps); tests only read them."""
    return blocky_images(tmp_path_factory.mktemp("images"), 8)


@pytest.fixture(scope="session")
def run_images(tmp_path_factory) -> Path:
    """Six smooth random colour images: the training images of :func:`trained_run`."""
    return blocky_images(tmp_path_factory.mktemp("run-images"), 6, seed=3)


@pytest.fixture(scope="session")
def trained_run(run_images, tmp_path_factory) -> Path:
    """The folder of a finished :data:`SMALL` run (pattern D, 4 steps) on ``run_images``."""
    from splitcam.training import train

    out = tmp_path_factory.mktemp("runs") / "d"
    train(small_config(run_images, out), progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_universal(tmp_path_factory):
    """A tiny universal network trained a few steps over random patterns, exported as a model;
    its training images."""
    from splitcam.training import train
    from splitcam.training.models import export_model

    root = tmp_path_factory.mktemp("universal")
    data = blocky_images(root / "img", 6)
    settings = {"pattern.name": "random", "network.arch": "universal", "optim.steps": 3}
    train(tiny_config(data, root / "run", **settings), progress=False)
    model = export_model(root / "run", root / "models" / "uni", name="uni")
    return model, data


@pytest.fixture
def serve():
    """``serve(folder)`` starts a local HTTP mirror of ``folder`` (:class:`mirror.Server`: its
    ``url``, the ``log`` of paths asked for, ``cut_once`` paths to cut short); all are closed
    after the test."""
    from mirror import Server

    servers: list[Server] = []

    def start(root: Path) -> Server:
        servers.append(Server(root))
        return servers[-1]

    yield start
    for server in servers:
        server.close()


def load_script(path: Path, name: str | None = None):
    """A script that is not a package module (a study, ``docs/models.py``), imported from its
    file under ``name`` (default: its stem)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name or path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
