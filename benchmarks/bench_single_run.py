"""Speed of one closed-loop run against the baselines a user writes by hand (run by `make bench`, never by pytest).

Problem: Example 6.3.1 (Slotine–Li, Table 6.3.1, on the two-link arm of spec §1.3), 10 s simulated. The baselines are
written out here, with the dynamics coded inline as a user would:
  * numpy + scipy.integrate.solve_ivp (RK45, rtol 1e-6, atol 1e-8);
  * a plain Python fixed-step RK4 loop at 1 kHz.
robotadapt runs the same problem with `simulate` (RK4, 1 kHz; backends numpy, jax and c) and with `simulate_batch` for
one run. Every method must
reach the plain loop's final state: the fixed-step RK4 runs to round-off (1e-9), RK45 to its tolerance (1e-4 after
10 s). Prints medians over repeats and speed ratios against both baselines measured in the same run, and the start-up
cost of importing the library in a fresh interpreter.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp

from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, simulate
from robotadapt.sim.batch import simulate_batch
from robotadapt.trajectories import sinusoid

L1 = L2 = 1.0
G = 9.8
LAM, KV, GAM = 2.5, 10.0, 20.0
PHI = (0.8, 2.3)
T_FINAL, DT = 10.0, 1e-3


def rhs(t: float, z: np.ndarray, phi: tuple[float, float] = PHI, kv: float = KV) -> np.ndarray:
    """The user's inline model: two-link arm + Slotine–Li (spec §1.3, Table 6.3.1), q_d = sin t on both joints."""
    q1, q2, dq1, dq2, m1h, m2h = z
    qd, dqd, ddqd = np.sin(t), np.cos(t), -np.sin(t)
    e = np.array([qd - q1, qd - q2])
    de = np.array([dqd - dq1, dqd - dq2])
    r = de + LAM * e
    v = dqd + LAM * e
    a = ddqd + LAM * de
    c1, c2, s2, c12 = np.cos(q1), np.cos(q2), np.sin(q2), np.cos(q1 + q2)
    y11 = L1**2 * a[0] + L1 * G * c1
    y12 = ((L1**2 + L2**2 + 2 * L1 * L2 * c2) * a[0] + (L2**2 + L1 * L2 * c2) * a[1] - L1 * L2 * s2 * dq2 * v[0]
           - L1 * L2 * s2 * (dq1 + dq2) * v[1] + L1 * G * c1 + L2 * G * c12)
    y22 = (L2**2 + L1 * L2 * c2) * a[0] + L2**2 * a[1] + L1 * L2 * s2 * dq1 * v[0] + L2 * G * c12
    Y = np.array([[y11, y12], [0.0, y22]])
    tau = Y @ np.array([m1h, m2h]) + kv * r
    m1, m2 = phi
    M = np.array([[(m1 + m2) * L1**2 + m2 * L2**2 + 2 * m2 * L1 * L2 * c2, m2 * L2**2 + m2 * L1 * L2 * c2],
                  [m2 * L2**2 + m2 * L1 * L2 * c2, m2 * L2**2]])
    bias = np.array([-m2 * L1 * L2 * s2 * (2 * dq1 * dq2 + dq2**2) + (m1 + m2) * G * L1 * c1 + m2 * G * L2 * c12,
                     m2 * L1 * L2 * s2 * dq1**2 + m2 * G * L2 * c12])
    ddq = np.linalg.solve(M, tau - bias)
    return np.concatenate([[dq1, dq2], ddq, GAM * (Y.T @ r)])


def naive_solve_ivp(t_final: float = T_FINAL) -> np.ndarray:
    return solve_ivp(rhs, (0.0, t_final), np.zeros(6), method="RK45", rtol=1e-6, atol=1e-8).y[:, -1]


def naive_rk4(t_final: float = T_FINAL, phi: tuple[float, float] = PHI, kv: float = KV) -> np.ndarray:
    """The plain fixed-step loop at 1 kHz; returns the final state [q, q̇, φ̂]."""
    z = np.zeros(6)
    for k in range(round(t_final / DT)):
        t = k * DT
        k1 = rhs(t, z, phi, kv)
        k2 = rhs(t + DT / 2, z + DT / 2 * k1, phi, kv)
        k3 = rhs(t + DT / 2, z + DT / 2 * k2, phi, kv)
        k4 = rhs(t + DT, z + DT * k3, phi, kv)
        z = z + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return z


ARM = TwoLinkArm()
CTRL = InertiaRelated(ARM, Lam=LAM, Kv=KV, Gamma=GAM, phi_hat0=[0.0, 0.0])


def robotadapt_simulate(backend: str = "numpy") -> np.ndarray:
    res = simulate(Plant(ARM, PHI), CTRL, sinusoid(2), t_final=T_FINAL, integrator=RK4(DT, backend), log_every=1000)
    return np.concatenate([res.q[-1], res.dq[-1], res.x[-1]])


def robotadapt_jax() -> np.ndarray:
    return robotadapt_simulate("jax")


def robotadapt_c() -> np.ndarray:
    return robotadapt_simulate("c")


def first_run_seconds(backend: str) -> tuple[float, float]:
    """Wall time of a fresh process's first compiled run on `backend` (import, tracing, compilation, run), with an empty
    cache and then with the programs the first process left on disk (C: found without tracing, JAX not imported)."""
    import tempfile

    script = (f"import time; t0 = time.perf_counter(); from bench_single_run import robotadapt_simulate; "
              f"robotadapt_simulate({backend!r}); print(time.perf_counter() - t0)")
    out = []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(INSTALLED, ROBOTADAPT_CACHE=cache)
        for _ in range(2):
            done = subprocess.run([sys.executable, "-c", script], check=True, capture_output=True, text=True, env=env,
                                  cwd=os.path.dirname(os.path.abspath(__file__)))
            out.append(float(done.stdout.split()[-1]))
    return out[0], out[1]


def fresh_cli_seconds(repeats: int = 3) -> float:
    """Median wall time of a fresh `robotadapt run example-6.3.1` (default backend, the three figures written) once a
    first run has stored its program."""
    import tempfile

    with tempfile.TemporaryDirectory() as out:
        return import_seconds_of([sys.executable, "-m", "robotadapt", "run", "example-6.3.1", "--out", out], repeats)


def robotadapt_batch_of_one() -> np.ndarray:
    res = simulate_batch(Plant(ARM, PHI), CTRL, sinusoid(2), t_final=T_FINAL, integrator=RK4(DT),
                         q0=np.zeros((1, 2)), log_every=1000)
    return res.z[-1, 0, :6]  # [q, q̇, φ̂]: the monitors' integrals trail the state


def timed(fn: Callable[[], np.ndarray], repeats: int) -> tuple[float, np.ndarray]:
    """Median wall time over `repeats` calls, and the last result."""
    times, out = [], np.empty(0)
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


#: a fresh process's environment as an installed package starts: with Python's bytecode cache. This machine's shell sets
#: PYTHONDONTWRITEBYTECODE=1, under which every start compiles the package's 120 modules from source again (about
#: 0.2 s of `import robotadapt.sim`, cProfile) — which an installed copy, compiled by pip at install, never does
INSTALLED = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def import_seconds_of(command: list[str], repeats: int) -> float:
    """Median wall time of a fresh process running `command` (in :data:`INSTALLED`), after one untimed start (which
    leaves the bytecode cache and any program the command builds on disk)."""
    times = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True, env=INSTALLED)
        times.append(time.perf_counter() - t0)
    return statistics.median(times[1:])


def import_seconds(statement: str, repeats: int = 5) -> float:
    """Median wall time of a fresh interpreter running `statement`."""
    return import_seconds_of([sys.executable, "-c", statement], repeats)


def main() -> None:
    rows = [("numpy + solve_ivp RK45 (rtol 1e-6)", naive_solve_ivp, 1e-4),
            ("plain Python RK4 loop, 1 kHz", naive_rk4, 0.0),
            ("robotadapt simulate, RK4 1 kHz", robotadapt_simulate, 1e-9),
            ("robotadapt simulate_batch, 1 run", robotadapt_batch_of_one, 1e-9),
            ("robotadapt simulate, backend jax", robotadapt_jax, 1e-9),
            ("robotadapt simulate, backend c", robotadapt_c, 1e-9)]
    for warm in (robotadapt_jax, robotadapt_c, robotadapt_jax, robotadapt_c):  # steady state: compilation timed apart
        warm()
    results = [(name, *timed(fn, 3), tol) for name, fn, tol in rows]
    t_ivp, t_loop, reference = results[0][1], results[1][1], results[1][2]
    print(f"Example 6.3.1, {T_FINAL:g} s simulated, one run (median of 3); speed-up = baseline time / time")
    print(f"{'method':<36} {'time (s)':>9} {'vs RK4 loop':>12} {'vs solve_ivp':>13} {'max |Δ final state|':>20}")
    failed = []
    for name, seconds, state, tol in results:
        diff = float(np.max(np.abs(state - reference)))
        print(f"{name:<36} {seconds:>9.3f} {t_loop / seconds:>11.2f}x {t_ivp / seconds:>12.2f}x {diff:>20.2e}")
        if diff > tol and tol > 0:
            failed.append(f"{name}: final state differs from the plain loop's by {diff:.2e} > {tol:g}")
    print()
    for backend in ("jax", "c"):
        cold, warm = first_run_seconds(backend)
        print(f"{backend} backend, first run of a fresh process (import, trace, "
              f"compile, run): {cold:.2f} s with an empty cache, {warm:.2f} s with the program on disk")
    cli = fresh_cli_seconds()
    print(f"a fresh `robotadapt run example-6.3.1` with its figures, program on disk: {cli:.2f} s = "
          f"{cli / t_loop:.2f}x the plain loop (goal ≤ 1.5x)")
    python = import_seconds("pass")
    top = import_seconds("import robotadapt")
    lib = import_seconds("import robotadapt.sim, robotadapt.sim.batch, robotadapt.studies.scenarios")
    print(f"start-up: a fresh python {python:.3f} s; `import robotadapt` adds {top - python:.3f} s; the simulator, "
          f"batches and scenarios {lib - python:.3f} s")
    if failed:
        sys.exit("\n".join(failed))


if __name__ == "__main__":
    main()
