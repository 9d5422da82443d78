"""The engine against the plain loop, in one run (issue "One engine"; run by `make bench`, never by pytest).

Every row is a ratio to the plain Python RK4 loop of Example 6.3.1 (10 s at 1 kHz, written out in bench_single_run.py)
timed in this same run:

* one run in this process: solve_ivp RK45 by hand, robotadapt's numpy path, robotadapt's compiled path (steady
  state) as a user runs it (`simulate`'s default `log_every=1`, every step logged) and logging every 1000th step;
* one run end to end in a fresh process, `robotadapt run example-6.3.1` (import, trace, compile or load from the disk
  cache, run, result.npz, metrics.json and the three figures), with an empty compilation cache (cold) and with the cache
  the first process left (warm); the plain loop's reference is its own time;
* the PUMA 560's compiled Slotine–Li loop: a fresh process (imports, the model from its derivation cache) and, within
  it, its first compiled run (trace, compile or load the program, 2 s simulated), cold and from the cache;
* the default sweep `robotadapt sweep example-6.3.1 --random controller.Kv=5:20 --n N` end to end (N = 10⁴ unless
  `--quick`), per run against one plain-loop run; and its peak memory.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_single_run import ARM, CTRL, DT, PHI, T_FINAL, naive_rk4, naive_solve_ivp, robotadapt_simulate, timed

from robotadapt.plant import Plant
from robotadapt.sim import RK4, simulate
from robotadapt.trajectories import sinusoid

HERE = Path(__file__).resolve().parent
CLI = [sys.executable, "-m", "robotadapt"]


def compiled_run(log_every: int) -> np.ndarray:
    """Example 6.3.1 on the compiled path, logging every `log_every`-th step (1: `simulate`'s default)."""
    res = simulate(Plant(ARM, PHI), CTRL, sinusoid(2), t_final=T_FINAL, integrator=RK4(DT, "jax"), log_every=log_every)
    return np.concatenate([res.q[-1], res.dq[-1], res.x[-1]])


def without_lean() -> float:
    """The steady compiled run (log_every = 1) with the step's short sums left as XLA's dot and reduce kernels: what
    :func:`robotadapt.sim.compiled.lean` saves, so that it is kept only while this row shows it pays."""
    from robotadapt.sim import compiled
    from robotadapt.tracing import PROGRAMS

    kept = compiled.lean
    compiled.lean = lambda fn: fn
    PROGRAMS.items.clear()
    try:
        compiled_run(1)
        return timed(lambda: compiled_run(1), 5)[0]
    finally:
        compiled.lean = kept
        PROGRAMS.items.clear()


def fresh(args: list[str], cache: str) -> float:
    """Wall time of a fresh process running `args` with the compilation cache in `cache`."""
    env = dict(os.environ, ROBOTADAPT_CACHE=cache)
    t0 = time.perf_counter()
    subprocess.run(args, check=True, capture_output=True, env=env)
    return time.perf_counter() - t0


def children_peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024


PUMA = ("import time; from robotadapt.studies.scenarios import load; from robotadapt.tracing import jax_module; "
        "jax_module(); s = load('puma560-slotine-li', ['simulation.t_final=2.0', \"simulation.backend='jax'\"]); "
        "t0 = time.perf_counter(); s.run(); print(time.perf_counter() - t0)")


def fresh_inner(args: list[str], cache: str) -> tuple[float, float]:
    """Wall time of a fresh process running `args`, and the seconds it prints (its own timing of one part)."""
    env = dict(os.environ, ROBOTADAPT_CACHE=cache)
    t0 = time.perf_counter()
    out = subprocess.run(args, check=True, capture_output=True, env=env, text=True).stdout
    return time.perf_counter() - t0, float(out.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a 1000-run sweep instead of 10⁴")
    n_sweep = 1000 if parser.parse_args().quick else 10_000
    t_loop, _ = timed(naive_rk4, 3)
    rows = [("plain Python RK4 loop (the baseline)", t_loop, 1)]
    rows.append(("numpy + solve_ivp RK45, by hand", timed(naive_solve_ivp, 3)[0], 1))
    rows.append(("robotadapt, numpy path", timed(lambda: robotadapt_simulate("numpy"), 1)[0], 1))
    for log_every, what in ((1, "log_every=1 (default)"), (1000, "log_every=1000")):
        compiled_run(log_every)  # trace and compile: not the steady state
        seconds = timed(lambda every=log_every: compiled_run(every), 5)[0]
        rows.append((f"robotadapt, compiled, steady, {what}", seconds, 1))
    rows.append(("robotadapt, compiled, steady, short sums kept (no lean)", without_lean(), 1))
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        derived = Path(os.environ.get("ROBOTADAPT_CACHE", Path.home() / ".cache" / "robotadapt")) / "dh"
        if derived.is_dir():  # the PUMA's sympy derivation is not what is timed: only the JAX cache starts empty
            shutil.copytree(derived, Path(cache) / "dh")
        run = [*CLI, "run", "example-6.3.1", "--out", out]
        rows.append(("`robotadapt run example-6.3.1`, fresh, cold", fresh(run, cache), 1))
        rows.append(("`robotadapt run example-6.3.1`, fresh, warm", fresh(run, cache), 1))
        puma = [sys.executable, "-c", PUMA]
        for how in ("cold", "cached"):
            whole, first = fresh_inner(puma, cache)
            rows.append((f"PUMA 560 compiled run (2 s), fresh, {how}", whole, 1))
            rows.append(("  of which its first run (trace, compile, 2 s)", first, 1))
        sweep = [*CLI, "sweep", "example-6.3.1", "--random", "controller.Kv=5:20", "--n", str(n_sweep), "--out",
                 str(Path(out) / "sweep")]
        rows.append((f"`robotadapt sweep … --n {n_sweep}` (default backend)", fresh(sweep, cache), n_sweep))
    print("Example 6.3.1 (10 s at 1 kHz); ratio = plain-loop time × runs / time")
    print(f"{'what':<52} {'wall (s)':>9} {'runs':>6} {'vs plain loop':>14}")
    for name, seconds, runs in rows:
        print(f"{name:<52} {seconds:>9.3f} {runs:>6} {t_loop * runs / seconds:>13.2f}x")
    print(f"peak RSS of a child process (the sweep's parent): {children_peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
