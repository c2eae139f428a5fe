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
@pytest.mark.slow  # 15 s; .ci/run also builds the site strictly before the tests
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


def test_the_api_reference_has_every_public_module() -> None:
    """Each module of a subpackage (not ``_private``) has its ``:::`` entry in
    ``docs/api/<subpackage>.md``, so a new module cannot be left out of the reference."""
    package = REPO / "src" / "splitcam"
    missing = []
    for page in sorted((REPO / "docs" / "api").glob("*.md")):
        folder = package / page.stem
        if not folder.is_dir():
            continue
        text = page.read_text(encoding="utf-8")
        for module in sorted(folder.glob("*.py")):
            name = f"splitcam.{page.stem}.{module.stem}"
            if not module.stem.startswith("_") and f"::: {name}\n" not in text + "\n":
                missing.append(name)
    assert not missing, f"not in docs/api: {missing}"


def test_the_navigation_holds_every_results_page() -> None:
    """Every page under docs/results is in mkdocs.yml's navigation (67 once were not)."""
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    root = REPO / "docs"
    pages = sorted(p.relative_to(root).as_posix() for p in (root / "results").rglob("*.md"))
    missing = [p for p in pages if f"- {p}\n" not in nav and f": {p}\n" not in nav]
    assert not missing, f"not in mkdocs.yml's nav: {missing}"
