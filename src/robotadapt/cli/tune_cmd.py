"""`robotadapt tune`: tune a scenario's gains by gradients through the closed loop under a torque budget; writes
tuned.toml (runnable by `robotadapt run`), tune.json and tune.png (or .pdf, .svg: --format; docs/tuning.md)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from .common import add_figure_arguments, add_scenario_arguments, figure_format, overrides

EXIT_BUDGET = 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tune", help="tune a controller's gains by differentiating the closed loop; write tuned.toml",
                       description="Minimise an objective of the run over the controller's gains (kept positive "
                       "definite) with L-BFGS-B on gradients from jax.grad through the closed loop, under a torque "
                       "budget. Exit 1 when no gains found meet the budget (the best found is written).")
    add_scenario_arguments(p)
    p.add_argument("--vary", action="append", default=[], metavar="FIELD[=LO:HI]",
                   help="a gain of the controller to tune, optionally within a box: controller.Kv, controller.Lam=0.5:20, "
                        "controller.law.F_p (repeatable; a scalar, list or matrix gain stays one)")
    p.add_argument("--objective", default="rms_error", metavar="NAME",
                   help="rms_error (sqrt of the mean of ‖e‖²), ise, final_error, energy, or a weighted sum such as "
                        "rms_error+1e-6*energy (default rms_error)")
    p.add_argument("--max-torque", type=float, metavar="T", help="budget: max over joints and time of |τ_i(t)| ≤ T")
    p.add_argument("--over", metavar="plant.phi=LO:HI",
                   help="robust tuning: minimise the mean objective over true parameters drawn in this box")
    p.add_argument("--samples", type=int, default=8, help="true-parameter sets drawn for --over (default 8)")
    p.add_argument("--seed", type=int, default=0, help="seed of the --over draws (default 0)")
    p.add_argument("--max-runs", type=int, default=100,
                   help="most differentiated runs (each a forward and a backward pass; default 100)")
    p.add_argument("--screen", type=int, metavar="N",
                   help="forward runs of the batched screen that picks the start (default 64; 0 or 1: start at the "
                        "scenario's gains)")
    p.add_argument("--surface", type=int, metavar="K",
                   help="draw the objective over a K×K grid of the first two scalar gains (K² forward runs); default 9 "
                        "when exactly two scalar gains are tuned, else none; 0: none")
    p.add_argument("--out", type=Path, metavar="DIR", help="output folder (default: results/tune-NAME)")
    p.add_argument("--no-plots", action="store_true", help="skip the figure tune.png")
    add_figure_arguments(p)


def main(args: argparse.Namespace) -> int:
    from ..files import atomic_write, writable_dir
    from ..studies.scenarios import load
    from ..studies.tune import tune

    started = time.perf_counter()
    output = figure_format(args)
    scenario = load(args.scenario, overrides(args))
    out = writable_dir(args.out if args.out is not None else Path("results") / f"tune-{scenario.name}")
    tuned = tune(scenario, args.vary, args.objective, args.max_torque, over=args.over, samples=args.samples,
                 seed=args.seed, max_runs=args.max_runs, surface_points=args.surface, progress=True,
                 **({} if args.screen is None else {"screen": args.screen}))
    summary = tuned.summary()
    header = (f"# robotadapt tune {scenario.name}: {summary['objective_expression']} = {summary['objective']:.6g}, "
              f"max |tau| = {summary['max_abs_torque']:.6g}" + ("" if args.max_torque is None else
                                                               f" (budget {args.max_torque:g})") + "\n")
    atomic_write(out / "tuned.toml", lambda f: f.write(header + tuned.scenario.text))
    atomic_write(out / "tune.json", lambda f: json.dump(summary, f, indent=2))
    if not args.no_plots:
        from ..report.tune_figures import tune_figure

        tune_figure(tuned, out / output.name("tune"), output)
    gains = ", ".join(f"{k} = {v}" for k, v in summary["gains"].items())
    print(f"tune {scenario.name}: {summary['objective_expression']} {tuned.before.objective:.4g} -> "
          f"{tuned.after.objective:.4g}, max |τ| {tuned.before.max_abs_torque:.4g} -> {tuned.after.max_abs_torque:.4g}"
          f" in {summary['differentiated_runs']} differentiated runs (+ {summary['forward_runs']} forward runs: the "
          f"screen, the start and the answer), {time.perf_counter() - started:.3g} s in all (the search "
          f"{tuned.wall_time:.3g} s); {gains}")
    print(f"wrote {out}/")
    if not tuned.feasible:
        hint = ""
        if summary["peak_elasticity"]:  # the gain that moves the peak most, and which way to move it
            name, value = max(summary["peak_elasticity"].items(), key=lambda kv: abs(kv[1]))
            way = "lower" if value > 0 else "raise"
            edge = _at_edge(tuned, name, way)
            hint = (f"; of the gains varied, the peak moves most with {name} (∂ln max|τ|/∂ln gain = {value:.2g}: "
                    + (f"{way} it" if edge is None else f"it is at the {edge} of its range: widen it") +
                    "; a gain not varied may set the peak: vary it too)")
        print(f"robotadapt: no gains found meet the budget max |τ| ≤ {args.max_torque:g} (best found: "
              f"{tuned.after.max_abs_torque:.4g}{'' if tuned.after.ok else ', diverged'}){hint}; kept in "
              f"{out}/tuned.toml")
        return EXIT_BUDGET
    return 0


def _at_edge(tuned: Any, field: str, way: str) -> str | None:
    """"top"/"bottom" when the tuned `field` sits at the end of its range that `way` ("raise"/"lower") asks to move it
    past, else None (a gain without a box has no end)."""
    from ..studies.gain_space import split

    for gain, part in zip(tuned.gains, split(tuned.gains, tuned.theta), strict=True):
        if gain.field != field or gain.lower is None:
            continue
        ends = gain.bounds()  # log-space (low, high) per entry, as the search's θ
        theta = np.ravel(part)
        if way == "raise" and any(t >= hi - 1e-6 for t, (_, hi) in zip(theta, ends, strict=False) if hi is not None):
            return "top"
        if way == "lower" and any(t <= lo + 1e-6 for t, (lo, _) in zip(theta, ends, strict=False) if lo is not None):
            return "bottom"
    return None
