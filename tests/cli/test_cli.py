"""The ``splitcam`` command itself (splitcam.cli): parsing without torch, moved names."""

from __future__ import annotations

import pytest


@pytest.mark.integration
def test_parsing_every_command_imports_no_torch():
    """`splitcam --help` and each command's --help build the parsers only: no torch, numpy or
    matplotlib is imported (checked in a fresh interpreter, where nothing is imported yet)."""
    import subprocess
    import sys

    from splitcam.cli import COMMANDS

    code = (
        "import sys, contextlib, io\n"
        "from splitcam.cli import build_parser\n"
        "parser = build_parser()\n"
        f"for argv in [['--help'], *[[c, '--help'] for c in {list(COMMANDS)!r}]]:\n"
        "    with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "        try:\n"
        "            parser.parse_args(argv)\n"
        "        except SystemExit:\n"
        "            pass\n"
        "    assert 'usage: splitcam' in out.getvalue(), argv\n"
        "print(sorted(m for m in ('torch', 'numpy', 'matplotlib') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
