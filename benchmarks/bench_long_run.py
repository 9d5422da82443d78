"""A 10⁶-step run (Example 6.3.1, dt = 1 ms, 1000 s simulated) with a decimated log: peak memory against a 10⁴-step run
with the same log size (no per-step growth), V(t) drift, and throughput. Run by `make bench`."""

from __future__ import annotations

import time
import tracemalloc

import numpy as np

from robotadapt.analysis.metrics import metrics
from robotadapt.studies.scenarios import load


def run(steps: int) -> tuple[float, float, object]:
    scenario = load("example-6.3.1", [f"simulation.t_final={steps * 1e-3!r}", f"simulation.log_every={steps // 1000}"])
    tracemalloc.start()
    t0 = time.perf_counter()
    result = scenario.run(progress=True)
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return seconds, peak, result


def main() -> None:
    base_s, base_peak, _ = run(10_000)
    seconds, peak, res = run(1_000_000)
    m = metrics(res)
    print("Long run: Example 6.3.1, 10^6 RK4 steps of 1 ms, 1001 logged samples")
    print(f"  status {m['status']}, wall {seconds:.1f} s ({1e6 / seconds:,.0f} steps/s; 10^4 steps took {base_s:.2f} s)")
    print(f"  peak traced memory {peak / 1e6:.2f} MB vs {base_peak / 1e6:.2f} MB for 10^4 steps "
          f"(ratio {peak / base_peak:.2f}: no per-step growth)")
    print(f"  V(0) = {m['V_initial']:.4g}, V(end) = {m['V_final']:.3g}, largest step increase / V(0) = "
          f"{m['lyapunov_max_rel_increase']:.2g}, final |e| = {np.max(m['final_abs_error']):.2g}")


if __name__ == "__main__":
    main()
