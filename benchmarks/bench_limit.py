"""Speed at the limit (issue 45; run by `make bench`, never by pytest): what a user waits for, each row against the
plain Python RK4 loop of Example 6.3.1 (bench_single_run.py) timed in this same run.

* `ra.load("example-6.3.1").run()` in steady state (default backend: C), median of 21, and within it the time spent in
  the C programs (the loop and the records, timed around each native call): the rest is Python around them;
* a fresh `robotadapt run example-6.3.1` with its three figures, the programs on disk (warm cache), median of 5;
  fresh processes start as an installed package does, with Python's bytecode cache (bench_single_run.INSTALLED);
* `robotadapt sweep example-6.3.1 --random controller.Kv=5:20 --n N` end to end (continuous, and sampled at Ts = 2 ms):
  N plain-loop runs against the sweep's wall time, with the peak resident memory of its largest process;
* panda-slotine-li, 10 s at 1 kHz: steady (C) and a fresh process with its program on disk, against the plain
  two-link loop (the issue's goals: ≤ 0.06 s; ≤ 2× the plain loop).

`python benchmarks/bench_limit.py [--sweep-runs N] [--no-panda]`. The Panda's first run builds its C program (about a
minute on this machine) once per cache; the other rows use the cache a first run left.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

from bench_single_run import INSTALLED, fresh_cli_seconds, import_seconds_of, naive_rk4, timed

import robotadapt as ra
from robotadapt.native import build

CLI = [sys.executable, "-m", "robotadapt"]


def in_c(fn: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """Median wall time of `fn()` over `repeats` calls and the median time of its native calls within a call."""
    spent: list[float] = []
    plain = build.Compiled.__call__

    def counted(self: Any, *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return plain(self, *args, **kwargs)
        finally:
            spent[-1] += time.perf_counter() - t0

    walls, natives = [], []
    build.Compiled.__call__ = counted  # type: ignore[method-assign]
    try:
        for _ in range(repeats):
            spent.append(0.0)
            t0 = time.perf_counter()
            fn()
            walls.append(time.perf_counter() - t0)
            natives.append(spent[-1])
    finally:
        build.Compiled.__call__ = plain  # type: ignore[method-assign]
    return statistics.median(walls), statistics.median(natives)


def sweep(runs: int, extra: tuple[str, ...]) -> tuple[float, float]:
    """Wall time of the sweep as a user types it (programs on disk) and the peak RSS of its largest process (MB),
    measured by a parent of its own (RUSAGE_CHILDREN keeps the largest child a process ever waited for)."""
    with tempfile.TemporaryDirectory() as out:
        command = [*CLI, "sweep", "example-6.3.1", "--random", "controller.Kv=5:20", "--n", str(runs), *extra,
                   "--out", out]
        parent = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, capture_output=True); "
                  "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", parent, *command], check=True, capture_output=True, text=True,
                              env=INSTALLED)
        seconds = time.perf_counter() - t0
    return seconds, int(done.stdout.split()[-1]) / 1024


PANDA_FRESH = ("import robotadapt as ra; ra.load('panda-slotine-li', ['simulation.t_final=10']).run()")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep-runs", type=int, default=10_000)
    parser.add_argument("--no-panda", action="store_true", help="leave out the Panda's rows")
    args = parser.parse_args()
    scenario = ra.load("example-6.3.1")
    for _ in range(3):  # the programs built or found, the caches warm
        scenario.run()
    loop = timed(naive_rk4, 3)[0]
    rows: list[tuple[str, float, float, str]] = []
    wall, native = in_c(scenario.run, 21)
    rows.append(('ra.load("example-6.3.1").run(), steady', wall, loop / wall, "≥ 500x"))
    rows.append(("  of which in the C programs (loop, records)", native, loop / native,
                 f"the run is {wall / native:.2f}x it (goal ≤ 2x)"))
    cli = fresh_cli_seconds(5)
    rows.append(("fresh `robotadapt run example-6.3.1`, figures, warm", cli, loop / cli, "≤ 1.0x slower (≥ 1.0x)"))
    peaks = []
    for extra, what in (((), "continuous"), (("--control-period", "0.002"), "Ts = 2 ms")):
        sweep(min(args.sweep_runs, 200), extra)  # the programs on disk
        seconds, peak = sweep(args.sweep_runs, extra)
        peaks.append(f"{what} {peak:.0f} MB")
        rows.append((f"sweep of {args.sweep_runs} runs, {what}, end to end", seconds,
                     loop * args.sweep_runs / seconds, "≥ 1000x"))
    if not args.no_panda:
        panda = ra.load("panda-slotine-li", ["simulation.t_final=10"])
        panda.run()  # built once per cache
        steady = timed(panda.run, 3)[0]
        rows.append(("panda-slotine-li 10 s at 1 kHz, steady", steady, loop / steady, "≤ 0.06 s"))
        warm = import_seconds_of([sys.executable, "-c", PANDA_FRESH], 3)
        rows.append(("panda-slotine-li 10 s, fresh process, warm", warm, loop / warm, "≤ 2x slower (≥ 0.5x)"))
    print(f"Example 6.3.1, 10 s at 1 kHz: the plain Python RK4 loop {loop:.3f} s in this run; load average "
          f"{os.getloadavg()[0]:.2f}")
    print(f"{'what':<56} {'wall (s)':>9} {'vs plain loop':>14}  goal")
    for name, seconds, ratio, goal in rows:
        print(f"{name:<56} {seconds:>9.4f} {ratio:>13.1f}x  {goal}")
    print(f"peak RSS of a sweep's largest process: {'; '.join(peaks)}")


if __name__ == "__main__":
    main()
