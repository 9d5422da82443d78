"""Step latency of `robotadapt.realtime.RealtimeController` (issue 18; run by `make bench`, never by pytest).

For the two-link arm (Example 6.3.1), the PUMA 560 and the Panda (Slotine–Li, Table 6.3.1): `reset` at the desired
start, then `step(t, q, dq)` every tick with the desired state plus a small error as the measurement, as a driver's
1 kHz callback would call it (no plant: the controller alone). Each call is timed with `perf_counter_ns`, the garbage
collector off, as in a real-time loop; prints p50, p99 and max per arm and backend as a markdown table, the goal of the
compiled step (p99 ≤ 50 µs, max ≤ 500 µs; issue 22) and the machine's load average before and after (other processes
on the same cores show up in p99 and max). The compiled backend takes `STEPS` steps; the numpy one, 5–50 times slower,
a tenth of them.
"""

from __future__ import annotations

import gc
import os
import sys
import time

import numpy as np

from robotadapt.realtime import RealtimeController

STEPS = 100_000
ARMS = (("two-link arm", "example-6.3.1"), ("PUMA 560", "puma560-slotine-li"), ("Panda", "panda-slotine-li"))
GOAL_P99_US, GOAL_MAX_US = 50.0, 500.0  # of the compiled step


def latencies(scenario: str, backend: str, steps: int) -> np.ndarray:
    """The time of each of `steps` calls of step(t, q, dq), µs."""
    ctrl = RealtimeController.from_scenario(scenario, backend=backend)
    t = ctrl.Ts * np.arange(steps)
    ref = ctrl.trajectory(t)
    q, dq = ref.q_des + 1e-3 * np.sin(t)[:, None], ref.dq_des + 1e-3 * np.cos(t)[:, None]  # a small tracking error
    ctrl.reset(q[0], dq[0])
    ctrl.step(0.0, q[0], dq[0])  # the first call of a program may load it: not part of the loop
    out = np.empty(steps)
    gc.disable()
    try:
        for k in range(steps):
            start = time.perf_counter_ns()
            ctrl.step(t[k], q[k], dq[k])
            out[k] = time.perf_counter_ns() - start
    finally:
        gc.enable()
    return out / 1e3


def main() -> int:
    steps = int(sys.argv[1]) if len(sys.argv) > 1 else STEPS
    print(f"step latency over {steps} steps (numpy: {steps // 10}); load average {os.getloadavg()[0]:.2f} on "
          f"{os.cpu_count()} cores; goal (jax) p99 ≤ {GOAL_P99_US:g} µs, max ≤ {GOAL_MAX_US:g} µs")
    print("| arm | backend | p50 (µs) | p99 (µs) | max (µs) |")
    print("|---|---|---|---|---|")
    for name, scenario in ARMS:
        for backend, count in (("jax", steps), ("numpy", steps // 10)):
            lat = latencies(scenario, backend, count)
            p50, p99 = np.percentile(lat, [50, 99])
            print(f"| {name} | {backend} | {p50:.1f} | {p99:.1f} | {lat.max():.0f} |", flush=True)
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
