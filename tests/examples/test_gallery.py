"""The examples gallery (``examples/``): every script runs on tiny settings and writes the
figures it promises.

Each script runs as a subprocess, as a user runs it (``python examples/NN_name.py --tiny
--out DIR``), on one thread; each figure must be a PNG that PIL opens, of a sensible size.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

#: Every script of the gallery and the figures it writes into ``--out``.
FIGURES = {
    "01_compare_patterns.py": ["patterns_psnr.png"],
    "02_your_own_pattern.py": ["own_patterns.png", "own_patterns_psnr.png"],
    "03_design_pattern.py": ["design.png", "design_curve.png"],
    "04_train_and_evaluate.py": ["curves.png"],
    "05_filters_vs_routers.py": ["exposure.png"],
    "06_metasurface_router.py": ["heights.png", "router.png"],
    "07_deepinv_solver.py": ["deepinv.png"],
}


def test_every_script_is_listed():
    assert sorted(p.name for p in EXAMPLES.glob("[0-9][0-9]_*.py")) == sorted(FIGURES)


def test_the_readme_lists_every_script():
    readme = (EXAMPLES / "README.md").read_text(encoding="utf-8")
    assert all(name in readme for name in FIGURES)
    assert all(f in readme for figures in FIGURES.values() for f in figures)


def _why_deepinv_cannot_run() -> str | None:
    """Where deepinv cannot run here, the line the integration says why in (else None)."""
    if importlib.util.find_spec("deepinv") is None:
        return "needs deepinv, an optional dependency: pip install 'splitcam[deepinv]'"
    from splitcam.integrations._torchvision import torchvision_mismatch

    return torchvision_mismatch()


@pytest.mark.slow
@pytest.mark.integration
@pytest.mark.parametrize("script", sorted(FIGURES))
def test_script_runs_tiny_and_writes_its_figures(script, tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    env.pop("SPLITCAM_DATA", None)
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / script), "--tiny", "--out", str(out)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    if script == "07_deepinv_solver.py":
        reason = _why_deepinv_cannot_run()
        if reason is not None:
            # It cannot run: one line saying why, with the fix, and a failing status.
            assert done.returncode == 1, done.stdout + done.stderr
            assert "cannot run here" in done.stderr and reason in done.stderr, done.stderr
            assert len(done.stderr.strip().splitlines()) == 1
            pytest.skip(f"the script said why it cannot run and exited 1: {reason}")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.strip(), "a gallery script prints what it found"
    for name in FIGURES[script]:
        path = out / name
        assert path.is_file() and path.stat().st_size > 0, f"{script} did not write {name}"
        with Image.open(path) as image:
            assert image.format == "PNG"
            image.load()
            width, height = image.size
        assert 200 <= width <= 4000 and 150 <= height <= 4000, (name, image.size)
    assert not (tmp_path / "examples-out").exists()  # --out is where everything goes


@pytest.mark.slow
@pytest.mark.integration
def test_default_output_folder_is_examples_out_under_the_working_directory(tmp_path):
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "03_design_pattern.py"), "--tiny"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "examples-out" / "03" / "design.png").is_file()
