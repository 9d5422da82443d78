"""Gradient tuning against a random sweep over the same box (issues 17 and 25, docs/tuning.md).

Example 6.3.1 (Slotine–Li, 10 s, the state logged every 10 steps for both) under a torque budget of 150 N·m: the best
run of a 1000-run random sweep (`robotadapt sweep --random ... --n 1000`, uniform in the box, feasible runs only) against
`robotadapt tune` on the same box and budget with at most 100 differentiated runs. Prints both objectives, run counts
and wall times, the tuner's time to reach the sweep's best (its first evaluation within the budget at or below that
objective, the screen and compilation included), and the ratios.

    python benchmarks/bench_tune.py
"""

from __future__ import annotations

import math
import tempfile
import time

from robotadapt.studies.scenarios import load
from robotadapt.studies.sweep import make_sweep, run_sweep
from robotadapt.studies.tune import tune

BOX = {"controller.Kv": (2.0, 50.0), "controller.Lam": (0.5, 10.0), "controller.Gamma": (0.05, 2.0)}
BUDGET = 150.0  # N·m: the book's gains peak at 571 N·m
SETTINGS = ["simulation.log_every=10", "simulation.backend='jax'"]
RANDOM_RUNS, TUNE_RUNS = 1000, 100


def main() -> None:
    scenario = load("example-6.3.1", SETTINGS)
    sweep = make_sweep(scenario, random=[f"{k}={lo}:{hi}" for k, (lo, hi) in BOX.items()], n=RANDOM_RUNS, seed=0)
    with tempfile.TemporaryDirectory() as folder:
        report = run_sweep(sweep, folder, workers=2)
    feasible = [row for row in report.rows if row.get("status") == "ok" and max(row["max_abs_torque"]) <= BUDGET]
    best = min(feasible, key=lambda row: row["rms_error_norm"]) if feasible else None
    random_best = best["rms_error_norm"] if best else math.inf
    print(f"random sweep: {len(report.rows)} runs in {report.seconds:.1f} s, {len(feasible)} within {BUDGET:g} N·m; "
          f"best rms_error {random_best:.5g}" + (f" at {', '.join(f'{k}={best[k]:.4g}' for k in BOX)}" if best else ""))
    wall = start = time.perf_counter()
    tuned = tune(scenario, [f"{k}={lo}:{hi}" for k, (lo, hi) in BOX.items()], "rms_error", BUDGET, max_runs=TUNE_RUNS)
    wall = time.perf_counter() - wall
    s = tuned.summary()
    print(f"tune: {s['runs']} runs (differentiated, plus the forward runs scoring the start and the answer) in "
          f"{wall:.1f} s; rms_error {s['objective']:.5g}, max |tau| {s['max_abs_torque']:.5g} N·m at "
          f"{', '.join(f'{k}={v:.4g}' for k, v in s['gains'].items())}")
    hit = tuned.search.reached(random_best, BUDGET)
    reach = hit.seconds + (tuned.search.began - start) if hit else math.inf
    print(f"tune reached the sweep's best ({random_best:.5g}) after {reach:.1f} s" +
          (f" (rms_error {hit.objective:.5g}, max |tau| {hit.peak:.5g} N·m)" if hit else ""))
    print(f"ratios: objective tune/random {s['objective'] / random_best:.3f}, runs {s['runs'] / len(report.rows):.3f}, "
          f"wall time {wall / report.seconds:.2f}, time to the sweep's best {reach / report.seconds:.2f}")


if __name__ == "__main__":
    main()
