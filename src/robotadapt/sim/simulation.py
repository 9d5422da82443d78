"""Closing the loop: plant + controller + desired trajectory, integrated in time (DESIGN "Simulation").

:func:`simulate` validates once, then hands the closed loop (:mod:`robotadapt.sim.loop`) to the integrator asked for
(:mod:`robotadapt.sim.integrators`): the fixed-step RK4 driver here (numpy) or compiled by JAX
(:mod:`robotadapt.sim.compiled`), scipy's solve_ivp, or the sampled-data loop (:mod:`robotadapt.sim.sampled`). A
divergence guard stops a run whose state is non-finite or exceeds `max_state`; the result keeps everything up to there
and says where and why it stopped. In continuous time, outputs (torque, V, r) are recomputed after integration from the
pure controller maps, vectorized over time (:mod:`robotadapt.sim.outputs`); a sampled run logs the torque it applied.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..controllers.base import Law, as_law
from ..grid import Grid
from ..native.patience import patience
from ..plant.plant import Plant, same_model
from ..trajectories import Trajectory, traceable
from ..validation import ConfigError, as_scalar, as_vector
from . import running
from .backends import Run, execute
from .driver import drive
from .integrators import RK4, Sampled, SolveIVP, check_plant_step
from .loop import MAX_LOG_BYTES, ClosedLoop, DelayLine, Ring, RK4Step
from .outputs import outputs
from .result import SimulationResult
from .status import Status

Array = Any


def _fixed(loop: ClosedLoop, traj: Trajectory, z0: Array, grid: Grid, max_state: float, progress: bool,
           line: DelayLine | None, backend: str) -> tuple[Array, Array, Status, dict[str, Any]]:
    """Fixed-step RK4 from t = 0 through the one driver (:class:`~robotadapt.sim.loop.RK4Step`); returns logged (t, z),
    the status and the running metrics (:mod:`robotadapt.sim.running`). The log at t_k holds the state applied over
    step k (with a delay line, x as read from it); the last sample, at t_final, is logged, not integrated."""
    inside = backend == "c" and traceable(traj)  # the C program evaluates the reference itself
    rk4 = RK4Step(loop, grid.h, max_state, traj if inside else None)
    carry = (z0, None if line is None else Ring.start(line.buffer))
    trace = drive([rk4], [carry], rk4.feed(traj), grid.n, grid.log_every, backend=backend, progress=progress)
    z = trace.records.z[:, 0]
    return grid.times(len(z)), z, trace.status[0], running.values(running.run(trace.running, 0), grid.h)


def _solve_ivp(loop: ClosedLoop, traj: Trajectory, z0: Array, opts: SolveIVP, t_final: float,
               max_state: float) -> tuple[Array, Array, Status]:
    from scipy.integrate import solve_ivp

    class Refused(Exception):
        """A guarded law's guard failed at a state solve_ivp asked for."""

    def fun(t: float, y: Array) -> Array:
        dz, ok = loop.rate(t, y, traj(t))
        if ok is not None and not ok:
            raise Refused(loop.stop_reason(y))
        return dz

    def runaway(t: float, y: Array) -> float:
        y = loop.guarded_part(y)
        return max_state - float(np.max(np.abs(y))) if np.all(np.isfinite(y)) else -1.0

    runaway.terminal = True  # type: ignore[attr-defined]
    t_eval = Grid(opts.dt, t_final).times()
    try:
        with np.errstate(all="ignore"):
            sol = solve_ivp(fun, (0.0, t_eval[-1]), z0, method=opts.method, t_eval=t_eval, rtol=opts.rtol,
                            atol=opts.atol, events=runaway)
    except Refused as stop:  # solve_ivp keeps nothing: rerun to just before the stop is not worth it
        why = f"{stop} (solve_ivp keeps nothing of the run: use method = 'rk4' to keep the partial run)"
        return t_eval[:1], z0[None, :], Status.between(0.0, float(t_eval[-1]), why)
    t, z = sol.t, sol.y.T
    finite = np.all(np.isfinite(z), axis=1)
    t, z = t[np.cumprod(finite).astype(bool)], z[np.cumprod(finite).astype(bool)]
    if sol.status == 1:
        return t, z, Status.at(sol.t_events[0][0], f"state exceeded {max_state:g} in magnitude")
    if sol.status == -1:
        return t, z, Status.at(t[-1] if len(t) else 0.0, f"{opts.method} failed: {sol.message}")
    return t, z, Status.ok()


def host_sampling(plant: Plant, integrator: RK4 | SolveIVP | Sampled) -> Sampled:
    """The sampled-data loop a plant stepped on the host by another engine (`stepped_on_host`: MuJoCo's) runs in: the
    controller every control period of a `Sampled` integrator, or at every step `dt` of a continuous-time `RK4` one (Euler
    updates of x); the engine steps `plant.timestep` (default the plant step of the integrator) between ticks.
    Host-side: backend "auto" is numpy, "jax" an error."""
    if isinstance(integrator, SolveIVP):
        raise ConfigError("simulation.method", "a MuJoCo plant is stepped by MuJoCo: use method = 'rk4' (the controller "
                          "at every step) or a control_period")
    if integrator.backend in ("jax", "c"):
        raise ConfigError("simulation.backend", "a MuJoCo plant is stepped by MuJoCo on the host, not compiled by "
                          f"{'JAX' if integrator.backend == 'jax' else 'C'}: use backend = 'numpy' or 'auto'")
    sampled = integrator if isinstance(integrator, Sampled) else Sampled(integrator.dt, integrator.dt)
    timestep = getattr(plant, "timestep", None)  # the host engine's own step, if it sets one
    if timestep is None:
        return Sampled(sampled.control_period, sampled.dt, sampled.discretization, "numpy")
    try:
        return Sampled(sampled.control_period, timestep, sampled.discretization, "numpy")
    except ConfigError as exc:
        raise ConfigError("plant.timestep", exc.reason) from None


def simulate(plant: Plant, controller: Law, trajectory: Trajectory, *, t_final: float,
             integrator: RK4 | SolveIVP | Sampled | None = None, q0: Any = None, dq0: Any = None, x0: Any = None,
             log_every: int = 1, max_state: float = 1e6, progress: bool = False,
             info: dict[str, Any] | None = None) -> SimulationResult:
    """Simulate the closed loop from t = 0 to `t_final` (s).

    `q0, dq0` default to zero, `x0` to `controller.initial_state()` at what the law measures first (the sensor's tick-0
    measurement of (q0, q̇0) in sampled time, noise included: the composite law's filter starts from it). With
    :class:`RK4`, the state is logged every `log_every` steps; with :class:`SolveIVP` on its own output grid; with
    :class:`Sampled` every `log_every` control ticks. The run stops early, keeping its partial result, if the state
    becomes non-finite or exceeds `max_state`. The plant's sensor, rate limit and delay act at control ticks: they need
    :class:`Sampled`. A plant stepped by another engine (`stepped_on_host`:
    :class:`~robotadapt.plant.mujoco.MujocoPlant`) runs in the sampled-data loop (:func:`host_sampling`). The result's
    `info` records the plant's real-world effects and its model when it is not the controller's (`plant`), and the
    sampling (`sampling`).

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
    size = as_law(controller).error_size  # n joints, or a task-space law's m coordinates
    if trajectory.n != size:
        what = "coordinates, the hand" if controller.space == "task" else "joints, the robot"
        raise ConfigError("trajectory", f"the trajectory has {trajectory.n} {what} {size}")
    integrator = RK4() if integrator is None else integrator
    if plant.stepped_on_host:
        integrator = host_sampling(plant, integrator)
    t_final = as_scalar(t_final, "simulation.t_final", positive=True)
    q0 = as_vector(0.0 if q0 is None else q0, n, "plant.q0")
    dq0 = as_vector(0.0 if dq0 is None else dq0, n, "plant.dq0")
    if not isinstance(log_every, int) or log_every < 1:
        raise ConfigError("simulation.log_every", f"must be a positive integer, got {log_every!r}")
    plant.check_state(q0)
    controller = as_law(controller)
    sampled = isinstance(integrator, Sampled)
    if x0 is None:  # from what the law sees first: the sensor's tick-0 measurement in sampled time, else (q0, q̇0)
        seen = (plant.sensor.first_measurement(q0, dq0, integrator.control_period)
                if isinstance(integrator, Sampled) and plant.sensor is not None else (q0, dq0))
        x0 = controller.initial_state(*seen)
    x0 = np.asarray(x0, dtype=float)
    check_plant_step(plant, integrator)
    h = integrator.control_period if isinstance(integrator, Sampled) else integrator.dt
    try:
        controller = controller.prepare(trajectory, h, t_final)
    except ConfigError as exc:  # sampled, the controller's step is the control period
        if not sampled or exc.field != "simulation.dt":
            raise
        raise ConfigError("simulation.control_period", f"{exc.reason} (the controller's step here is the "
                          "control period)") from None
    line = None
    buffer = controller.delay_line(h, q0, dq0)
    if buffer is not None:
        if isinstance(integrator, SolveIVP):
            raise ConfigError("simulation.method", "a controller with a delay line (repetitive) needs method = 'rk4'")
        line = DelayLine(np.array(buffer, dtype=float))
    loop = ClosedLoop(plant, controller, n, monitored=True)
    z0 = loop.start(plant.initial_state(q0, dq0), x0)
    info, effects = dict(info or {}), plant.describe()
    if not same_model(plant.model, controller.model):  # the truth is another model: friction it lacks, a URDF arm
        effects["model"] = {"class": type(plant.model).__name__, "param_names": list(plant.model.param_names),
                            "phi": plant.phi.tolist()}
    if effects:
        info["plant"] = effects
    wall = time.perf_counter()
    logged: dict[str, Array] | None = None
    folded: dict[str, Any] | None = None
    if isinstance(integrator, SolveIVP):
        if integrator.backend == "jax":  # "auto" keeps scipy, the reference (sim/compiled_ivp.py)
            from .compiled_ivp import integrate_ivp

            t, z, status = integrate_ivp(loop, trajectory, z0, integrator, t_final, max_state)
        else:
            t, z, status = _solve_ivp(loop, trajectory, z0, integrator, t_final, max_state)
        info["backend"] = integrator.backend.replace("auto", "numpy")
    else:
        grid = Grid(h, t_final, log_every)
        n_steps = grid.n
        width = z0.size + (4 * n if sampled else 0)
        log_bytes = 8.0 * (n_steps // log_every + 1) * width
        if log_bytes > MAX_LOG_BYTES:
            name = "simulation.control_period" if sampled else "simulation.dt"
            raise ConfigError(name, f"{n_steps:.3g} steps would keep a {log_bytes / 1e9:.3g} GB log; "
                              f"use a larger {name.split('.')[1]} or simulation.log_every")
        step = RK4Step(loop, h, max_state)  # a step of the loop: what the backends are asked about (sampled runs too)
        asked = Run(step, step.start(z0, None if line is None else line.buffer), step.feed(trajectory), n_steps,
                    traceable=plant.model.traceable and controller.model.traceable)

        def run(backend: str) -> tuple[Array, Array, Status, dict[str, Any], dict[str, Array] | None]:
            if isinstance(integrator, Sampled):
                from .sampled import integrate

                return integrate(loop, trajectory, z0, integrator, grid, max_state, progress, line, backend=backend)
            return (*_fixed(loop, trajectory, z0, grid, max_state, progress, line, backend), None)

        if isinstance(integrator, Sampled):
            info["sampling"] = integrator.describe()
        (t, z, status, folded, logged), backend = execute(integrator.backend, asked, run)
        info["backend"] = backend
    wall = time.perf_counter() - wall
    # a diverged run's last samples may overflow in the recomputed outputs; "auto" need not wait for a long C program
    with np.errstate(all="ignore"), patience(integrator.backend != "auto"):
        return outputs(loop, trajectory, t, z, status, wall, info, logged, folded)
