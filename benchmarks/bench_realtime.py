"""Step latency of `robotadapt.realtime.RealtimeController` (issue 18; run by `make bench`, never by pytest).

For the two-link arm (Example 6.3.1), the PUMA 560 and the Panda (Slotine–Li, Table 6.3.1): `reset` at the desired
start, then `step(t, q, dq)` every tick with the desired state plus a small error as the measurement, as a driver's
1 kHz callback would call it (no plant: the controller alone). Each call is timed with `perf_counter_ns`, the garbage
collector off, as in a real-time loop; prints p50, p99 and max per arm and backend as a markdown table, the goals
(issue 22: the compiled step p99 ≤ 50 µs, max ≤ 500 µs; issue 28: through RealtimeController's C backend p99 ≤ 15 µs
two-link, ≤ 30 µs Panda) and the machine's load average before and after (other processes on the same cores show up in
p99 and max). The "C from C" row times the exported `ra_step` inside a C program (`clock_gettime` around each call,
the inputs read beforehand; goal p99 ≤ 5 µs two-link, ≤ 20 µs Panda, ≤ 5 µs the Panda's task-space Slotine–Li, issue
44): what a robot's callback pays. The compiled
backends take `STEPS` steps; the numpy one, 5–50 times slower, a tenth of them.
"""

from __future__ import annotations

import gc
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from robotadapt.native.build import require_compiler
from robotadapt.realtime import RealtimeController
from robotadapt.studies.scenarios import load

STEPS = 100_000
ARMS = (("two-link arm", "example-6.3.1"), ("PUMA 560", "puma560-slotine-li"), ("Panda", "panda-slotine-li"),
        ("Panda, task-space Slotine–Li", "panda-task-circle"))
GOAL_P99_US, GOAL_MAX_US = 50.0, 500.0  # of the compiled step


def measured(scenario: str, ctrl: RealtimeController, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The measurements: the desired joint state (a task-space law's: the arm's start) with a small error."""
    ref = ctrl.trajectory(t)
    q, dq = np.asarray(ref.q_des), np.asarray(ref.dq_des)
    if q.shape[-1] != ctrl.n:
        start = load(scenario).setup
        q, dq = np.broadcast_to(start.q0, (t.size, ctrl.n)), np.broadcast_to(start.dq0, (t.size, ctrl.n))
    return q + 1e-3 * np.sin(t)[:, None], dq + 1e-3 * np.cos(t)[:, None]


def latencies(scenario: str, backend: str, steps: int) -> np.ndarray:
    """The time of each of `steps` calls of step(t, q, dq), µs."""
    ctrl = RealtimeController.from_scenario(scenario, backend=backend)
    t = ctrl.Ts * np.arange(steps)
    q, dq = measured(scenario, ctrl, t)
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


TIMER = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "ra.h"
int main(int argc, char **argv) {
    long steps = atol(argv[1]);
    int n = ra_n();
    double *rows = malloc(steps * (1 + 2 * n) * sizeof(double)), *state = malloc(ra_state_size() * sizeof(double));
    double tau[64];
    for (long i = 0; i < steps * (1 + 2 * n); i++) if (scanf("%lf", &rows[i]) != 1) return 1;
    ra_reset(state, rows + 1, rows + 1 + n);
    for (long k = 0; k < steps; k++) {
        double *r = rows + k * (1 + 2 * n);
        struct timespec a, b;
        clock_gettime(CLOCK_MONOTONIC, &a);
        ra_step(state, r[0], r + 1, r + 1 + n, tau);
        clock_gettime(CLOCK_MONOTONIC, &b);
        printf("%ld\n", (b.tv_sec - a.tv_sec) * 1000000000L + (b.tv_nsec - a.tv_nsec));
    }
    return 0;
}
"""


def c_latencies(scenario: str, steps: int) -> np.ndarray:
    """The time of each of `steps` calls of the exported ra_step inside a C program, µs."""
    cc = require_compiler("bench")
    ctrl = RealtimeController.from_scenario(scenario, backend="numpy")
    t = ctrl.Ts * np.arange(steps)
    rows = np.column_stack([t, *measured(scenario, ctrl, t)])
    code = ctrl.export("ra")
    with tempfile.TemporaryDirectory() as tmp:
        for name, text in (("ra.h", code.header), ("ra.c", code.source), ("timer.c", TIMER)):
            (Path(tmp) / name).write_text(text)
        subprocess.run([cc, "-O2", "-o", "timer", "timer.c", "ra.c", "-lm"], cwd=tmp, check=True)
        text = "\n".join(" ".join(f"{v:.17g}" for v in r) for r in rows)
        done = subprocess.run(["./timer", str(steps)], cwd=tmp, input=text, capture_output=True, text=True, check=True)
    return np.array(done.stdout.split(), dtype=float) / 1e3


def main() -> int:
    steps = int(sys.argv[1]) if len(sys.argv) > 1 else STEPS
    print(f"step latency over {steps} steps (numpy: {steps // 10}); load average {os.getloadavg()[0]:.2f} on "
          f"{os.cpu_count()} cores; goal (jax) p99 ≤ {GOAL_P99_US:g} µs, max ≤ {GOAL_MAX_US:g} µs")
    print("| arm | backend | p50 (µs) | p99 (µs) | max (µs) |")
    print("|---|---|---|---|---|")
    for name, scenario in ARMS:
        for backend, count in (("C from C", steps), ("c", steps), ("jax", steps), ("numpy", steps // 10)):
            lat = c_latencies(scenario, count) if backend == "C from C" else latencies(scenario, backend, count)
            p50, p99 = np.percentile(lat, [50, 99])
            print(f"| {name} | {backend} | {p50:.1f} | {p99:.1f} | {lat.max():.0f} |", flush=True)
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
