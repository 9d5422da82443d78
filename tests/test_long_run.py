"""Long runs: memory stays at the decimated log (no per-step growth) and V(t) does not drift (issue 9; the 10⁶-step
version is benchmarks/bench_long_run.py)."""

import tracemalloc

import numpy as np

from robotadapt.analysis.metrics import metrics
from robotadapt.studies.scenarios import load


def _fill_free_lists() -> None:
    """Fill CPython's tuple free lists (at most 2000 tuples of each length below 20): tracemalloc counts a tuple kept
    there as allocated, so a loop that only ever returns tuples to them would otherwise look like one that grows."""
    held = [tuple(range(i, i + length)) for length in range(1, 20) for i in range(2_500)]
    del held


def _peak_bytes(steps: int, log_every: int) -> tuple[int, object]:
    scenario = load("example-6.3.1", [f"simulation.t_final={steps * 1e-3!r}", f"simulation.log_every={log_every}"])
    _fill_free_lists()
    tracemalloc.start()
    result = scenario.run()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak, result


def test_memory_does_not_grow_with_the_number_of_steps(monkeypatch):
    """Three times the steps with the same number of logged samples: the same peak memory (within 20 %). Both runs span
    more than two chunks of the vectorized reference (made small here: tracemalloc slows every allocation), so the
    chunk buffer is the same size in both; a warm-up run first keeps one-time allocations (imports, caches) out."""
    monkeypatch.setattr("robotadapt.sim.driver.CHUNK", 64)
    _peak_bytes(200, 2)
    short, _ = _peak_bytes(500, 5)
    long, res = _peak_bytes(1_500, 15)
    assert res.t.size == 101
    assert long < 1.2 * short, (short, long)


def test_lyapunov_function_does_not_drift_on_a_long_run():
    """Example 6.3.1 over 30 s (30 000 RK4 steps): V keeps falling to round-off; it never climbs back."""
    res = load("example-6.3.1", ["simulation.t_final=30", "simulation.log_every=100"]).run()
    assert res.ok
    assert metrics(res)["lyapunov_max_rel_increase"] < 1e-12
    assert res.V[-1] < 1e-12 * res.V[0]
    assert np.all(np.abs(res.e[-1]) < 1e-9)
