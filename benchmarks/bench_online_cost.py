"""On-line cost of the §7.2 laws: compute time of one control step (torque and state update) for each controller,
with ratios to Slotine–Li measured in the same run (spec §8–§9: DCAL's Y_d can be tabulated ahead of time, the
repetitive law needs no regressor at all). Run by `make bench`, or alone: `python benchmarks/bench_online_cost.py`.

One control step is what a real-time loop evaluates per sample: for Slotine–Li and DCAL `ctrl(t, x, q, dq, ref)`; for
adaptive computed torque `torque` then `update` (with the measured q̈); for the repetitive law `sample` (the delay
line) then the torque. States are random points near the desired trajectory; the least of several repeats.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from robotadapt.controllers import DCAL, AdaptiveComputedTorque, InertiaRelated, Repetitive
from robotadapt.robots import PolarArm, RobotModel, TwoLinkArm
from robotadapt.trajectories import sinusoid

STEPS = 2000
DT = 2 * np.pi / 4000


def _per_step(step: Callable[[int], object], repeats: int = 7) -> float:
    """Least over repeats of the mean time of one call, in microseconds: on a shared virtual machine the other tenants
    only ever add time, so the least repeat is the cost of the code (as `timeit` advises)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(STEPS):
            step(k)
        times.append((time.perf_counter() - t0) / STEPS * 1e6)
    return min(times)


def _cases(model: RobotModel, traj) -> dict[str, Callable[[int], object]]:  # type: ignore[no-untyped-def]
    n, p = model.n, model.p
    rng = np.random.default_rng(0)
    t = DT * np.arange(STEPS)
    ref_all = traj(t)
    refs = [type(ref_all)(ref_all.q_des[k], ref_all.dq_des[k], ref_all.ddq_des[k]) for k in range(STEPS)]
    q = ref_all.q_des + 0.05 * rng.normal(size=(STEPS, n))
    dq = ref_all.dq_des + 0.05 * rng.normal(size=(STEPS, n))
    ddq = ref_all.ddq_des
    phi = np.ones(p) if model.default_phi is None else np.asarray(model.default_phi)  # n-DOF: M̂ must stay PD
    sl = InertiaRelated(model, Lam=2.5, Kv=10, Gamma=20, phi_hat0=phi)
    ct = AdaptiveComputedTorque(model, Kp=125, Kv=50, Gamma=500, phi_hat0=phi)
    dcal = DCAL(model, Kv=50, Kp=50, Ka=50, Gamma=20, phi_hat0=phi)
    dcal_table = DCAL(model, Kv=50, Kp=50, Ka=50, Gamma=20, phi_hat0=phi, precompute=True).prepare(traj, 2 * DT, t[-1])
    rcl = Repetitive(model, Kv=50, Kp=50, Ka=50, kL=50).prepare(traj, DT, t[-1])
    line = rcl.delay_line(DT, q[0], dq[0])
    x_rcl = rcl.initial_state(q[0], dq[0])  # its state: û_d, the integrals of its monitor (7.2.43)

    def repetitive(k: int) -> object:
        held, store = rcl.sample(t[k], x_rcl, q[k], dq[k], refs[k], line[k % line.shape[0]])
        line[k % line.shape[0]] = store
        return rcl(t[k], held, q[k], dq[k], refs[k])

    return {
        "Slotine–Li (Table 6.3.1)": lambda k: sl(t[k], phi, q[k], dq[k], refs[k]),
        "adaptive computed torque (Table 6.2.1)": lambda k: ct.update(t[k], phi, q[k], dq[k], ddq[k], refs[k])
        if ct.torque(t[k], phi, q[k], dq[k], refs[k]) is not None else None,
        "DCAL, Y_d on line (Table 7.2.1)": lambda k: dcal(t[k], phi, q[k], dq[k], refs[k]),
        "DCAL, Y_d precomputed": lambda k: dcal_table(t[k], phi, q[k], dq[k], refs[k]),
        "repetitive (Table 7.2.2)": repetitive,
    }


def _n_dof() -> dict[str, tuple[RobotModel, object]]:
    """The n-DOF models whose extras are installed: PUMA 560 (sympy, [symbolic]), Panda (Pinocchio, [urdf])."""
    out: dict[str, tuple[RobotModel, object]] = {}
    try:
        from robotadapt.robots.symbolic import puma560

        out["PUMA 560, DH table (sympy)"] = (puma560(), sinusoid(6, amplitude=0.3, offset=[0, -0.5, 0.5, 0, 0.3, 0]))
    except ImportError as exc:
        print(f"(PUMA 560 skipped: {exc})")
    try:
        from robotadapt.robots.pinocchio import PinocchioArm

        out["Franka Panda, URDF (Pinocchio)"] = (PinocchioArm.example("panda"),
                                                 sinusoid(7, amplitude=0.3, offset=[0, -0.785, 0, -2.356, 0, 1.571, 0.785]))
    except (ImportError, ValueError) as exc:
        print(f"(Panda skipped: {exc})")
    return out


def main() -> None:
    traj = sinusoid(2, amplitude=[1.0, 0.2], offset=[0.0, 1.0])
    models = {"two-link arm": (TwoLinkArm(), sinusoid(2)), "polar arm": (PolarArm(), traj)}
    models.update(_n_dof())
    print(f"On-line cost of one control step (µs, least of 7 × {STEPS} steps), ratio to Slotine–Li in the same run")
    for label, (model, trajectory) in models.items():
        results = {name: _per_step(step) for name, step in _cases(model, trajectory).items()}
        base = results["Slotine–Li (Table 6.3.1)"]
        print(f"\n{label} (n = {model.n}, p = {model.p})")
        print(f"{'controller':<42} {'µs/step':>8} {'vs Slotine–Li':>14}")
        for name, us in results.items():
            print(f"{name:<42} {us:>8.1f} {us / base:>13.2f}x")


if __name__ == "__main__":
    main()
