"""Closing the loop: plant + controller + desired trajectory, integrated in time (DESIGN "Simulation").

State z = [s, x]: the plant's state s = [q, q̇] (then θ, θ̇ of elastic joints and the motor currents, see
:mod:`robotadapt.plant`) and the controller's x. Integrators are option objects: :class:`RK4` (fixed step, default,
deterministic, batchable), :class:`SolveIVP` (scipy's error-controlled solvers, tolerances always explicit) and
:class:`Sampled` (sampled-data control: the controller at its ticks only, zero-order hold on the torque, the plant by RK4
between them; :mod:`robotadapt.sampled`). A divergence guard stops a run whose state is non-finite or exceeds
`max_state`; the result keeps everything up to there and says where and why it stopped. In continuous time, outputs
(torque, V, r) are recomputed after integration from the pure controller maps, vectorized over time; a sampled run logs
the torque it applied.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ._array import array_namespace, matvec
from .controllers.base import (
    Controller,
    FiltersTorque,
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
from .plant import Plant, same_model
from .result import SimulationResult
from .trajectories import Reference, Trajectory
from .validation import ConfigError, as_scalar, as_vector

Array = Any
_CHUNK = 2048  # steps whose reference is evaluated in one vectorized call
_MAX_LOG_BYTES = 4e9


BACKENDS = ("numpy", "jax")


@dataclass(frozen=True)
class RK4:
    """Classic fixed-step Runge–Kutta 4 with step `dt` (s), stepped by numpy or, with `backend="jax"`, compiled by JAX
    (:mod:`robotadapt.compiled`; the same step, equal to round-off)."""

    dt: float = 1e-3
    backend: str = "numpy"

    def __post_init__(self) -> None:
        object.__setattr__(self, "dt", as_scalar(self.dt, "simulation.dt", positive=True))
        if not isinstance(self.backend, str) or self.backend not in BACKENDS:
            raise ConfigError("simulation.backend", f"expected one of {', '.join(BACKENDS)}; got {self.backend!r}")


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


DISCRETIZATIONS = ("euler", "hold")
_MAX_SUBSTEPS = 10**6


@dataclass(frozen=True)
class Sampled:
    """Sampled-data control: the controller runs only at t_k = k·Ts (`control_period` Ts, s) and its torque is held
    over [t_k, t_k + Ts) (zero-order hold); the plant is integrated by RK4 with the step `dt` = Ts/m, m whole (default:
    the largest such step ≤ 1 ms). The controller sees the plant through its sensor (:mod:`robotadapt.sensors`; exact
    samples without one); a controller with acceleration feedback gets q̈_m,k = (q̇_m,k − q̇_m,k−1)/Ts, the backward
    difference of the velocities it measured (0 at k = 0); a delay line (the repetitive law) holds T/Ts ticks.

    `discretization` is the rule advancing the controller's state x between ticks, from the samples y_k at t_k:

    - ``"euler"``: x_{k+1} = x_k + Ts·f(t_k, x_k, y_k), forward Euler, what `x += Ts * dx` in a control loop does;
    - ``"hold"``: x_{k+1} = x(t_k + Ts) of dx/dt = f(t_k, x, y_k) with t, y and the reference held at their samples,
      integrated by RK4 on the plant's sub-steps: the zero-order-hold equivalent (exact for the linear filters of the
      passivity servo and the composite law, up to RK4's error; the same as Euler when f does not depend on x, as for
      the gradient law).

    A projection (HasProjection) is applied after each update (each sub-step of "hold"). As Ts → 0 the run tends to
    the continuous-time one, to first order in Ts.
    """

    control_period: float
    dt: Any = None  # the plant's step (s): a float once constructed
    discretization: str = "euler"
    substeps: int = field(init=False)

    def __post_init__(self) -> None:
        Ts = as_scalar(self.control_period, "simulation.control_period", positive=True)
        if not isinstance(self.discretization, str) or self.discretization not in DISCRETIZATIONS:
            raise ConfigError("simulation.discretization", f"expected one of {', '.join(DISCRETIZATIONS)}; got "
                              f"{self.discretization!r}")
        hint = Ts / max(1, math.ceil(Ts / 1e-3 - 1e-9))
        if self.dt is None:
            dt = hint
        else:
            dt = as_scalar(self.dt, "simulation.dt", positive=True)
            if dt > Ts * (1 + 1e-9):
                raise ConfigError("simulation.dt", f"the plant's step {dt:g} s is longer than the control period "
                                  f"{Ts:g} s; use dt = Ts/m, e.g. {hint:.6g}")
            if abs(Ts / dt - round(Ts / dt)) > 1e-6:
                raise ConfigError("simulation.dt", f"the control period {Ts:g} s is not a whole number of plant "
                                  f"steps of {dt:g} s; use dt = Ts/m, e.g. {hint:.6g}")
        substeps = max(1, round(Ts / dt))
        if substeps > _MAX_SUBSTEPS:
            raise ConfigError("simulation.dt", f"{substeps:.3g} plant steps per control period; at most "
                              f"{_MAX_SUBSTEPS:.0e} (use a larger dt)")
        for name, value in (("control_period", Ts), ("dt", Ts / substeps), ("substeps", substeps)):
            object.__setattr__(self, name, value)

    def describe(self) -> dict[str, Any]:
        return {"control_period": self.control_period, "dt": self.dt, "substeps": self.substeps,
                "discretization": self.discretization}


@dataclass(frozen=True, eq=False)
class _Loop:
    """The closed-loop vector field dz/dt = f(t, z), z = [s, x]; the plant receives the saturated torque. Controllers
    that need q̈ get the plant's acceleration for the torque they just applied (no algebraic loop: their torque does not
    depend on q̈). A law that filters the torque (FiltersTorque) is given the torque the plant receives."""

    plant: Plant
    controller: Any  # a Controller, or a NeedsAcceleration law (torque, then update with the plant's q̈)
    n: int
    needs_acceleration: bool = field(init=False)
    m: int = field(init=False)  # the plant's state size, 2n + its extra states
    rigid: bool = field(init=False)  # no extra plant states: the fast path
    filters_torque: bool = field(init=False)  # the law filters the applied torque, and an actuator may change it

    def __post_init__(self) -> None:  # a protocol check costs microseconds: once, not per evaluation
        object.__setattr__(self, "needs_acceleration", isinstance(self.controller, NeedsAcceleration))
        object.__setattr__(self, "filters_torque", isinstance(self.controller, FiltersTorque)
                           and self.plant.actuator is not None)
        object.__setattr__(self, "m", 2 * self.n + self.plant.n_extra)
        object.__setattr__(self, "rigid", self.plant.n_extra == 0)

    def split(self, z: Array) -> tuple[Array, Array, Array]:
        n = self.n
        return z[..., :n], z[..., n : 2 * n], z[..., self.m :]

    def torque(self, t: Array, z: Array, ref: Reference) -> Array:
        """The controller's commanded torque (before the actuator's saturation)."""
        q, dq, x = self.split(z)
        if self.needs_acceleration:
            return self.controller.torque(t, x, q, dq, ref)
        return self.controller(t, x, q, dq, ref)[0]

    def _plant(self, t: Array, z: Array, q: Array, dq: Array, u: Array) -> tuple[Array, Array]:
        """(the plant's ds/dt without q̇, q̈) for the applied torque."""
        if self.rigid:
            return dq, self.plant.acceleration(t, q, dq, u)
        ds = self.plant.derivative(t, z[..., : self.m], u)
        return ds, ds[..., self.n : 2 * self.n]

    def __call__(self, t: Array, z: Array, ref: Reference) -> Array:
        q, dq, x = self.split(z)
        if self.needs_acceleration:
            tau = self.controller.torque(t, x, q, dq, ref)
            head, ddq = self._plant(t, z, q, dq, self.plant.saturate(tau))
            dx = self.controller.update(t, x, q, dq, ddq, ref)
        else:
            tau, dx = self.controller(t, x, q, dq, ref)
            u = self.plant.saturate(tau)
            if self.filters_torque:
                dx = self.controller.applied(dx, tau, u)
            head, ddq = self._plant(t, z, q, dq, u)
        return array_namespace(z).concatenate([head, ddq, dx] if self.rigid else [head, dx], axis=-1)

    def project(self, z: Array) -> Array:
        if not isinstance(self.controller, HasProjection):
            return z
        return array_namespace(z).concatenate([z[..., : self.m], self.controller.project(z[..., self.m :])], axis=-1)


REASONS = {1: "non-finite state", 2: "state exceeded {max_state:g} in magnitude"}  # why the divergence guard stopped


def diverged_status(t: float, why: int, max_state: float) -> str:
    """The status of a run the compiled guard stopped at `t` for reason code `why` (a key of `REASONS`; 0: none)."""
    return f"diverged at t={t:.6g} s: " + REASONS[why].format(max_state=max_state) if why else "ok"


def _diverged(z: Array, max_state: float) -> str | None:
    if not np.all(np.isfinite(z)):
        return REASONS[1]
    if np.max(np.abs(z)) > max_state:
        return REASONS[2].format(max_state=max_state)
    return None


def _take(ref: Reference, i: int) -> Reference:
    return Reference(ref.q_des[i], ref.dq_des[i], ref.ddq_des[i])


@dataclass
class _DelayLine:
    """The ring buffer of a controller with a delay line (HasDelayLine), owned here so the controller stays pure.

    The law gets a copy of the slot it reads: a view would let the write that follows change the value it holds."""

    buffer: Array

    def advance(self, controller: Any, k: int, t: float, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The controller's state for step (or tick) k, reading and writing slot k mod N."""
        slot = k % self.buffer.shape[0]
        x_new, store = controller.sample(t, x, q, dq, ref, self.buffer[slot].copy())
        self.buffer[slot] = store
        return x_new

    def sample(self, loop: _Loop, k: int, t: float, z: Array, ref: Reference) -> Array:
        q, dq, x = loop.split(z)
        return np.concatenate([z[..., : loop.m], self.advance(loop.controller, k, t, x, q, dq, ref)], axis=-1)


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
                        if (start + j) % log_every == 0:  # the log at t_k holds the state applied at t_k
                            z_log[(start + j) // log_every] = z
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
    if line is not None and n_steps % log_every == 0:  # the sample at t_final, logged, not integrated
        z_log[k_log - 1] = line.sample(loop, n_steps, n_steps * dt, z, _take(ref, 2 * m))
    return t_log[:k_log], z_log[:k_log], "ok"


def _rk4_compiled(loop: _Loop, traj: Trajectory, z0: Array, dt: float, n_steps: int, log_every: int,
                  max_state: float) -> tuple[Array, Array, str]:
    """:func:`_rk4` compiled by JAX: the same logged samples and status."""
    from .compiled import integrate

    t, z, n_logged, t_bad, why = integrate(loop, traj, z0, dt, n_steps, log_every, max_state)
    return t[:n_logged], z[:n_logged], diverged_status(float(t_bad), int(why), max_state)


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
             integrator: RK4 | SolveIVP | Sampled | None = None, q0: Any = None, dq0: Any = None, x0: Any = None,
             log_every: int = 1, max_state: float = 1e6, progress: bool = False,
             info: dict[str, Any] | None = None) -> SimulationResult:
    """Simulate the closed loop from t = 0 to `t_final` (s).

    `q0, dq0` default to zero, `x0` to `controller.initial_state()`. With :class:`RK4`, the state is logged every
    `log_every` steps; with :class:`SolveIVP` on its own output grid; with :class:`Sampled` every `log_every` control
    ticks. The run stops early, keeping its partial result, if the state becomes non-finite or exceeds `max_state`.
    The plant's sensor, rate limit and delay act at control ticks: they need :class:`Sampled`. The result's `info`
    records the plant's real-world effects and its model when it is not the controller's (`plant`), and the sampling
    (`sampling`).

    Examples
    --------
    Example 6.3.1: Slotine–Li (Table 6.3.1) on the book's two-link arm, q_d = sin t, the masses learnt from zero:

    >>> from robotadapt.controllers import InertiaRelated
    >>> from robotadapt.robots import TwoLinkArm
    >>> from robotadapt.trajectories import sinusoid
    >>> arm = TwoLinkArm()
    >>> res = simulate(Plant(arm, [0.8, 2.3]), InertiaRelated(arm, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0]),
    ...                sinusoid(2), t_final=10, integrator=RK4(1e-3), log_every=100)
    >>> res.status, bool(abs(res.e[-1]).max() < 1e-9), res.phi_hat[-1].round(6).tolist()
    ('ok', True, [0.8, 2.3])
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
    sampled = isinstance(integrator, Sampled)
    _check_plant_step(plant, integrator)
    step = integrator.control_period if isinstance(integrator, Sampled) else integrator.dt
    if isinstance(controller, Prepares):
        try:
            controller = controller.prepare(trajectory, step, t_final)
        except ConfigError as exc:  # sampled, the controller's step is the control period
            if not sampled or exc.field != "simulation.dt":
                raise
            raise ConfigError("simulation.control_period", f"{exc.reason} (the controller's step here is the "
                              "control period)") from None
    line = None
    if isinstance(controller, HasDelayLine):
        if isinstance(integrator, SolveIVP):
            raise ConfigError("simulation.method", "a controller with a delay line (repetitive) needs method = 'rk4'")
        line = _DelayLine(np.array(controller.delay_line(step, q0, dq0), dtype=float))
    loop = _Loop(plant, controller, n)
    z0 = np.concatenate([plant.initial_state(q0, dq0), x0])
    info, effects = dict(info or {}), plant.describe()
    if not same_model(plant.model, controller.model):  # the truth is another model: friction it lacks, a URDF arm
        effects["model"] = {"class": type(plant.model).__name__, "param_names": list(plant.model.param_names),
                            "phi": plant.phi.tolist()}
    if effects:
        info["plant"] = effects
    wall = time.perf_counter()
    logged = None
    if isinstance(integrator, SolveIVP):
        t, z, status = _solve_ivp(loop, trajectory, z0, integrator, t_final, max_state)
    else:
        n_steps = int(np.ceil(t_final / step - 1e-9))
        width = z0.size + (4 * n if sampled else 0)
        log_bytes = 8.0 * (n_steps // log_every + 1) * width
        if log_bytes > _MAX_LOG_BYTES:
            name = "simulation.control_period" if sampled else "simulation.dt"
            raise ConfigError(name, f"{n_steps:.3g} steps would keep a {log_bytes / 1e9:.3g} GB log; "
                              f"use a larger {name.split('.')[1]} or simulation.log_every")
        if isinstance(integrator, Sampled):
            from .sampled import integrate

            info["sampling"] = integrator.describe()
            t, z, status, logged = integrate(loop, trajectory, z0, integrator, n_steps, log_every, max_state,
                                             progress, line)
        elif integrator.backend == "jax":
            if line is not None:
                raise ConfigError("simulation.backend", "a controller with a delay line (repetitive) keeps it on the "
                                  "host: use backend = 'numpy'")
            t, z, status = _rk4_compiled(loop, trajectory, z0, integrator.dt, n_steps, log_every, max_state)
        else:
            t, z, status = _rk4(loop, trajectory, z0, integrator.dt, n_steps, log_every, max_state, progress, line)
    wall = time.perf_counter() - wall
    with np.errstate(all="ignore"):  # a diverged run's last samples may overflow in the recomputed outputs
        return _outputs(loop, trajectory, t, z, status, wall, info, logged)


_RK4_STABLE = 2.5  # |λ dt| inside RK4's stability region (2.78 on the real axis, 2.83 on the imaginary one)


def _check_plant_step(plant: Plant, integrator: RK4 | SolveIVP | Sampled) -> None:
    """Refuse effects that need control ticks in continuous time, and a fixed step too long for the plant's fastest
    unmodeled dynamics (a motor's electrical pole, a stiff joint), which RK4 would turn into a numerical blow-up."""
    if plant.needs_sampling and not isinstance(integrator, Sampled):
        raise ConfigError("simulation.control_period", "the plant's sensor, torque rate limit and delay act at "
                          "control ticks: set simulation.control_period (sampled-data mode)")
    rate = plant.fastest_rate
    if isinstance(integrator, RK4 | Sampled) and rate * integrator.dt > _RK4_STABLE:
        raise ConfigError("simulation.dt", f"the plant's fastest unmodeled dynamics (rate {rate:.4g} 1/s: motor "
                          f"L/(R + K_c), joint √(K/J)) need a step dt ≤ {_RK4_STABLE / rate:.3g} s, got "
                          f"{integrator.dt:g} s")


def _outputs(loop: _Loop, trajectory: Trajectory, t: Array, z: Array, status: str, wall: float,
             info: dict[str, Any], logged: dict[str, Array] | None = None) -> SimulationResult:
    """Recompute torque, V(t), r(t) and the passivity integral (6.4.4) from the pure maps at the logged instants.

    `logged` (sampled-data mode) holds the torque applied at each logged tick (`tau`) and what the run recorded
    besides (`tau_commanded`, `q_measured`, `dq_measured`); in continuous time the applied torque is the saturated
    command. V, r and the passivity integral are evaluated on the true state, φ̂ from what the controller saw. The
    truth is the plant's φ(t) when the controller's model is the plant's; the result's `phi` is its value at the last
    sample, and `monitors["phi_true"]` its history when it changed during the run (a payload attached).
    """
    ctrl, plant = loop.controller, loop.plant
    q, dq, x = loop.split(z)
    ref = trajectory(t)
    extras = dict(logged or {})
    if logged is None:
        commanded = loop.torque(t, z, ref)
        tau = plant.saturate(commanded)
        if plant.actuator is not None:
            extras["tau_commanded"] = commanded
    else:
        tau = extras.pop("tau")
    q_seen, dq_seen = extras.get("q_measured", q), extras.get("dq_measured", dq)
    phi_hat = (ctrl.phi_hat_at(t, x, q_seen, dq_seen, ref) if isinstance(ctrl, HasInstantEstimate)
               else ctrl.phi_hat(x))
    truth = plant.truth_for(ctrl.model, t)
    phi = None
    if truth is not None and phi_hat.shape[-1] == plant.model.p:
        phi = truth[-1] if truth.ndim == 2 else truth
    known = phi is not None
    V = ctrl.lyapunov(t, x, q, dq, ref, truth) if isinstance(ctrl, HasLyapunov) and truth is not None else None
    r = ctrl.filtered_error(t, x, q, dq, ref) if isinstance(ctrl, HasFilteredError) else None
    passivity = None
    if isinstance(ctrl, HasRegressor) and known and t.size > 1:
        Z, r_z = ctrl.regressor(t, x, q, dq, ref)
        from scipy.integrate import cumulative_simpson  # here: importing the simulator stays light

        passivity = cumulative_simpson(-(r_z * matvec(Z, truth - phi_hat)).sum(axis=-1), x=t, initial=0.0)
    if known and plant.varies:
        extras["phi_true"] = truth
    extras.update(plant.extra_series(z[..., : loop.m]))
    result = SimulationResult(
        t=t, q=q, dq=dq, x=x, q_des=ref.q_des, dq_des=ref.dq_des, ddq_des=ref.ddq_des, tau=tau, V=V, r=r,
        phi_hat=phi_hat, phi=phi, param_names=ctrl.model.param_names if phi_hat.shape[-1] else (),
        state_names=ctrl.state_names, status=status,
        wall_time=wall, info=info, passivity=passivity,
    )
    return replace(result, monitors={**controller_series(result, ctrl), **extras})
