"""The documentation site (mkdocs.yml) builds with warnings as errors and holds the API reference.

A broken link, a docstring griffe cannot parse or a parameter documented under a wrong name fails
``mkdocs build --strict``; this test runs that build as a user does, into a temporary folder.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.integration
def test_site_builds_strict_with_the_api_reference(tmp_path: Path) -> None:
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    pytest.importorskip("material")
    pytest.importorskip("mkdocs_include_markdown_plugin")
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    recon = (site / "api" / "recon.html").read_text(encoding="utf-8")
    assert "build_method" in recon
    assert "Reconstructor" in recon
    assert 'id="splitcam.recon.registry.build_method"' in recon
    assert 'id="splitcam.recon.base.Reconstructor"' in recon
    # The Sphinx roles of the docstrings read as plain code (docs/api/hooks.py).
    assert ":func:<code>" not in recon and ":class:<code>" not in recon
    assert (site / "index.html").is_file()
