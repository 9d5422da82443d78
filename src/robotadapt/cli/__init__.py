"""`robotadapt` command line: parse, call the library, write files. Bad input exits 2 with one line, no traceback.

Each command is a module of this package with `add_parser(subparsers)` and `main(args) -> exit code`; the commands
listed in `COMMANDS` whose module exists are offered.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from types import ModuleType
from typing import Any

from ..validation import ConfigError

EXIT_BAD_INPUT = 2
COMMANDS = ("list", "run", "gains", "pe", "excite", "identify", "export", "figures", "compare", "sweep", "tune", "explore")


def version() -> str:
    """The installed package's version (its metadata, from pyproject.toml: no copy of the number here)."""
    from importlib.metadata import version as installed

    return installed("robotadapt")


class _Version(argparse.Action):
    """`--version`: the version printed, read from the metadata only then (a lookup costs every start 45 ms)."""

    def __call__(self, parser: argparse.ArgumentParser, *args: Any) -> None:
        print(f"{parser.prog} {version()}")
        parser.exit()


def _modules() -> dict[str, ModuleType]:
    found = {}
    for name in COMMANDS:
        try:
            found[name] = importlib.import_module(f"{__name__}.{name}_cmd")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}_cmd":
                raise
    return found


def _parser(modules: dict[str, ModuleType]) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="robotadapt", description="Adaptive control of rigid robot manipulators.",
                                epilog="Start with `robotadapt list`, then `robotadapt run example-6.3.1`; "
                                "`robotadapt COMMAND --help` for a command's options.")
    p.add_argument("--version", action=_Version, nargs=0, help="print the installed version and exit")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for module in modules.values():
        module.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    modules = _modules()
    parser = _parser(modules)
    args = parser.parse_args(argv)
    if args.command is None:  # bare `robotadapt`: the commands, not an error
        parser.print_help()
        return 0
    try:
        return int(modules[args.command].main(args))
    except ConfigError as exc:
        print(f"robotadapt: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("robotadapt: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a reader that stopped early (e.g. `| head`)
        sys.stderr.close()
        return 0
