"""The ``splitcam`` command. It only parses arguments and calls the library.

Errors a user can cause (a bad pattern, an unreadable image, a missing folder) are printed as one
line, ``splitcam <command>: error: ...``, with exit status 1; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from . import __version__

Handler = Callable[[argparse.Namespace], int]


def _table(rows: list[dict[str, str]]) -> str:
    """A Markdown table (also readable as plain text)."""
    keys = list(rows[0])
    widths = {k: max(len(k), *(len(r[k]) for r in rows)) for k in keys}
    lines = ["| " + " | ".join(k.ljust(widths[k]) for k in keys) + " |"]
    lines.append("|" + "|".join("-" * (widths[k] + 2) for k in keys) + "|")
    lines += ["| " + " | ".join(r[k].ljust(widths[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def cmd_patterns(args: argparse.Namespace) -> int:
    from . import patterns

    if args.action == "list":
        names = args.names or patterns.names()
        rows = []
        for name in names:
            p = patterns.get(name)
            rows.append({**patterns.measure(p).row(), "provenance": p.provenance})
        print(_table(rows))
        return 0
    if len(args.names) != 1:
        raise ValueError(f"'patterns {args.action}' takes one pattern name or file")
    pattern = patterns.get(args.names[0])
    if args.action == "show":
        from .patterns.plot import draw_pattern

        out = Path(args.out or f"pattern_{pattern.name}.png")
        draw_pattern(pattern, out)
        print(f"wrote {out}")
    else:
        out = Path(args.out or f"{pattern.name}.toml")
        patterns.save(pattern, out)
        print(f"wrote {out}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    import torch

    from . import patterns
    from .imageio import read_image, write_image, write_raw
    from .noise import add_evaluation_noise
    from .sensor import SplitterSensor
    from .visualize import false_colour

    image = Path(args.image)
    pattern = patterns.get(args.pattern)
    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".npy"):
        raise ValueError(f"--out must end in .png or .npy, got {out.name!r}")
    rgb = torch.from_numpy(read_image(image)).permute(2, 0, 1)[None].double()
    with torch.no_grad():
        raw = SplitterSensor(pattern).double()(rgb)
    # Evaluation noise: seeded from the image name and sigma, so a simulation is reproducible
    # and matches what `splitcam evaluate` feeds the methods.
    raw = add_evaluation_noise(raw, image.stem, args.sigma)[0, 0].numpy()
    out.parent.mkdir(parents=True, exist_ok=True)
    scale = write_raw(out, raw)
    preview = Path(args.preview) if args.preview else out.with_name(out.stem + "_preview.png")
    write_image(preview, false_colour(raw, pattern))
    stored = f"16-bit PNG, full scale {scale:g}" if out.suffix.lower() == ".png" else "float32"
    print(f"pattern {pattern.name}, sigma {args.sigma:g}: raw {raw.shape[1]}x{raw.shape[0]}, "
          f"values {raw.min():.3f}..{raw.max():.3f}")
    print(f"wrote {out} ({stored}) and {preview} (false-colour preview)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="splitcam",
        description="Design and evaluate colour image sensors built on metasurface colour "
        "splitters.",
    )
    parser.add_argument("--version", action="version", version=f"splitcam {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser(
        "patterns", help="list, draw or export splitter patterns",
        description="`splitcam patterns` prints the design-principle measures of every pattern; "
        "`patterns show D --out d.png` draws one; `patterns export D --out d.toml` writes its "
        "pattern file (a starting point for your own).",
    )
    p.add_argument("action", nargs="?", choices=["list", "show", "export"], default="list")
    p.add_argument("names", nargs="*", metavar="PATTERN", help="pattern names or files")
    p.add_argument("--out", help="output file (PNG for show, .json/.toml for export)")
    p.set_defaults(handler=cmd_patterns)

    p = sub.add_parser(
        "simulate", help="simulate the raw image a splitter sensor records of a picture",
        description="Writes the raw image (16-bit PNG with its scale recorded, or .npy) and a "
        "false-colour preview PNG beside it.",
    )
    p.add_argument("image", help="colour image (PNG, JPEG, TIFF, BMP; 8 or 16 bit)")
    p.add_argument("--pattern", default="D", help="pattern name or file (default: D)")
    p.add_argument("--sigma", type=float, default=0.0,
                   help="Gaussian noise sigma in 8-bit units (default: 0)")
    p.add_argument("--out", required=True, help="raw output, .png or .npy")
    p.add_argument("--preview", help="preview PNG (default: <out>_preview.png)")
    p.set_defaults(handler=cmd_simulate)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
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
