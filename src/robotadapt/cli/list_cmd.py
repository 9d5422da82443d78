"""`robotadapt list`: the packaged scenarios, one line each."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    sub.add_parser("list", help="the packaged scenarios, one line each; [needs: X]: runs after pip install 'robotadapt[X]'")


def main(args: argparse.Namespace) -> int:
    from ..studies.scenarios import available
    from ..studies.scenarios.loader import needs

    items, extra = available(), needs()
    width = max(map(len, items)) if items else 0
    for name, description in items.items():
        mark = f"  [needs: {', '.join(extra[name])}]" if extra.get(name) else ""
        print(f"{name:<{width}}  {description}{mark}")
    return 0
