"""The ``froude`` command. Each subcommand lives in its own module of this package and exposes
``register(subparsers)``; the module parses arguments, calls the library and writes files — nothing else.

Every ``FroudeError`` becomes one line on stderr and exit status 2; no traceback reaches the user.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import FroudeError

#: Subcommand modules, in the order ``froude --help`` lists them.
SUBCOMMANDS = ("info", "fit", "scale", "accelerate", "view", "render", "demo", "batch")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: one line and exit 2, like ours
        self.print_usage(sys.stderr)
        print(f"froude: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(
        prog="froude",
        description=(
            "Change running motion physically: new characters, speeds, accelerations. "
            "Fits a point mass on spring legs to the motion (Pollard 1999), changes it by dynamic "
            "similarity and simulation, then corrects the whole body with inverse kinematics."
        ),
        epilog="Start with 'froude demo'. Every command has --help.",
    )
    parser.add_argument("--version", action="version", version=f"froude {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"{__name__}.{name}":
                continue  # subcommand not built yet
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        result = args.func(args)
    except FroudeError as e:
        print(f"froude {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"froude {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(result or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
