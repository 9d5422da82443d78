"""`robotadapt figures`: run every book example and problem; one folder of figures and an index.html gallery."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import add_figure_arguments, figure_format


def add_parser(sub: argparse._SubParsersAction) -> None:
    figures = sub.add_parser("figures", help="run every book example and problem; figures and an index.html gallery")
    figures.add_argument("--out", type=Path, default=Path("results/figures"),
                         help="output folder (default: results/figures)")
    figures.add_argument("--t-final", type=float, metavar="T",
                         help="cap the simulated time at T seconds (the gallery says which runs were capped)")
    add_figure_arguments(figures)


def main(args: argparse.Namespace) -> int:
    """Exit 0 when every scenario ran (the book's Example 6.2.2 stops by design and still counts), 1 otherwise."""
    from ..report.html import run_gallery
    from ..validation import as_scalar

    cap = None if args.t_final is None else as_scalar(args.t_final, "--t-final", positive=True)
    entries = run_gallery(args.out, cap, progress=True, output=figure_format(args))
    total = sum(e.wall_time for e in entries)
    print(f"wrote {args.out}/index.html: {len(entries)} scenarios in {total:.0f} s")
    return 0
