"""Scaling with the number of joints: per-step cost of the model terms and of one Slotine–Li control step on arms from
DH tables (robotadapt.robots.symbolic), with ratios to Pinocchio's `rnea` (inverse dynamics, C++) on the same arm,
measured in the same run. Run by `make bench`, or alone: `python benchmarks/bench_ndof_scaling.py`.

Arms: a spatial chain of n = 2…7 revolute joints (twists alternating ±90°, a = 0.3 m, d = 0.1 m, offset centres of
mass), the PUMA 560, and a 14-link planar chain of uniform rods; Pinocchio gets the same arm from
`SymbolicArm.pinocchio_model()`. One state per call (what a real-time loop evaluates), states cycled from 64 random ones;
medians over repeats. "batch" is the cost per state of one vectorized call on 1000 states. Also timed: building each arm
with an empty disk cache (sympy derivation, code generation, compilation) and again from the cache in a fresh memory.
"""

from __future__ import annotations

import math
import os
import statistics
import tempfile
import time
from collections.abc import Callable

import numpy as np

from robotadapt.controllers import InertiaRelated
from robotadapt.robots import dh
from robotadapt.robots.pinocchio import PinocchioArm
from robotadapt.robots.symbolic import SymbolicArm, planar_arm, puma560
from robotadapt.trajectories import Reference

CALLS = 500
STATES = 64


def spatial_chain(n: int) -> SymbolicArm:
    alpha = [(-1) ** i * math.pi / 2 for i in range(n)]
    inertia = np.array([np.diag([0.02, 0.03, 0.04])] * n)
    return SymbolicArm("R" * n, [0.3] * n, alpha, [0.1] * n, [0.0] * n, [1.0] * n, [[0.05, 0.02, -0.03]] * n, inertia)


ARMS: dict[str, Callable[[], SymbolicArm]] = {
    **{f"spatial {n}R": (lambda n=n: spatial_chain(n)) for n in range(2, 8)},
    "PUMA 560": puma560,
    "planar 14R": lambda: planar_arm(14, lengths=0.2, masses=0.5, rods=True),
}


def per_call(step: Callable[[int], object], repeats: int = 5) -> float:
    """Median over repeats of the mean time of one call, in microseconds."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(CALLS):
            step(k % STATES)
        times.append((time.perf_counter() - t0) / CALLS * 1e6)
    return statistics.median(times)


def load_times(build: Callable[[], SymbolicArm]) -> tuple[SymbolicArm, float, float]:
    """(arm, seconds to build with an empty cache, seconds from the disk cache with the in-memory cache cleared)."""
    dh.compiled.cache_clear()
    t0 = time.perf_counter()
    model = build()
    first = time.perf_counter() - t0
    dh.compiled.cache_clear()
    t0 = time.perf_counter()
    model = build()
    return model, first, time.perf_counter() - t0


def costs(model: SymbolicArm) -> dict[str, float]:
    import pinocchio as pin

    n, p = model.n, model.p
    rng = np.random.default_rng(0)
    q, dq, v, a = rng.uniform(-1.0, 1.0, (4, STATES, n))
    phi = model.default_phi
    pm = model.pinocchio_model()
    data = pm.createData()
    urdf = PinocchioArm(pm)
    ctrl = InertiaRelated(model, Lam=5.0, Kv=20.0, Gamma=1.0, phi_hat0=0.7 * phi)
    refs = [Reference(q[k] + 0.01, dq[k] + 0.01, a[k]) for k in range(STATES)]
    batch = rng.uniform(-1.0, 1.0, (4, 1000, n))
    batch_times = []
    for _ in range(5):
        t0 = time.perf_counter()
        model.regressor(*batch)
        batch_times.append((time.perf_counter() - t0) / 1000 * 1e6)
    return {
        "rnea": per_call(lambda k: pin.rnea(pm, data, q[k], dq[k], a[k])),
        "Y": per_call(lambda k: model.regressor(q[k], dq[k], v[k], a[k])),
        "M": per_call(lambda k: model.mass_matrix(q[k], phi)),
        "V_m": per_call(lambda k: model.coriolis_matrix(q[k], dq[k], phi)),
        "G": per_call(lambda k: model.gravity(q[k], phi)),
        "fwd dyn": per_call(lambda k: model.forward_dynamics(q[k], dq[k], a[k], phi)),
        "SL step": per_call(lambda k: ctrl(0.0, phi, q[k], dq[k], refs[k])),
        "Y (pin)": per_call(lambda k: urdf.regressor(q[k], dq[k], v[k], a[k])),
        "Y batch": statistics.median(batch_times),
        "p": p,
    }


def main() -> None:
    columns = ["Y", "M", "V_m", "G", "fwd dyn", "SL step", "Y batch", "Y (pin)"]
    print("Per-step cost on arms from DH tables (µs per state, median of 5 × 500 calls), and × Pinocchio's rnea on the "
          "same arm, same run")
    print("Y: mixed regressor Y(q, q̇, v, a); fwd dyn: M⁻¹(τ − V_m q̇ − G); SL step: one Slotine–Li control step "
          "(Table 6.3.1: Y, τ, dφ̂/dt); Y batch: one call on 1000 states, per state;\nY (pin): the same mixed regressor "
          "from Pinocchio's joint-torque regressor (PinocchioArm on the same pin.Model), for comparison")
    header = f"{'arm':<12} {'n':>3} {'p':>4} {'build':>8} {'cached':>8} {'rnea':>6}"
    header += "".join(f" {c:>17}" for c in columns)
    print("\n" + header)
    with tempfile.TemporaryDirectory() as cache:
        os.environ["ROBOTADAPT_CACHE"] = cache  # an empty cache: the first build derives
        for label, build in ARMS.items():
            model, first, cached = load_times(build)
            c = costs(model)
            base = c["rnea"]
            row = f"{label:<12} {model.n:>3} {int(c['p']):>4} {first:>7.2f}s {cached * 1e3:>6.1f}ms {base:>6.2f}"
            row += "".join(f" {c[k]:>8.1f} {c[k] / base:>6.1f}x " for k in columns)
            print(row)


if __name__ == "__main__":
    main()
