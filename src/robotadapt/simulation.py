"""Closing the loop: plant + controller + desired trajectory, integrated in time (DESIGN "Simulation").

State z = [q, q̇, x]. Integrators are option objects: :class:`RK4` (fixed step, default, deterministic, batchable) and
:class:`SolveIVP` (scipy's error-controlled solvers, tolerances always explicit). A divergence guard stops a run whose
state is non-finite or exceeds `max_state`; the result keeps everything up to there and says where and why it stopped.
Outputs (torque, V, r) are recomputed after integration from the pure controller maps, vectorized over time.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.integrate import cumulative_simpson

from ._array import matvec
from .controllers.base import (
    Controller,
    HasDelayLine,
    HasFilteredError,
    HasInstantEstimate,
    HasLyapunov,
    HasProjection,
    HasRegressor,
    NeedsAcceleration,
    Prepares,
    SimulationStop,
)
from .monitors import controller_series
from .plant import Plant
from .result import SimulationResult
from .trajectories import Reference, Trajectory
from .validation import ConfigError, as_scalar, as_vector

Array = Any
_CHUNK = 2048  # steps whose reference is evaluated in one vectorized call
_MAX_LOG_BYTES = 4e9


@dataclass(frozen=True)
class RK4:
    """Classic fixed-step Runge–Kutta 4 with step `dt` (s)."""

    dt: float = 1e-3

    def __post_init__(self) -> None:
        object.__setattr__(self, "dt", as_scalar(self.dt, "simulation.dt", positive=True))


@dataclass(frozen=True)
class SolveIVP:
    """scipy.integrate.solve_ivp with `method` ('RK45', 'DOP853', 'Radau', 'BDF', 'LSODA'), explicit tolerances, and
    the result sampled every `dt` seconds."""

    method: str = "RK45"
    rtol: float = 1e-8
    atol: float = 1e-10
    dt: float = 1e-3

    def __post_init__(self) -> None:
        known = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
        if self.method not in known:
            raise ConfigError("simulation.method", f"unknown method {self.method!r}; use 'rk4' or one of {known}")
        for name in ("rtol", "atol", "dt"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), f"simulation.{name}", positive=True))


@dataclass(frozen=True, eq=False)
class _Loop:
    """The closed-loop vector field dz/dt = f(t, z); controllers that need q̈ get the plant's acceleration for the
    torque they just applied (no algebraic loop: their torque does not depend on q̈)."""

    plant: Plant
    controller: Any  # a Controller, or a NeedsAcceleration law (torque, then update with the plant's q̈)
    n: int
    needs_acceleration: bool = field(init=False)

    def __post_init__(self) -> None:  # a protocol check costs microseconds: once, not per evaluation
        object.__setattr__(self, "needs_acceleration", isinstance(self.controller, NeedsAcceleration))

    def split(self, z: Array) -> tuple[Array, Array, Array]:
        n = self.n
        return z[..., :n], z[..., n : 2 * n], z[..., 2 * n :]

    def torque(self, t: Array, z: Array, ref: Reference) -> Array:
        q, dq, x = self.split(z)
        if self.needs_acceleration:
            return self.controller.torque(t, x, q, dq, ref)
        return self.controller(t, x, q, dq, ref)[0]

    def __call__(self, t: Array, z: Array, ref: Reference) -> Array:
        q, dq, x = self.split(z)
        if self.needs_acceleration:
            tau = self.controller.torque(t, x, q, dq, ref)
            ddq = self.plant.acceleration(t, q, dq, tau)
            dx = self.controller.update(t, x, q, dq, ddq, ref)
        else:
            tau, dx = self.controller(t, x, q, dq, ref)
            ddq = self.plant.acceleration(t, q, dq, tau)
        return np.concatenate([dq, ddq, dx], axis=-1)

    def project(self, z: Array) -> Array:
        if not isinstance(self.controller, HasProjection):
            return z
        q, dq, x = self.split(z)
        return np.concatenate([q, dq, self.controller.project(x)], axis=-1)


def _diverged(z: Array, max_state: float) -> str | None:
    if not np.all(np.isfinite(z)):
        return "non-finite state"
    if np.max(np.abs(z)) > max_state:
        return f"state exceeded {max_state:g} in magnitude"
    return None


def _take(ref: Reference, i: int) -> Reference:
    return Reference(ref.q_des[i], ref.dq_des[i], ref.ddq_des[i])


@dataclass
class _DelayLine:
    """The ring buffer of a controller with a delay line (HasDelayLine), owned here so the controller stays pure."""

    buffer: Array

    def sample(self, loop: _Loop, k: int, t: float, z: Array, ref: Reference) -> Array:
        q, dq, x = loop.split(z)
        slot = k % self.buffer.shape[0]
        x_new, store = loop.controller.sample(t, x, q, dq, ref, self.buffer[slot])
        self.buffer[slot] = store
        return np.concatenate([q, dq, x_new], axis=-1)


def _rk4_step(loop: _Loop, t: float, z: Array, dt: float, r0: Reference, rh: Reference, r1: Reference) -> Array:
    k1 = loop(t, z, r0)
    k2 = loop(t + 0.5 * dt, z + 0.5 * dt * k1, rh)
    k3 = loop(t + 0.5 * dt, z + 0.5 * dt * k2, rh)
    k4 = loop(t + dt, z + dt * k3, r1)
    return loop.project(z + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))


def _rk4(loop: _Loop, traj: Trajectory, z0: Array, dt: float, n_steps: int, log_every: int, max_state: float,
         progress: bool, line: _DelayLine | None) -> tuple[Array, Array, str]:
    """Fixed-step RK4 from t = 0; returns logged (t, z) and the status."""
    from tqdm import tqdm

    n_log = n_steps // log_every + 1
    t_log = np.empty(n_log)
    z_log = np.empty((n_log,) + z0.shape)
    t_log[0], z_log[0] = 0.0, z0
    z, k_log = z0, 1
    with tqdm(total=n_steps, delay=1.0, disable=not progress, unit="step", leave=False, file=sys.stderr) as bar, \
            np.errstate(all="ignore"):
        for start in range(0, n_steps, _CHUNK):
            m = min(_CHUNK, n_steps - start)
            ref = traj(dt * (start + 0.5 * np.arange(2 * m + 1)))
            for j in range(m):
                t = (start + j) * dt
                r0 = _take(ref, 2 * j)
                try:
                    if line is not None:
                        z = line.sample(loop, start + j, t, z, r0)
                    z_new = _rk4_step(loop, t, z, dt, r0, _take(ref, 2 * j + 1), _take(ref, 2 * j + 2))
                except SimulationStop as stop:
                    return t_log[:k_log], z_log[:k_log], f"diverged at t={t:.6g} s: {stop}"
                reason = _diverged(z_new, max_state)
                if reason is not None:
                    return t_log[:k_log], z_log[:k_log], f"diverged at t={t + dt:.6g} s: {reason}"
                z = z_new
                if (start + j + 1) % log_every == 0:
                    t_log[k_log], z_log[k_log] = (start + j + 1) * dt, z
                    k_log += 1
            bar.update(m)
    return t_log[:k_log], z_log[:k_log], "ok"


def _solve_ivp(loop: _Loop, traj: Trajectory, z0: Array, opts: SolveIVP, t_final: float,
               max_state: float) -> tuple[Array, Array, str]:
    from scipy.integrate import solve_ivp

    def fun(t: float, y: Array) -> Array:
        return loop(t, y, traj(t))

    def runaway(t: float, y: Array) -> float:
        return max_state - float(np.max(np.abs(y))) if np.all(np.isfinite(y)) else -1.0

    runaway.terminal = True  # type: ignore[attr-defined]
    t_eval = opts.dt * np.arange(int(np.floor(t_final / opts.dt + 1e-9)) + 1)
    try:
        with np.errstate(all="ignore"):
            sol = solve_ivp(fun, (0.0, t_eval[-1]), z0, method=opts.method, t_eval=t_eval, rtol=opts.rtol,
                            atol=opts.atol, events=runaway)
    except SimulationStop as stop:  # solve_ivp keeps nothing: rerun to just before the stop is not worth it
        return t_eval[:1], z0[None, :], f"diverged at t=0 s or later: {stop} (use method = 'rk4' to keep the partial run)"
    t, z = sol.t, sol.y.T
    finite = np.all(np.isfinite(z), axis=1)
    t, z = t[np.cumprod(finite).astype(bool)], z[np.cumprod(finite).astype(bool)]
    if sol.status == 1:
        return t, z, f"diverged at t={sol.t_events[0][0]:.6g} s: state exceeded {max_state:g} in magnitude"
    if sol.status == -1:
        return t, z, f"diverged at t={t[-1] if len(t) else 0.0:.6g} s: {opts.method} failed: {sol.message}"
    return t, z, "ok"


def simulate(plant: Plant, controller: Controller | NeedsAcceleration, trajectory: Trajectory, *, t_final: float,
             integrator: RK4 | SolveIVP | None = None, q0: Any = None, dq0: Any = None, x0: Any = None,
             log_every: int = 1, max_state: float = 1e6, progress: bool = False,
             info: dict[str, Any] | None = None) -> SimulationResult:
    """Simulate the closed loop from t = 0 to `t_final` (s).

    `q0, dq0` default to zero, `x0` to `controller.initial_state()`. With :class:`RK4`, the state is logged every
    `log_every` steps; with :class:`SolveIVP` on its own output grid. The run stops early, keeping its partial result,
    if the state becomes non-finite or exceeds `max_state`.
    """
    n = plant.model.n
    if controller.model.n != n:
        raise ConfigError("controller", f"the controller's model has {controller.model.n} joints, the plant {n}")
    if trajectory.n != n:
        raise ConfigError("trajectory", f"the trajectory has {trajectory.n} joints, the robot {n}")
    integrator = RK4() if integrator is None else integrator
    t_final = as_scalar(t_final, "simulation.t_final", positive=True)
    q0 = as_vector(0.0 if q0 is None else q0, n, "plant.q0")
    dq0 = as_vector(0.0 if dq0 is None else dq0, n, "plant.dq0")
    x0 = controller.initial_state(q0, dq0) if x0 is None else np.asarray(x0, dtype=float)
    if not isinstance(log_every, int) or log_every < 1:
        raise ConfigError("simulation.log_every", f"must be a positive integer, got {log_every!r}")
    plant.check_state(q0)
    step = integrator.dt
    if isinstance(controller, Prepares):
        controller = controller.prepare(trajectory, step, t_final)
    line = None
    if isinstance(controller, HasDelayLine):
        if not isinstance(integrator, RK4):
            raise ConfigError("simulation.method", "a controller with a delay line (repetitive) needs method = 'rk4'")
        line = _DelayLine(np.array(controller.delay_line(step, q0, dq0), dtype=float))
    loop = _Loop(plant, controller, n)
    z0 = np.concatenate([q0, dq0, x0])
    wall = time.perf_counter()
    if isinstance(integrator, RK4):
        n_steps = int(np.ceil(t_final / integrator.dt - 1e-9))
        log_bytes = 8.0 * (n_steps // log_every + 1) * z0.size
        if log_bytes > _MAX_LOG_BYTES:
            raise ConfigError("simulation.dt", f"{n_steps:.3g} steps would keep a {log_bytes / 1e9:.3g} GB log; "
                              "use a larger dt or simulation.log_every")
        t, z, status = _rk4(loop, trajectory, z0, integrator.dt, n_steps, log_every, max_state, progress, line)
    else:
        t, z, status = _solve_ivp(loop, trajectory, z0, integrator, t_final, max_state)
    wall = time.perf_counter() - wall
    with np.errstate(all="ignore"):  # a diverged run's last samples may overflow in the recomputed outputs
        return _outputs(loop, trajectory, t, z, status, wall, info or {})


def _outputs(loop: _Loop, trajectory: Trajectory, t: Array, z: Array, status: str, wall: float,
             info: dict[str, Any]) -> SimulationResult:
    """Recompute torque, V(t), r(t) and the passivity integral (6.4.4) from the pure maps at the logged instants."""
    ctrl, plant = loop.controller, loop.plant
    q, dq, x = loop.split(z)
    ref = trajectory(t)
    tau = loop.torque(t, z, ref)
    phi_hat = ctrl.phi_hat_at(t, x, q, dq, ref) if isinstance(ctrl, HasInstantEstimate) else ctrl.phi_hat(x)
    same_model = ctrl.model.param_names == plant.model.param_names
    phi = plant.phi if same_model and phi_hat.shape[-1] == plant.model.p else None
    V = ctrl.lyapunov(t, x, q, dq, ref, plant.phi) if isinstance(ctrl, HasLyapunov) and same_model else None
    r = ctrl.filtered_error(t, x, q, dq, ref) if isinstance(ctrl, HasFilteredError) else None
    passivity = None
    if isinstance(ctrl, HasRegressor) and phi is not None and t.size > 1:
        Z, r_z = ctrl.regressor(t, x, q, dq, ref)
        passivity = cumulative_simpson(-(r_z * matvec(Z, phi - phi_hat)).sum(axis=-1), x=t, initial=0.0)
    result = SimulationResult(
        t=t, q=q, dq=dq, x=x, q_des=ref.q_des, dq_des=ref.dq_des, ddq_des=ref.ddq_des, tau=tau, V=V, r=r,
        phi_hat=phi_hat, phi=phi, param_names=ctrl.model.param_names if phi_hat.shape[-1] else (),
        state_names=ctrl.state_names, status=status,
        wall_time=wall, info=info, passivity=passivity,
    )
    return replace(result, monitors=controller_series(result, ctrl))
