"""`robotadapt sweep`: a scenario over a grid × random draws, on local processes or a Dask scheduler, resumable;
writes runs.jsonl (one row per run), sweep.json and sweep.png (or .pdf, .svg: --format)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from .common import add_figure_arguments, add_scenario_arguments, figure_format, overrides


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="run a scenario over a grid and random draws of its fields; resumable",
                       description="Run a scenario over every grid point × N random draws. Rows are appended to "
                       "DIR/runs.jsonl as chunks finish: rerun the same command to resume an interrupted sweep.")
    add_scenario_arguments(p)
    p.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="grid axis: a scenario field and its values, e.g. controller.Kv=5,10,20 (repeatable)")
    p.add_argument("--random", action="append", default=[], metavar="KEY=LO:HI",
                   help="random axis, uniform in [LO, HI], e.g. controller.Kv=5:20 or plant.phi=[0.6,2]:[1,2.6]")
    p.add_argument("--n", type=int, default=1, help="random draws per grid point (default 1)")
    p.add_argument("--seed", type=int, default=0, help="base of every run's seed (default 0)")
    p.add_argument("--workers", type=int, help="local worker processes (default: one per core; 1 runs in-process)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="a Dask distributed scheduler, e.g. tcp://host:8786")
    p.add_argument("--metric", default="rms_error_norm",
                   help="metric of the summary figure and the best run (default rms_error_norm = sqrt(mean ‖e‖²))")
    p.add_argument("--out", type=Path, metavar="DIR", help="output folder (default: results/sweep-NAME)")
    p.add_argument("--no-plots", action="store_true", help="skip the figure sweep.png")
    add_figure_arguments(p)


def _summary(rows: list[dict[str, Any]], keys: list[str], metric: str) -> str:
    """One line: runs finished, and the best value of `metric` with the swept values of its run (4 significant
    digits)."""
    from ..studies.compare import number_text
    from ..studies.sweep import scalar

    ok = [row for row in rows if row.get("status") == "ok"]
    line = f"{len(ok)} ok, {len(rows) - len(ok)} not finished"
    values = [(scalar(row.get(metric)), row) for row in ok if not math.isnan(scalar(row.get(metric)))]
    if values:
        best, row = min(values, key=lambda v: v[0])
        at = ", ".join(f"{k}={number_text(row[k])}" for k in keys)
        line += f"; {metric}: best {best:.4g} at run {row['run']} ({at})"
    return line


def main(args: argparse.Namespace) -> int:
    from ..studies.scenarios import load
    from ..studies.sweep import FIGURE, check_metric, make_sweep, run_sweep
    from ..validation import ConfigError

    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers", f"must be at least 1, got {args.workers}")
    output = figure_format(args)
    scenario = load(args.scenario, overrides(args))
    sweep = make_sweep(scenario, args.grid, args.random, args.n, args.seed)
    out = args.out if args.out is not None else Path("results") / f"sweep-{scenario.name}"
    check_metric(scenario.setup, args.metric)
    report = run_sweep(sweep, out, workers=args.workers, scheduler=args.scheduler, progress=True)
    if not args.no_plots:
        from ..report.sweep_figures import summary_figure

        summary_figure(report.rows, sweep.keys, args.metric, Path(out) / output.name(FIGURE), sweep.name,
                       output=output)
    rate = f", {report.computed / report.seconds:.3g} runs/s" if report.computed else ""
    print(f"sweep {scenario.name}: {len(sweep)} runs ({report.computed} now, {len(sweep) - report.computed} already "
          f"in the table) in {report.seconds:.3g} s{rate}" + (f"; {report.how}" if report.how else ""))
    print(_summary(report.rows, sweep.keys, args.metric))
    print(f"wrote {out}/")
    return 0
