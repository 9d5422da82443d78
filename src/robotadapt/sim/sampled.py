"""The sampled-data loop (:class:`robotadapt.sim.Sampled`): a digital controller at its ticks t_k = k·Ts, a zero-order
hold on the torque, the plant integrated between ticks.

One tick is one pure function, :class:`Tick`: `carry_{k+1}, record_k, verdict_k = tick(carry_k, inputs_k)`, written
against the array API of its inputs (no writes into arrays, no branch on a value): a transition of the one driver
(:mod:`robotadapt.sim.driver`), which loops over it in Python (numpy) or scans over it (JAX), as over the continuous
step. Everything that changes from tick to tick is in the carry (:class:`Carry`): the plant's state s, the controller's
x, the sensor's memory, the actuator's held torque and commands in flight, and the delay line of the repetitive law.
What comes from outside is an input (:class:`Inputs`): k, t_k, the reference at t_k and the tick's noise draws (numpy
draws them from the run's seed ahead, a block of ticks at a time, for both drivers). Tick k:

1. measure (q_m, q̇_m, q̈_m) from the plant's state through its sensor (:mod:`robotadapt.plant.sensors`; exact samples
   without one);
2. a delay line (the repetitive law, N = T/Ts ticks per period) is read at slot k mod N and written with what the law
   returns (a new array: :func:`robotadapt.sim.loop.ring_write`);
3. the controller gives τ_k and ẋ_k from (t_k, x_k, q_m, q̇_m, ref(t_k)) (with q̈_m for a law that needs it); where a
   guarded law's assumption fails (Law.guard, read at the sample) the run stops at t_k, this tick unlogged;
4. the actuator turns τ_k into the applied u_k (delay, saturation, rate limit; :mod:`robotadapt.plant.actuators`);
5. the record of the tick: the true state s_k, x_k, u_k, τ_k, q_m, q̇_m (the drivers keep every `log_every`-th);
6. the plant: `substeps` RK4 steps of dt = Ts/substeps of ds/dt = f(t, s, u_k) (a MuJoCo plant: `substeps` steps of
   MuJoCo's own integrator, :meth:`robotadapt.plant.mujoco.MujocoPlant.advance`); the controller's state: x_{k+1} by the
   discrete rule ("euler", the exponential map of a law on a manifold, or "hold"), projected (a guard failing
   inside "hold" stops the run at t_k, this tick logged);
7. the divergence guard on (s_{k+1}, x_{k+1}): the run stops at t_k + Ts on a non-finite state or one beyond
   `max_state` (:class:`Verdict`, codes of :data:`robotadapt.sim.loop.REASONS` and `GUARD`).

The last tick (t = t_final) is measured, computed and logged, not integrated (the driver's rule).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..arrays import array_namespace, repeat, rk4
from ..grid import Grid
from ..plant.actuators import Actuator
from ..plant.sensors import Sensor
from ..pytree import Module
from ..tracing import jax_module
from ..trajectories import Reference
from . import running
from .driver import GUARD, Verdict, drive
from .loop import REASONS, ClosedLoop, ring_write
from .status import Status

if TYPE_CHECKING:
    from ..trajectories import Trajectory
    from .integrators import Sampled
    from .loop import DelayLine

Array = Any
Dynamics = Callable[[Array, Array, Array], Array]  # (t, s, u) -> ds/dt


class Carry(NamedTuple):
    """What one tick hands the next, arrays only (a JAX pytree as it stands)."""

    s: Array  # the plant's state (m,)
    x: Array  # the controller's state
    sensor: tuple[Array, Array, Array, Array]  # the measurement path's memory (Sensor.start)
    actuator: tuple[Array, Array]  # u_{k−1} and the commands in flight (d, n) (Actuator.start)
    line: Array  # the delay line (N, ...) of a law with one; shape (0,) without
    w: Array  # the monitors (loop.w,): the passivity sum Σ_{j<k} Ts·(−r_jᵀ Z_j φ̃_j) and its running minimum


class Inputs(NamedTuple):
    """What tick k takes from outside (the drivers may pass a plain tuple in this order)."""

    k: Array  # the tick's index
    t: Array  # t_k = k Ts
    ref: Reference  # q_des, q̇_des, q̈_des at t_k
    noise: Array  # the tick's standard normal draws (2, n) (Sensor.noise)


class Sample(NamedTuple):
    """The tick's measurements and the controller's outputs, what the hold and the record need."""

    q_m: Array
    dq_m: Array
    ddq_m: Array
    tau: Array  # commanded
    u: Array  # applied
    dx: Array
    ok: Array | None  # a guarded law's guard at the sample, traced (None: no guard, or numpy, where the law raises)
    dw: Array | None  # the monitors' summands at the tick (the passivity integrand, as the law saw the tick), or None


class Record(NamedTuple):
    """What a logged tick keeps (the names of the result's signals)."""

    z: Array  # [s_k, x_k, w_k]
    tau: Array  # the applied u_k
    tau_commanded: Array
    q_measured: Array
    dq_measured: Array
    sample: running.Sample | None = None  # the tick's sample for the running metrics (folded by the driver, not logged)


def guarded_rk4(g: Callable[[Array], tuple[Array, Array]], y: Array, h: float) -> tuple[Array, Array, Array]:
    """:func:`rk4` of dy/dt = g(y)[0], g also giving a guard: (the step, whether it held in all four stages, the first
    stage state where it did not)."""
    xp = array_namespace(y)
    k1, ok1 = g(y)
    y2 = y + 0.5 * h * k1
    k2, ok2 = g(y2)
    y3 = y + 0.5 * h * k2
    k3, ok3 = g(y3)
    y4 = y + h * k3
    k4, ok4 = g(y4)
    bad = xp.where(ok1, xp.where(ok2, xp.where(ok3, y4, y3), y2), y)
    return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4), ok1 & ok2 & ok3 & ok4, bad


@dataclass(frozen=True, eq=False)
class Tick(Module):
    """One control tick of the sampled-data loop as a pure function of (carry, inputs) (module docstring). Holds
    constants only: the closed loop, the sampling options, the sensor and actuator (defaults: exact, none), the
    divergence bound and whether the law has a delay line."""

    loop: ClosedLoop
    opts: Sampled
    sensor: Sensor
    actuator: Actuator
    max_state: float
    has_line: bool

    def start(self, z0: Array, line: Array | None = None) -> Carry:
        """The carry before tick 0: z0 = [s0, x0, w0] (ClosedLoop.start) and the delay line's initial contents (None: no
        line)."""
        n, m, Ts = self.loop.n, self.loop.m, self.opts.control_period
        xp = array_namespace(z0)
        s, x = z0[:m], z0[m : z0.shape[0] - self.loop.w]
        buffer = np.zeros(0) if line is None else np.array(line, dtype=float)
        actuator = tuple(xp.asarray(a) for a in self.actuator.start())
        return Carry(s, x, self.sensor.start(s[:n], s[n : 2 * n], Ts), actuator, xp.asarray(buffer),
                     xp.zeros(self.loop.w))

    def __call__(self, carry: Carry, inputs: Any, dynamics: Dynamics | None = None) -> tuple[Carry, Record, Verdict]:
        """(carry_{k+1}, record_k, verdict_k): steps 1–7 of the module docstring; `dynamics` the plant's ds/dt
        (default :meth:`dynamics`). The verdict's `held` is the guard at the sample, its `bad` the (q, x) a guard failed
        at."""
        mid, sample = self.sample(carry, inputs)
        new, why, x_bad = self.advance(mid, inputs, sample, dynamics or self.dynamics)
        if sample.ok is None:
            return new, self.record(mid, sample, inputs[2]), Verdict(None, why, None)
        x_bad = array_namespace(mid.x).where(sample.ok, x_bad, mid.x)
        return new, self.record(mid, sample, inputs[2]), Verdict(sample.ok, why, (sample.q_m, x_bad))

    def compiled(self, native: bool = False) -> Callable[[Carry, Any], tuple[Carry, Record, Verdict]]:
        """The tick with the plant's ds/dt as a function of its own: traced once, called by every RK4 stage of every
        plant sub-step (an n-DOF arm's dynamics: thousands of operations), for XLA and C alike."""
        return partial(self.__call__, dynamics=jax_module().jit(self.dynamics))

    def blanks(self, carry: Carry) -> tuple[Record, tuple[Array, Array] | None]:
        """Zeros like the record and like `bad` (the q and x a guard failed at; None without a guard)."""
        xp = array_namespace(carry.s, carry.x)
        n, zero = self.loop.n, xp.zeros(carry.s.shape[-1] + carry.x.shape[-1] + carry.w.shape[-1])
        record = Record(zero, *(xp.zeros(n) for _ in range(4)))
        return record, (xp.zeros(n), xp.zeros_like(carry.x)) if self.loop.guarded else None

    def sample(self, carry: Carry, inputs: Any) -> tuple[Carry, Sample]:
        """Steps 1–4: the carry with the sensor's, the delay line's and the actuator's memory advanced and x_k read
        from the line, and the tick's samples."""
        k, t, ref, noise = inputs
        n, Ts, ctrl = self.loop.n, self.opts.control_period, self.loop.controller
        s, x, line = carry.s, carry.x, carry.line
        (q_m, dq_m, ddq_m), sensor = self.sensor.measure(carry.sensor, s[:n], s[n : 2 * n], noise, Ts)
        if self.has_line:
            slot = k % line.shape[0]
            x, store = ctrl.sample(t, x, q_m, dq_m, ref, array_namespace(line).asarray(line[slot], copy=True))
            line = ring_write(line, slot, store)
        ok = ctrl.guard(t, x, q_m, dq_m, ref)

        def apply(tau: Array) -> tuple[Array, Array, Any]:  # the actuator's torque; q̈ as the sensor measured it
            u, actuator = self.actuator.apply(carry.actuator, tau, Ts)
            return u, ddq_m, actuator

        tau, u, dx, actuator = ctrl.respond(t, x, q_m, dq_m, ref, apply)  # a torque filter is given the held u_k
        dw = self.loop.dissipation(t, x, q_m, dq_m, ref)[..., None] if self.loop.w else None
        return carry._replace(x=x, sensor=sensor, actuator=actuator, line=line), Sample(q_m, dq_m, ddq_m, tau, u, dx,
                                                                                        ok, dw)

    def record(self, carry: Carry, sample: Sample, ref: Reference) -> Record:
        """Step 5, from the carry `sample` returned."""
        z = array_namespace(carry.s, carry.x).concatenate([carry.s, carry.x, carry.w])
        n = self.loop.n
        e, de = self.loop.controller.tracking_error(carry.s[:n], carry.s[n : 2 * n], ref)
        tally = running.Sample(e, de, sample.u, sample.tau)
        return Record(z, sample.u, sample.tau, sample.q_m, sample.dq_m, tally)

    def advance(self, carry: Carry, inputs: Any, sample: Sample,
                dynamics: Dynamics) -> tuple[Carry, Array, Array | None]:
        """Steps 6–7: the carry one tick on, the code why the run stops there (0: it goes on) and, for a guarded law,
        the state x its guard failed at under "hold" (x_k otherwise; None without a guard read)."""
        t, ref = inputs[1], inputs[2]
        x, ok, x_bad = self.next_state(t, ref, carry.x, sample)
        s = self.hold(t, carry.s, sample.u, dynamics)
        xp = array_namespace(s, x)
        why = self.loop.divergence(xp.concatenate([s, x, carry.w]), self.max_state)
        if ok is not None:
            why = xp.where(ok, why, GUARD)
        elif sample.ok is not None:
            x_bad = carry.x
        w = carry.w
        if sample.dw is not None:  # the sum, then its running minimum
            total = carry.w[:1] + self.opts.control_period * sample.dw
            w = xp.concatenate([total, xp.minimum(carry.w[1:], total)])
        return carry._replace(s=s, x=x, w=w), why, x_bad

    def next_state(self, t: Array, ref: Reference, x: Array, sample: Sample) -> tuple[Array, Array | None, Array | None]:
        """x_{k+1} by the discrete rule, projected (each sub-step of "hold", where ẋ = f(x) has every other input held
        at its sample, u_k too; a law that filters the torque filters u_k); for a guarded law under "hold" (traced),
        whether its guard held in every stage and the first stage state where it did not (None otherwise)."""
        opts, ctrl, q, dq, ddq = self.opts, self.loop.controller, sample.q_m, sample.dq_m, sample.ddq_m
        if opts.discretization == "euler":
            h = opts.control_period
            return ctrl.project(ctrl.step(x, sample.dx, h)), None, None

        def rate(_t: Any, y: Array) -> Array:  # every input held at its sample, u_k and the measured q̈ too
            return ctrl.respond(t, y, q, dq, ref, lambda _tau: (sample.u, ddq, None))[2]

        xp = array_namespace(x)
        if sample.ok is None:
            return repeat(xp, opts.substeps, lambda _i, y: ctrl.project(rk4(rate, 0.0, y, opts.dt)), x), None, None

        def guarded(_i: Any, state: tuple[Array, Array, Array]) -> tuple[Array, Array, Array]:
            y, ok, bad = state
            y, ok_i, bad_i = guarded_rk4(lambda y: (rate(0.0, y), ctrl.guard(t, y, q, dq, ref)), y, opts.dt)
            return ctrl.project(y), ok & ok_i, xp.where(ok, bad_i, bad)

        return repeat(xp, opts.substeps, guarded, (x, xp.asarray(True), x))

    def dynamics(self, t: Array, s: Array, u: Array) -> Array:
        """The plant's ds/dt under the applied torque u (rigid: [q̇, the plant's acceleration], as in the continuous
        loop)."""
        plant, n = self.loop.plant, self.loop.n
        if self.loop.rigid:
            return array_namespace(s).concatenate([s[n:], plant.acceleration(t, s[:n], s[n:], u)])
        return plant.derivative(t, s, u)

    def hold(self, t: Array, s: Array, u: Array, dynamics: Dynamics) -> Array:
        """The plant's state one control period on, under the held torque u: the plant's advance hook
        (:meth:`robotadapt.plant.plant.Plant.advance`: `substeps` RK4 steps of dt of `dynamics`; MuJoCo's own steps for
        a MuJoCo plant)."""
        return self.loop.plant.advance(t, s, u, self.opts.substeps, self.opts.dt, dynamics)

    def status(self, k: int, why: int, bad: tuple[Array, Array] | None) -> Status:
        """The status of a run stopped at tick k for the code `why`: at t_k for a guard (the law's reason at the (q, x)
        of `bad`), at t_k + Ts for the divergence guard."""
        t = k * self.opts.control_period
        if why == GUARD:
            q_bad, x_bad = bad  # type: ignore[misc]
            return Status.at(t, str(self.loop.controller.stop_reason(np.asarray(q_bad), np.asarray(x_bad))))
        return Status.at(t + self.opts.control_period, REASONS[why].format(max_state=self.max_state))

    def signals(self, records: Record, t: Array, ref: Reference) -> tuple[Array, Array]:
        """(z, the applied torque) at the logged ticks, from their records."""
        return records.z, records.tau

    def logged(self, records: Record) -> dict[str, Array]:
        """The result's signals from the stacked records: `tau` (applied), and `tau_commanded` with an actuator,
        `q_measured`, `dq_measured` with a sensor."""
        plant = self.loop.plant
        keep = ["tau"] + ["tau_commanded"] * (plant.actuator is not None) + ["q_measured", "dq_measured"] * (
            plant.sensor is not None)
        return {name: getattr(records, name) for name in keep}


def feed(ticks: list[Tick], trajectories: list[Trajectory], shared: bool) -> tuple[Callable[[int, int], Inputs], Inputs]:
    """The inputs of ticks first … first + count − 1 for every run: k, t_k shared; the reference shared (`shared`: one
    trajectory for all) or per run on axis 1; the sensors' noise drawn from each run's seed, in order, per run on axis
    1 (zeros, shared, where no run is noisy). Returns the feed and which inputs are per run (the driver's `mapped`)."""
    Ts, n = ticks[0].opts.control_period, ticks[0].loop.n
    noisy = any(t.sensor.noise_q is not None or t.sensor.noise_dq is not None for t in ticks)
    draws = [_Draws(tick.sensor) for tick in ticks]

    def inputs(first: int, count: int) -> Inputs:
        k = np.arange(first, first + count)
        refs = [trajectory(Ts * k) for trajectory in trajectories[: 1 if shared else None]]
        ref = refs[0] if shared else Reference(*(np.stack(parts, axis=1) for parts in zip(*refs, strict=True)))
        noise = np.stack([d(first, count) for d in draws], axis=1) if noisy else np.zeros((count, 2, n))
        return Inputs(k, Ts * k, ref, noise)

    return inputs, Inputs(False, False, not shared, noisy)  # type: ignore[arg-type]


class _Draws:
    """A run's noise draws by tick: ticks first … first + count − 1 of its seed's one sequence, whatever the order of
    the requests (a tick asked for again gets the same draws; ticks before the last request's first are forgotten)."""

    def __init__(self, sensor: Sensor) -> None:
        self.sensor, self.rng = sensor, sensor.generator()
        self.start, self.ahead = 0, np.zeros((0, 2, sensor.n))

    def __call__(self, first: int, count: int) -> Array:
        if first < self.start:
            raise ValueError(f"tick {first} was forgotten (the draws start at tick {self.start})")
        end = self.start + len(self.ahead)
        if first + count > end:
            self.ahead = np.concatenate([self.ahead, self.sensor.noise(self.rng, first + count - end)])
        self.ahead, self.start = self.ahead[first - self.start :], first
        return self.ahead[:count]


def integrate_batch(loops: list[ClosedLoop], traj: Trajectory | list[Trajectory], z0: Array, opts: Sampled,
                    grid: Grid, max_state: float, progress: bool, lines: list[Array] | None,
                    backend: str = "numpy") -> tuple[Array, Array, Array, list[Status], running.Running,
                                                     dict[str, Array]]:
    """N runs' ticks 0 … `grid.n` through the one driver: one program mapped over the runs (`backend` "jax") or the
    runs in lockstep in Python ("numpy", the reference). `traj`: one trajectory for every run or one per run; `z0`
    `(N, d)`; `lines` each run's delay line contents (None: no line). Returns the logged times, the states `(T, N, d)`,
    each run's logged count (a stopped run's rows after it repeat its last one), the statuses and the logged signals
    `(T, N, n)` (:meth:`Tick.logged`)."""
    ticks = [Tick(loop, opts, loop.plant.sensor or Sensor(loop.n), loop.plant.actuator or Actuator(loop.n), max_state,
                  lines is not None) for loop in loops]
    carries = [tick.start(z0[i], None if lines is None else lines[i]) for i, tick in enumerate(ticks)]
    shared = not isinstance(traj, list)
    inputs, mapped = feed(ticks, traj if isinstance(traj, list) else [traj], shared)
    trace = drive(ticks, carries, inputs, grid.n, grid.log_every, backend=backend, mapped=mapped, progress=progress)
    records = trace.records
    return (grid.times(records.z.shape[0]), records.z, trace.n_logged, trace.status, trace.running,
            ticks[0].logged(records))


def integrate(loop: ClosedLoop, traj: Trajectory, z0: Array, opts: Sampled, grid: Grid, max_state: float,
              progress: bool, line: DelayLine | None,
              backend: str = "numpy") -> tuple[Array, Array, Status, dict[str, Any], dict[str, Array]]:
    """Ticks 0 … `grid.n` from t = 0, stepped by numpy (`backend` "numpy") or compiled by JAX ("jax"; the same tick,
    equal to round-off; `progress` is not shown); returns the logged (t, z), the status and the logged signals
    (:meth:`Tick.logged`). `line` gives the delay line's initial contents; it is not written. One run of
    :func:`integrate_batch`."""
    t, z, _, status, folded, logged = integrate_batch([loop], traj, np.asarray(z0)[None], opts, grid, max_state,
                                                      progress, None if line is None else [line.buffer], backend)
    return t, z[:, 0], status[0], running.values(running.run(folded, 0), grid.h), {name: a[:, 0] for name, a in
                                                                                     logged.items()}
