"""Speed of one closed-loop run against the baselines a user writes by hand (run by `make bench`, never by pytest).

Problem: Example 6.3.1 (Slotine–Li on the two-link arm, 10 s). Baselines, written out here:
  * numpy + scipy.integrate.solve_ivp (RK45, rtol 1e-6, atol 1e-8), the dynamics coded inline;
  * a plain Python fixed-step RK4 loop at 1 kHz on the same inline dynamics.
robotadapt runs the packaged scenario (RK4, 1 kHz). All three must reach the same final state; the table prints medians
over repeats and ratios against the solve_ivp baseline measured in the same run.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from scipy.integrate import solve_ivp

from robotadapt.scenarios import load

L1 = L2 = 1.0
G = 9.8
LAM, KV, GAM = 2.5, 10.0, 20.0
PHI = np.array([0.8, 2.3])


def _rhs(t: float, z: np.ndarray) -> np.ndarray:
    """The user's inline model: two-link arm + Slotine–Li (spec §1.3, Table 6.3.1)."""
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
    tau = Y @ np.array([m1h, m2h]) + KV * r
    m1, m2 = PHI
    M = np.array([[(m1 + m2) * L1**2 + m2 * L2**2 + 2 * m2 * L1 * L2 * c2, m2 * L2**2 + m2 * L1 * L2 * c2],
                  [m2 * L2**2 + m2 * L1 * L2 * c2, m2 * L2**2]])
    bias = np.array([-m2 * L1 * L2 * s2 * (2 * dq1 * dq2 + dq2**2) + (m1 + m2) * G * L1 * c1 + m2 * G * L2 * c12,
                     m2 * L1 * L2 * s2 * dq1**2 + m2 * G * L2 * c12])
    ddq = np.linalg.solve(M, tau - bias)
    return np.concatenate([[dq1, dq2], ddq, GAM * (Y.T @ r)])


def naive_solve_ivp() -> np.ndarray:
    return solve_ivp(_rhs, (0.0, 10.0), np.zeros(6), method="RK45", rtol=1e-6, atol=1e-8).y[:, -1]


def naive_rk4() -> np.ndarray:
    z, dt = np.zeros(6), 1e-3
    for k in range(10_000):
        t = k * dt
        k1 = _rhs(t, z)
        k2 = _rhs(t + dt / 2, z + dt / 2 * k1)
        k3 = _rhs(t + dt / 2, z + dt / 2 * k2)
        k4 = _rhs(t + dt, z + dt * k3)
        z = z + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return z


def robotadapt_rk4() -> np.ndarray:
    res = load("example-6.3.1").run()
    return np.concatenate([res.q[-1], res.dq[-1], res.x[-1]])


def _time(fn, repeats: int = 3) -> tuple[float, np.ndarray]:  # type: ignore[no-untyped-def]
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main() -> None:
    rows = [("numpy + solve_ivp RK45 (baseline)", naive_solve_ivp), ("plain Python RK4, 1 kHz", naive_rk4),
            ("robotadapt RK4, 1 kHz", robotadapt_rk4)]
    results = [(name, *_time(fn)) for name, fn in rows]
    base_time, base_state = results[0][1], results[0][2]
    print("Example 6.3.1, 10 s simulated, single run (median of 3)")
    print(f"{'method':<36} {'time (s)':>9} {'vs baseline':>12} {'max |Δ final state|':>20}")
    for name, seconds, state in results:
        print(f"{name:<36} {seconds:>9.3f} {base_time / seconds:>11.2f}x {np.max(np.abs(state - base_state)):>20.2e}")


if __name__ == "__main__":
    main()
