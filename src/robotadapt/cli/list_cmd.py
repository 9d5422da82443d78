"""`robotadapt list`: the packaged scenarios, one line each."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    sub.add_parser("list", help="the packaged scenarios, one line each")


def main(args: argparse.Namespace) -> int:
    from ..studies.scenarios import available

    items = available()
    width = max(map(len, items)) if items else 0
    for name, description in items.items():
        print(f"{name:<{width}}  {description}")
    return 0
