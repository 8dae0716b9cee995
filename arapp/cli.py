"""The `arapp` command line: one subcommand per module in `arapp.commands`.

Each command module defines `HELP` (one line), `add_arguments(parser)` and
`run(args) -> int`. Modules import their heavy dependencies inside `run`, so
`arapp --help` stays fast. Errors a user can fix (`ValueError`, `OSError`,
`RuntimeError` and their subclasses, which carry specific messages) are
printed without a traceback; `--debug` shows the traceback too.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

# (subcommand, module under arapp.commands); the order is the order in --help.
COMMANDS = [
    ("gui", "gui"),
    ("demo", "demo"),
    ("replay", "replay"),
    ("model", "model"),
    ("sources", "sources"),
    ("record", "record"),
    ("synth", "synth"),
    ("calibrate", "calibrate"),
    ("markers", "markers"),
    ("slice", "slice"),
    ("print", "print_"),
    ("printer", "printer"),
    ("scan", "scan"),
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="arapp",
        description="Augmented reality on printed markers: track the camera, "
        "overlay NURBS models, and print what you see. "
        "With no subcommand, opens the desktop app.",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in COMMANDS:
        module = importlib.import_module(f"arapp.commands.{module_name}")
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def show_source_warnings(command: str) -> None:
    """Show a source's warnings (a video that stops decoding early) as one line naming the command, instead of
    Python's two lines with a line of arapp's own code. Installed once however often main() runs (the tests call
    it many times in one process): later calls only rename the command."""
    from tracking.sources import SourceWarning

    shown = warnings.showwarning
    if getattr(shown, "arapp_command", None) is not None:
        shown.arapp_command = command
        return

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, SourceWarning):
            print(f"arapp {show.arapp_command}: warning: {message}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    show.arapp_command = command
    warnings.showwarning = show


def main(argv: list[str] | None = None) -> int:
    # PyOpenGL binds its platform on first import; the overlay renders offscreen (EGL, else OSMesa:
    # arapp.render.select_platform falls back), also on a desktop where GLX would be the default.
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        args = parser.parse_args(["gui", *(argv or [])])
    show_source_warnings(args.command)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("arapp: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError, RuntimeError) as exc:
        if args.debug:
            raise
        print(f"arapp {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
