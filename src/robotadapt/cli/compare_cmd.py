"""`robotadapt compare`: several controllers on one scenario's arm, trajectory, disturbance and initial state."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import add_scenario_arguments, overrides


def add_parser(sub: argparse._SubParsersAction) -> None:
    compare = sub.add_parser("compare", help="compare controllers on one scenario; write report.html and comparison.json")
    add_scenario_arguments(compare)
    compare.add_argument("--controllers", metavar="A,B,C",
                         help="comma-separated names from robotadapt.studies.compare.LINEUP, e.g. "
                              "slotine_li,dcal,repetitive (default: every controller that applies; an unknown name lists "
                              "them all)")
    compare.add_argument("--out", type=Path, help="output folder (default: results/NAME/compare)")


def main(args: argparse.Namespace) -> int:
    """Exit 0 when every controller ran to the end, 1 when one diverged (its partial run is in the report)."""
    from ..report.html import table_text, write_comparison
    from ..studies.compare import compare
    from ..studies.scenarios import load
    from ..validation import ConfigError

    names = None
    if args.controllers is not None:
        names = [n.strip() for n in args.controllers.split(",")]
        if not all(names):
            raise ConfigError("--controllers", f"expected comma-separated names, got {args.controllers!r}")
    base = load(args.scenario, overrides(args))
    rows, skipped = compare(base, names, progress=True)
    out = args.out if args.out is not None else Path("results") / base.name / "compare"
    path = write_comparison(base, rows, skipped, out)
    print(table_text(rows))
    for name, reason in skipped.items():
        print(f"not applicable: {name}: {reason}")
    print(f"wrote {path}")
    return 0 if all(r.result.ok for r in rows) else 1
