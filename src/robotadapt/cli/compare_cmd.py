"""`robotadapt compare`: several controllers on one scenario's arm, trajectory, disturbance and initial state."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import add_figure_arguments, add_scenario_arguments, figure_format, overrides


class _Help(argparse.HelpFormatter):
    """The help with the lineup's names filled in, read from the registered laws only when the help is printed."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = super()._get_help_string(action)
        if text is not None and "{lineup}" in text:
            from ..studies.compare import contenders

            text = text.replace("{lineup}", ", ".join(contenders()))
        return text


def add_parser(sub: argparse._SubParsersAction) -> None:
    compare = sub.add_parser("compare", help="compare controllers on one scenario; write report.html and comparison.json",
                             formatter_class=_Help)
    add_scenario_arguments(compare)
    compare.add_argument("--controllers", metavar="A,B,C",
                         help="comma-separated names of the lineup: {lineup} (default: every one that applies to "
                              "the scenario)")
    compare.add_argument("--variant", action="append", default=[], metavar="SECTION.KEY=VALUE[;...]",
                         help="compare the scenario as written with itself under these overrides, side by side "
                              "(repeatable: one row each; several overrides of one row separated by ';'), e.g. "
                              "--variant 'controller.adaptation=\"natural\"' --variant 'controller.adaptation=\"none\"'")
    compare.add_argument("--fair", action="store_true",
                         help="tune every law's own gains to the same --objective under the same --max-torque first "
                              "(robotadapt tune), then compare; laws that cannot be differentiated keep the lineup's "
                              "gains (the book's, scaled to the arm)")
    compare.add_argument("--max-torque", type=float, metavar="T", help="with --fair: the torque budget max |τ_i(t)| ≤ T")
    compare.add_argument("--objective", default="rms_error", metavar="NAME",
                         help="with --fair: the objective each law is tuned to (as for robotadapt tune; default rms_error)")
    compare.add_argument("--tune-runs", type=int, default=30, metavar="N",
                         help="with --fair: most differentiated runs per law (default 30)")
    compare.add_argument("--workers", type=int, metavar="N",
                         help="with --fair: laws tuned at once, each in a process of its own (default: one per core; "
                              "1 tunes them in-process; the Panda's composite law's tuning peaks at about 4 GB)")
    compare.add_argument("--out", type=Path, help="output folder (default: results/NAME/compare, or compare-fair)")
    add_figure_arguments(compare)


def main(args: argparse.Namespace) -> int:
    """Exit 0 when every controller ran to the end, 1 when one diverged (its partial run is in the report)."""
    from ..report.html import table_text, write_comparison
    from ..studies.compare import compare
    from ..studies.scenarios import load
    from ..validation import ConfigError

    output = figure_format(args)
    names = None
    if args.controllers is not None:
        names = [n.strip() for n in args.controllers.split(",")]
        if not all(names):
            raise ConfigError("--controllers", f"expected comma-separated names, got {args.controllers!r}")
    if args.fair and args.max_torque is None:
        raise ConfigError("--max-torque", "a fair comparison needs a torque budget: --fair --max-torque T")
    if not args.fair and args.max_torque is not None:
        raise ConfigError("--max-torque", "applies to --fair (tuning every law under the budget)")
    if args.workers is not None and not args.fair:
        raise ConfigError("--workers", "applies to --fair (the laws tuned at once)")
    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers", f"must be at least 1, got {args.workers}")
    base = load(args.scenario, overrides(args))
    if args.variant:
        if args.fair or args.controllers is not None:
            raise ConfigError("--variant", "compares the scenario's own law under other settings: not with --fair or "
                              "--controllers")
        from ..studies.compare import run_entries, variants

        settings = [[part.strip() for part in v.split(";") if part.strip()] for v in args.variant]
        if not all(settings):
            raise ConfigError("--variant", f"expected SECTION.KEY=VALUE[;...] each, got {args.variant!r}")
        rows = run_entries(variants(base, settings, lambda extra: load(args.scenario, [*overrides(args), *extra])),
                           progress=True)
        out = args.out if args.out is not None else Path("results") / base.name / "variants"
        path = write_comparison(base, rows, {}, out, None, output)
        print(table_text(rows))
        print(f"wrote {path}")
        return 0 if all(r.result.ok for r in rows) else 1
    if args.fair:
        from ..studies.compare import fair

        rows, skipped = fair(base, names, args.objective, args.max_torque, args.tune_runs, progress=True,
                             workers=args.workers)
    else:
        rows, skipped = compare(base, names, progress=True)
    folder = "compare-fair" if args.fair else "compare"
    out = args.out if args.out is not None else Path("results") / base.name / folder
    budget = {"objective": args.objective, "max_torque": args.max_torque} if args.fair else None
    path = write_comparison(base, rows, skipped, out, budget, output)
    print(table_text(rows))
    for name, reason in skipped.items():
        print(f"not applicable: {name}: {reason}")
    print(f"wrote {path}")
    return 0 if all(r.result.ok for r in rows) else 1
