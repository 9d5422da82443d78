"""Throughput of many runs against the user's own script (run by `make bench`, never by pytest).

1. `simulate_batch` (numpy, then the jax backend in steady state) for N = 1 … 10000 runs of Example 6.3.1 (Slotine–Li on
   the two-link arm), each with its own true masses (±20 % around 0.8, 2.3 kg) and its own K_v in [5, 20], against N
   sequential runs of the plain Python RK4 loop and of numpy + solve_ivp (benchmarks/bench_single_run.py), measured once
   here and extrapolated. Runs of `T_SIM` = 1 s simulated (1000 RK4 steps); the run picked for the check must reach the
   plain loop's final state.
2. The sweep end to end, as a user types it: `robotadapt sweep example-6.3.1 --random controller.Kv=5:20 --n N
   --backend B` (10 s per run; process start, loading, compilation with an empty cache, chunking, writing the table and
   the figure included) on the local cores, with the peak resident memory of its largest process; and the same sweep
   of sampled-data runs, `--control-period 0.002` (a digital controller at 500 Hz, the runs batched and compiled).
3. The same sweep (runs of `DASK_T_FINAL` s) through a Dask `LocalCluster` of 1 and of 2 single-threaded worker
   processes.

`python benchmarks/bench_batch.py [--sweep-runs N] [--dask-runs N] [--sweep-backends jax,numpy]`.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_single_run import ARM, DT, PHI, naive_rk4, naive_solve_ivp, timed

from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.sim import RK4
from robotadapt.sim.batch import simulate_batch
from robotadapt.studies.scenarios import load
from robotadapt.studies.sweep import make_sweep, run_sweep
from robotadapt.trajectories import sinusoid

T_SIM = 1.0
DASK_T_FINAL = 2.0
SIZES = (1, 10, 100, 1000, 10_000)


def per_run_baselines() -> tuple[float, float]:
    """Seconds per T_SIM-second run of the plain RK4 loop and of solve_ivp (medians of 3)."""
    return timed(lambda: naive_rk4(T_SIM), 3)[0], timed(lambda: naive_solve_ivp(T_SIM), 3)[0]


def batch(N: int, backend: str = "numpy") -> tuple[float, np.ndarray, tuple[float, float], float]:
    """Wall time of N runs in one simulate_batch; the final state, masses and K_v of the last run. With the jax backend
    the time is the second call's (steady state: the first one traces and compiles)."""
    rng = np.random.default_rng(N)
    phis = np.array(PHI) * rng.uniform(0.8, 1.2, size=(N, 2))
    kvs = rng.uniform(5.0, 20.0, size=N)
    plants = [Plant(ARM, phi) for phi in phis]
    ctrls = [InertiaRelated(ARM, Lam=2.5, Kv=kv, Gamma=20.0, phi_hat0=[0.0, 0.0]) for kv in kvs]
    for _ in range(2 if backend == "jax" else 1):
        t0 = time.perf_counter()
        res = simulate_batch(plants, ctrls, sinusoid(2), t_final=T_SIM, integrator=RK4(DT, backend), log_every=100)
        seconds = time.perf_counter() - t0
    assert res.ok.all()
    return seconds, res.z[-1, -1, :6], (float(phis[-1, 0]), float(phis[-1, 1])), float(kvs[-1])  # [q, q̇, φ̂]


def batch_table() -> None:
    loop, ivp = per_run_baselines()
    print(f"simulate_batch: N runs of Example 6.3.1, {T_SIM:g} s simulated each (RK4, 1 kHz), per-run masses and K_v")
    print(f"baselines measured here, per run: plain RK4 loop {loop:.3f} s, numpy + solve_ivp RK45 {ivp:.3f} s "
          "(N runs: N times that)")
    print(f"{'backend':>7} {'N':>6} {'wall (s)':>9} {'runs/s':>9} {'ms/run':>8} {'vs RK4 loop':>12} "
          f"{'vs solve_ivp':>13} {'check |Δ|':>10}")
    for backend in ("numpy", "jax"):
        for N in SIZES:
            seconds, state, phi, kv = batch(N, backend)
            diff = float(np.max(np.abs(state - naive_rk4(T_SIM, phi, kv))))
            if diff > 1e-9:
                sys.exit(f"{backend}, N = {N}: the last run's final state differs from the plain loop's by {diff:.2e}")
            print(f"{backend:>7} {N:>6} {seconds:>9.3f} {N / seconds:>9.1f} {1e3 * seconds / N:>8.2f} "
                  f"{loop * N / seconds:>11.1f}x {ivp * N / seconds:>12.1f}x {diff:>10.1e}")


def sweep_end_to_end(runs: int, loop_10s: float, backend: str, extra: tuple[str, ...] = ()) -> None:
    """The sweep as a user types it, in a fresh process with an empty compilation cache (compilation included)."""
    with tempfile.TemporaryDirectory() as out, tempfile.TemporaryDirectory() as cache:
        cmd = [sys.executable, "-m", "robotadapt", "sweep", "example-6.3.1", "--random", "controller.Kv=5:20",
               "--n", str(runs), "--backend", backend, *extra, "--out", out]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, ROBOTADAPT_CACHE=cache))
        seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(proc.stderr)
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"\nsweep end to end: {' '.join(['robotadapt'] + cmd[3:-2])} (10 s per run, local processes)")
    print(proc.stdout.splitlines()[0])
    print(f"wall {seconds:.1f} s = {1e3 * seconds / runs:.2f} ms per run, {runs / seconds:.1f} runs/s: "
          f"{loop_10s * runs / seconds:.0f}x the plain RK4 loop ({loop_10s:.2f} s per 10-s run); "
          f"peak RSS of the largest process {peak_mb:.0f} MB")


def dask_scaling(runs: int) -> None:
    """Chunks of up to 1000 runs, so `runs` ≥ 2000 gives both workers full-size chunks."""
    from dask.distributed import LocalCluster

    sweep = make_sweep(load("example-6.3.1", [f"simulation.t_final={DASK_T_FINAL}"]), random=["controller.Kv=5:20"],
                       n=runs)
    rates = {}
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                tempfile.TemporaryDirectory() as out:
            t0 = time.perf_counter()
            run_sweep(sweep, Path(out), scheduler=cluster.scheduler_address)
            rates[workers] = runs / (time.perf_counter() - t0)
    print(f"\nDask LocalCluster, {runs} runs of {DASK_T_FINAL:g} s, single-threaded worker processes: "
          f"1 worker {rates[1]:.0f} runs/s, 2 workers {rates[2]:.0f} runs/s, {rates[2] / rates[1]:.2f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep-runs", type=int, default=10_000)
    parser.add_argument("--dask-runs", type=int, default=2000)
    parser.add_argument("--sweep-backends", default="jax,numpy", help="backends of the end-to-end sweep")
    parser.add_argument("--only-sweeps", action="store_true", help="the end-to-end sweeps only (no table, no Dask)")
    args = parser.parse_args()
    if not args.only_sweeps:
        batch_table()
    loop_10s = timed(naive_rk4, 3)[0]
    for backend in args.sweep_backends.split(","):
        sweep_end_to_end(args.sweep_runs, loop_10s, backend)
    sweep_end_to_end(args.sweep_runs, loop_10s, "auto", ("--control-period", "0.002"))
    if not args.only_sweeps:
        dask_scaling(args.dask_runs)


if __name__ == "__main__":
    main()
