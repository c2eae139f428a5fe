"""The commands the documentation shows exist: every ``splitcam ...`` line of README.md,
docs/commands.md and experiments/README.md names a command (and subcommand) that the parser has,
and every ``--flag`` it uses is one of that command's options."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

from splitcam.cli import build_parser

REPO = Path(__file__).resolve().parents[2]
PAGES = ["README.md", "docs/commands.md", "experiments/README.md"]


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _command_lines(text: str) -> list[str]:
    """Every shell line of the fenced code blocks that runs ``splitcam`` (continuations joined,
    comments and environment assignments dropped)."""
    lines = []
    for block in re.findall(r"```(?:bash|sh)?\n(.*?)```", text, flags=re.S):
        joined = block.replace("\\\n", " ")
        for line in joined.splitlines():
            line = line.split("  #")[0].split(" # ")[0].strip()
            if "splitcam " not in line or line.startswith("#"):
                continue
            for part in re.split(r"&&|\|", line):
                part = part.strip()
                words = part.split()
                while words and "=" in words[0] and not words[0].startswith("-"):
                    words.pop(0)  # SPLITCAM_DATA=DIR and the like
                if words and words[0] == "splitcam":
                    lines.append(" ".join(words))
    return lines


def test_every_documented_command_and_flag_exists():
    root = build_parser()
    commands = _subparsers(root)
    problems = []
    for page in PAGES:
        for line in _command_lines((REPO / page).read_text(encoding="utf-8")):
            try:
                words = shlex.split(line)
            except ValueError:
                words = line.split()
            parser = commands.get(words[1]) if len(words) > 1 else None
            if parser is None:
                problems.append(f"{page}: {line!r}: no command {words[1:2]}")
                continue
            sub = _subparsers(parser)
            if len(words) > 2 and words[2] in sub:
                parser = sub[words[2]]
            known = {o for a in parser._actions for o in a.option_strings}
            for word in words[2:]:
                flag = word.split("=")[0]
                if flag.startswith("--") and flag not in known:
                    problems.append(f"{page}: {line!r}: {flag} is not an option")
    assert not problems, "\n".join(problems)
