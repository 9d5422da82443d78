"""The sampled-data loop (:class:`robotadapt.simulation.Sampled`): a digital controller at its ticks t_k = k·Ts, a
zero-order hold on the torque, the plant integrated between ticks.

One tick k:

1. measure (q_m, q̇_m, q̈_m) from the plant's state through its sensor (:mod:`robotadapt.sensors`; exact samples
   without one);
2. a delay line (the repetitive law, N = T/Ts ticks per period) is read and written with the measured signals;
3. the controller gives τ_k and ẋ_k from (t_k, x_k, q_m, q̇_m, ref(t_k));
4. the actuator turns τ_k into the applied u_k (delay, saturation, rate limit; :mod:`robotadapt.actuators`);
5. every `log_every` ticks: t_k, the true state s_k, x_k, u_k, τ_k, q_m, q̇_m are logged;
6. the plant: `substeps` RK4 steps of dt = Ts/substeps of ds/dt = f(t, s, u_k); the controller's state: x_{k+1} by the
   discrete rule ("euler" or "hold"), projected;
7. the divergence guard on (s_{k+1}, x_{k+1}).

The last tick (t = t_final) is measured, computed and logged, not integrated.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from ..controllers.base import HasProjection, SimulationStop
from ..plant.actuators import Actuator
from ..plant.sensors import Sensor
from .loop import CHUNK, diverged, take

if TYPE_CHECKING:
    from ..plant.plant import Plant
    from ..trajectories import Reference, Trajectory
    from .integrators import Sampled
    from .loop import ClosedLoop, DelayLine

Array = Any
Rate = Callable[[Array], Array]


def _controller(loop: ClosedLoop, t: float, x: Array, q: Array, dq: Array, ddq: Array, ref: Reference, actuator: Actuator,
                pending: Any, Ts: float) -> tuple[Array, Array, Any, Array, Rate]:
    """τ_k, the applied u_k and the actuator's next state, ẋ_k, and the map x ↦ ẋ with every other input (u_k too)
    held at its sample. A law that filters the torque (FiltersTorque) filters u_k."""
    ctrl: Any = loop.controller
    if loop.needs_acceleration:
        def rate(x: Array) -> Array:
            return ctrl.update(t, x, q, dq, ddq, ref)

        tau = ctrl.torque(t, x, q, dq, ref)
        u, pending = actuator.apply(pending, tau, Ts)
        return tau, u, pending, rate(x), rate

    def held(x: Array) -> Array:
        tau, dx = ctrl(t, x, q, dq, ref)
        return ctrl.applied(dx, tau, u) if loop.filters_torque else dx

    tau, dx = ctrl(t, x, q, dq, ref)
    u, pending = actuator.apply(pending, tau, Ts)
    return tau, u, pending, ctrl.applied(dx, tau, u) if loop.filters_torque else dx, held


def _rk4(f: Callable[[float, Array], Array], t: float, y: Array, h: float) -> Array:
    k1 = f(t, y)
    k2 = f(t + 0.5 * h, y + 0.5 * h * k1)
    k3 = f(t + 0.5 * h, y + 0.5 * h * k2)
    k4 = f(t + h, y + h * k3)
    return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def _next_state(opts: Sampled, x: Array, dx: Array, rate: Rate, project: Callable[[Array], Array] | None) -> Array:
    """x_{k+1} by the discrete rule, projected."""
    if opts.discretization == "euler":
        x = x + opts.control_period * dx
        return x if project is None else project(x)
    for _ in range(opts.substeps):
        x = _rk4(lambda _t, y: rate(y), 0.0, x, opts.dt)
        x = x if project is None else project(x)
    return x


def _hold(plant: Plant, t: float, s: Array, u: Array, h: float, substeps: int) -> Array:
    """The plant's state one control period on, under the held torque u: `substeps` RK4 steps of h."""
    for i in range(substeps):
        s = _rk4(lambda t, s: plant.derivative(t, s, u), t + i * h, s, h)
    return s


def integrate(loop: ClosedLoop, traj: Trajectory, z0: Array, opts: Sampled, n_ticks: int, log_every: int,
              max_state: float, progress: bool,
              line: DelayLine | None) -> tuple[Array, Array, str, dict[str, Array]]:
    """Ticks 0 … `n_ticks` from t = 0; returns the logged (t, z), the status and the logged signals (`tau` applied,
    and `tau_commanded` with an actuator, `q_measured`, `dq_measured` with a sensor)."""
    from tqdm import tqdm

    plant, n, m = loop.plant, loop.n, loop.m
    Ts, h = opts.control_period, opts.dt
    measure = (plant.sensor or Sensor(n)).start(z0[:n], z0[n : 2 * n], Ts)
    actuator = plant.actuator or Actuator(n)
    pending = actuator.start()
    project = loop.controller.project if isinstance(loop.controller, HasProjection) else None
    n_log = n_ticks // log_every + 1
    t_log = np.empty(n_log)
    logs = {name: np.empty((n_log, width)) for name, width in
            (("z", z0.size), ("tau", n), ("tau_commanded", n), ("q_measured", n), ("dq_measured", n))}
    s, x, k_log, status, start = z0[:m], z0[m:], 0, "ok", 0
    with tqdm(total=n_ticks + 1, delay=1.0, disable=not progress, unit="tick", leave=False, file=sys.stderr) as bar, \
            np.errstate(all="ignore"):
        while status == "ok" and start <= n_ticks:
            count = min(CHUNK, n_ticks + 1 - start)
            ref = traj(Ts * (start + np.arange(count)))
            for k in range(start, start + count):
                t, r = k * Ts, take(ref, k - start)
                q_m, dq_m, ddq_m = measure(s[:n], s[n : 2 * n])
                try:
                    if line is not None:
                        x = line.advance(loop.controller, k, t, x, q_m, dq_m, r)
                    tau, u, pending, dx, rate = _controller(loop, t, x, q_m, dq_m, ddq_m, r, actuator, pending, Ts)
                    if k % log_every == 0:
                        t_log[k_log] = t
                        for name, value in (("z", np.concatenate([s, x])), ("tau", u), ("tau_commanded", tau),
                                            ("q_measured", q_m), ("dq_measured", dq_m)):
                            logs[name][k_log] = value
                        k_log += 1
                    if k == n_ticks:
                        break
                    x_new = _next_state(opts, x, dx, rate, project)
                except SimulationStop as stop:
                    status = f"diverged at t={t:.6g} s: {stop}"
                    break
                s_new = _hold(plant, t, s, u, h, opts.substeps)
                reason = diverged(np.concatenate([s_new, x_new]), max_state)
                if reason is not None:
                    status = f"diverged at t={t + Ts:.6g} s: {reason}"
                    break
                s, x = s_new, x_new
            start += count
            bar.update(count)
    keep = ["tau"] + ["tau_commanded"] * (plant.actuator is not None) + ["q_measured", "dq_measured"] * (
        plant.sensor is not None)
    return t_log[:k_log], logs["z"][:k_log], status, {name: logs[name][:k_log] for name in keep}
