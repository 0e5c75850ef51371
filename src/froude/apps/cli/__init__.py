"""The ``froude`` command. Each subcommand lives in its own module of this package and exposes
``register(subparsers)``; the module parses arguments, calls the library and writes files — nothing else.

Every error reaches the user as one line on stderr: bad options, ``FroudeError``, operating-system errors
(a full disk, a vanished folder) and memory exhaustion exit with status 2; SIGINT and SIGTERM stop the
command the same way (temporaries removed, child processes ended) with status 130 / 143. Module imports
here and in ``register`` are light (no NumPy), so ``froude --help`` answers at once; each ``run`` imports
what it needs.
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys

from ...errors import FroudeError

#: Subcommand modules, in the order ``froude --help`` lists them.
SUBCOMMANDS = ("info", "fit", "scale", "accelerate", "convert", "view", "render", "demo", "batch", "blender")


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so every cleanup that handles an interrupt handles it too."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: one line and exit 2, like ours
        print(f"{self.prog}: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        raise SystemExit(2)

    def _get_values(self, action, arg_strings):
        # argparse (3.11) drops a '--' value ("--fps=--") and hands the option an empty list, unchecked
        if action.nargs is None and action.option_strings and arg_strings == ["--"]:
            self.error(f"argument {'/'.join(action.option_strings)}: expected a value, got '--'")
        return super()._get_values(action, arg_strings)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The whole parser; with ``argv``, only the command it names is built in full (the others are listed
    with their one-line help), so a command's start-up never pays for another's ``register``."""
    from ... import __version__  # lazy: start-up (froude --help imports every verb module and no NumPy)

    parser = _Parser(
        prog="froude",
        description=(
            "Change running motion physically: new characters, speeds, accelerations. "
            "Fits a point mass on spring legs to the motion (Pollard 1999), changes it by dynamic "
            "similarity and simulation, then corrects the whole body with inverse kinematics."
        ),
        epilog="Start with 'froude demo'. Every command has --help. Speeds are written the same way "
        "everywhere: 1.2x (or a bare 1.2) is a factor, 3.5m/s a speed. Exit status: 0 done, 1 an output "
        "missed a physics bar (not written unless --keep; or batch tasks failed), 2 bad input or output, "
        "3 internal error (a bug), 130/143 interrupted (Ctrl-C / SIGTERM).",
    )
    parser.add_argument("--version", action="version", version=f"froude {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    chosen = _command_in(argv)
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"{__name__}.{name}":
                continue  # subcommand not built yet
            raise
        if argv is None or name == chosen or not hasattr(module, "HELP"):
            module.register(sub)  # (a module without HELP is always built in full)
        else:
            sub.add_parser(name, help=module.HELP)
    return parser


def _command_in(argv: list[str] | None) -> str | None:
    """The subcommand argv names (its first word that is not an option), or None."""
    for word in argv or ():
        if not word.startswith("-"):
            return word if word in SUBCOMMANDS else None
    return None


def _on_sigterm(signum, frame):
    raise Terminated()


def _describe_os_error(e: OSError) -> str:
    names = [n for n in (e.filename, getattr(e, "filename2", None)) if n]
    what = e.strerror or str(e) or type(e).__name__
    return f"{': '.join(map(str, names))}: {what}" if names else what


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_usage(sys.stderr)
        print("froude: error: give a command (see 'froude --help')", file=sys.stderr)
        return 2
    previous = None
    try:  # only the main thread may set handlers (tests call main() from others)
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:
        pass
    name = f"froude {args.command}"
    import warnings

    try:
        with warnings.catch_warnings():
            # NumPy's RuntimeWarnings ("invalid value in divide") are not messages for a user: results are
            # checked for finiteness where they are written
            warnings.simplefilter("ignore", RuntimeWarning)
            result = args.func(args)
    except FroudeError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return 2
    except Terminated:
        print(f"{name}: terminated", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away ("froude info x.bvh | head"): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so the interpreter's last flush finds nowhere to fail
        return 141
    except OSError as e:
        print(f"{name}: error: {_describe_os_error(e)}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"{name}: error: out of memory (ask for less: fewer strides, frames or pixels)", file=sys.stderr)
        return 2
    except RecursionError:
        print(f"{name}: error: input nested too deeply", file=sys.stderr)
        return 2
    except Exception as e:  # a bug: one line by default, the traceback on request
        if os.environ.get("FROUDE_DEBUG"):
            raise
        print(f"{name}: internal error: {type(e).__name__}: {e} (please report it; FROUDE_DEBUG=1 shows "
              "the traceback)", file=sys.stderr)
        return 3
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return int(result or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
