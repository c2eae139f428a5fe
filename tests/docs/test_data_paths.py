"""The project reads whole without the folder it was built beside: pages, examples,
configurations, studies and code name data through the data registry ($SPLITCAM_DATA, the
download cache), never a sibling folder's path."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("docs", "examples", "experiments", "studies", "benchmarks", "scripts", "src")
SUFFIXES = {".md", ".py", ".toml", ".sh", ".txt", ".yml", ".yaml"}


def test_no_file_names_a_sibling_data_folder():
    sibling = "../" + "shared"  # written apart so that this file does not name it
    absolute = "/shared/" + "data"  # the same folder by a machine's absolute path
    found = []
    for folder in FOLDERS:
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in SUFFIXES and path.is_file():
                text = path.read_text(encoding="utf-8", errors="replace")
                if sibling in text or absolute in text:
                    found.append(str(path.relative_to(ROOT)))
    for name in ("README.md", "mkdocs.yml", "pyproject.toml"):
        if sibling in (ROOT / name).read_text(encoding="utf-8"):
            found.append(name)
    assert not found, f"files that name a sibling data folder: {found}"
