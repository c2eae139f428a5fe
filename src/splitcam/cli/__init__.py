"""The ``splitcam`` command: one module per command, each with ``register`` (its parser) and
``run`` (its handler). Parsing imports no torch (the commands import the library when they run),
so ``splitcam --help`` answers at once.

Errors a user can cause (a bad pattern, an unreadable image, a missing folder) are printed as one
line, ``splitcam <command>: error: ...``, with exit status 1; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
import warnings
from collections.abc import Sequence

from .. import __version__

#: The commands in the order ``splitcam --help`` lists them (module ``splitcam.cli.<name>``).
COMMANDS = (
    "patterns",
    "simulate",
    "train",
    "design",
    "evaluate",
    "report",
    "data",
    "plot",
    "models",
    "sweep",
    "study",
    "optics",
    "reproduce",
    "reconstruct",
)


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (argparse only: no torch is imported)."""
    parser = argparse.ArgumentParser(
        prog="splitcam",
        description="Design and evaluate colour image sensors built on metasurface colour "
        "splitters.",
    )
    parser.add_argument("--version", action="version", version=f"splitcam {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return parser


class _Console(logging.Handler):
    """The library's messages (``logging.getLogger("splitcam...")``) on the console: INFO to
    stdout, WARNING and above to stderr. The stream is looked up per message, so whatever
    ``sys.stdout`` is at the time (a test's capture included) receives it."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            stream = sys.stderr if record.levelno >= logging.WARNING else sys.stdout
            print(self.format(record), file=stream, flush=True)
        except Exception:
            self.handleError(record)


def _one_line_warning(message, category, filename, lineno, line=None) -> str:  # noqa: ARG001
    """A warning on the console as one line (``warning: ...``), not Python's two lines with the
    file and source line of the library's code (the formatting only: what records warnings,
    such as a test, still receives them)."""
    return f"warning: {message}\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``splitcam`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logger = logging.getLogger("splitcam")
    console, level = _Console(), logger.level
    logger.addHandler(console)
    logger.setLevel(logging.INFO)
    formatted = warnings.formatwarning
    warnings.formatwarning = _one_line_warning
    try:
        return args.handler(args)
    except KeyboardInterrupt:
        print(f"splitcam {args.command}: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError, TypeError) as exc:
        if args.debug:
            raise
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"splitcam {args.command}: error: {message}", file=sys.stderr)
        return 1
    finally:
        logger.removeHandler(console)
        logger.setLevel(level)
        warnings.formatwarning = formatted
