"""`splitcam patterns`: list, draw or export splitter patterns."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import pattern_or_model, table

ACTIONS = ("list", "show", "export")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "patterns",
        help="list, draw or export splitter patterns",
        description="`splitcam patterns` prints the design-principle measures of every pattern; "
        "`patterns show D --out d.png` draws one; `patterns export D --out d.toml` writes its "
        "pattern file (a starting point for your own).",
    )
    p.add_argument(
        "words",
        nargs="*",
        metavar="[list|show|export] PATTERN",
        help="an action (default list) and pattern names or files: `patterns D E` lists D and E",
    )
    p.add_argument("--out", help="output file (PNG for show, .json/.toml for export)")
    p.add_argument(
        "--force",
        action="store_true",
        help="export: replace an existing --out that holds something else (your edits)",
    )
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from .. import patterns

    words = list(args.words)
    args.action = words.pop(0) if words and words[0] in ACTIONS else "list"
    args.names = words
    if args.action == "list":
        names = args.names or patterns.names()
        rows = []
        for name in names:
            p = pattern_or_model(name)
            rows.append({**patterns.measure(p).row(), "provenance": p.provenance})
        print(table(rows))
        return 0
    if len(args.names) != 1:
        raise ValueError(f"'patterns {args.action}' takes one pattern name or file")
    pattern = pattern_or_model(args.names[0])
    if args.action == "show":
        from ..viz.patterns import draw_pattern

        out = Path(args.out or f"pattern_{pattern.name}.png")
        draw_pattern(pattern, out)
        print(f"wrote {out}")
    else:
        out = Path(args.out or f"{pattern.name}.toml")
        if out.exists() and not args.force:
            # An exported file is there to be edited: exporting again must not undo the edits.
            import tempfile

            with tempfile.TemporaryDirectory() as tmp:
                fresh = Path(tmp) / out.name
                patterns.save(pattern, fresh)
                if fresh.read_bytes() == out.read_bytes():
                    print(f"{out} already holds this pattern")
                    return 0
            raise ValueError(f"{out} exists and holds something else; --force replaces it")
        patterns.save(pattern, out)
        print(f"wrote {out}")
    return 0
