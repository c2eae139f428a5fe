"""MkDocs hooks of the site (mkdocs.yml): links that leave ``docs/``, and Sphinx roles.

Links out of ``docs/``: the home page includes ``README.md``, whose links reach files beside
``docs/`` (``experiments/README.md``). The site is built into ``site/``, a sibling of ``docs/``,
so the same relative link from the built page still reaches the file in the checkout; such a
link is written as raw HTML, which MkDocs does not check. A link whose target does not exist is
left alone, so the strict build still fails on it.

The examples gallery: where ``examples/README.md`` exists (beside ``docs/``), it becomes the
page ``examples.md`` of the site, after Results in the navigation, its links made relative to
``docs/``; where it does not, the site has no Examples page.

Sphinx roles: the docstrings name other objects as ``:func:`build_method```. mkdocstrings does
not resolve them and Markdown renders the role's text before the code span; the role text is
dropped so the page reads ``build_method`` (``~a.b.C``: ``C``, as Sphinx shows it).
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

_LINK = re.compile(r"(?<!!)\[([^\]\n]*)\]\(([^)\s]+)\)")
_ANY_LINK = re.compile(r"!?\[([^\]\n]*)\]\(([^)\s]+)\)")
_ROLE = re.compile(
    r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const):<code>(~?)([^<]*)</code>"
)


def _outside(target: str, page_dir: Path, docs_dir: Path) -> bool:
    """Whether a relative link target lies outside ``docs_dir`` and exists on disk."""
    if re.match(r"^[a-z][a-z0-9+.-]*:|^/|^#", target):
        return False
    path = (page_dir / posixpath.normpath(target.split("#", 1)[0])).resolve()
    return not path.is_relative_to(docs_dir) and path.exists()


def _examples(config) -> Path:
    return Path(config["docs_dir"]).resolve().parent / "examples" / "README.md"


def on_config(config):
    nav = config["nav"]
    if nav is not None and _examples(config).is_file():
        titles = [next(iter(entry)) for entry in nav if isinstance(entry, dict)]
        at = titles.index("Results") + 1 if "Results" in titles else len(nav)
        nav.insert(at, {"Examples": "examples.md"})
    return config


def on_files(files, config):
    from mkdocs.structure.files import File

    readme = _examples(config)
    if readme.is_file():

        def rebase(match: re.Match) -> str:
            text, target = match.groups()
            if re.match(r"^[a-z][a-z0-9+.-]*:|^/|^#", target):
                return match.group(0)
            path, hash_, anchor = target.partition("#")
            path = posixpath.normpath(posixpath.join("../examples", path))
            if path.startswith("../docs/"):  # a page of the site itself
                path = path[len("../docs/") :]
            return match.group(0).replace(f"]({target})", f"]({path}{hash_}{anchor})")

        text = _ANY_LINK.sub(rebase, readme.read_text(encoding="utf-8"))
        files.append(File.generated(config, "examples.md", content=text))
    return files


def on_page_markdown(markdown, page, config, files):
    docs_dir = Path(config["docs_dir"]).resolve()
    page_dir = (docs_dir / page.file.src_uri).parent

    def rewrite(match: re.Match) -> str:
        text, target = match.groups()
        if not _outside(target, page_dir, docs_dir):
            return match.group(0)
        return f'<a href="{target}">{text}</a>'

    return _LINK.sub(rewrite, markdown)


def _role(match: re.Match) -> str:
    tilde, name = match.groups()
    return f"<code>{name.rsplit('.', 1)[-1] if tilde else name}</code>"


def on_page_content(html, **kwargs):
    return _ROLE.sub(_role, html)
