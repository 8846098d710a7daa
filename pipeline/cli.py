"""`ridgeloc` command line: a thin dispatcher over `pipeline.commands.<name>` modules.

Each command module defines `HELP: str`, `add_arguments(parser)` and `main(args) -> int`.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from pipeline import __version__
from pipeline.errors import RidgelocError, environment_error_message

# The stage order of the product, written once.
COMMANDS = ("init", "run", "check", "solve", "simulate", "synth", "inspect", "locate", "mark", "overlay",
            "send")


def _load_commands() -> dict:
    modules = {}
    for name in COMMANDS:
        module_name = f"pipeline.commands.{name}"
        try:
            modules[name] = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name != module_name:
                raise
    return modules


def build_parser() -> tuple[argparse.ArgumentParser, dict]:
    parser = argparse.ArgumentParser(
        prog="ridgeloc",
        description="Locate ground targets from recorded UAV flights (video, telemetry, laser ranges).",
    )
    parser.add_argument("--version", action="version", version=f"ridgeloc {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    modules = _load_commands()
    for name, module in modules.items():
        # argparse %-formats a subcommand's help ("95 % ellipse" would crash `ridgeloc --help`)
        p = sub.add_parser(name, help=module.HELP.replace("%", "%%"), description=module.HELP)
        module.add_arguments(p)
    return parser, modules


def main(argv: list[str] | None = None) -> int:
    parser, modules = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(modules[args.command].main(args) or 0)
    except RidgelocError as exc:
        print(f"ridgeloc: error: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # `ridgeloc ... | head` closed the pipe: stop quietly, as other command-line tools do
        _silence_stdout()
        return 141  # 128 + SIGPIPE, the shell's status for a command whose reader went away
    except OSError as exc:  # a full disk, a read-only folder: the machine's state, not a bug
        message = environment_error_message(exc)
        if message is None:
            raise
        print(f"ridgeloc: error: {message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("ridgeloc: interrupted", file=sys.stderr)
        return 130


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's last flush of what is left of a closed pipe's buffer
    raises no second BrokenPipeError at exit (the Python documentation's recipe, `signal` module notes)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


if __name__ == "__main__":
    raise SystemExit(main())
