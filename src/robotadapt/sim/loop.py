"""The closed loop, defined once (DESIGN "Simulation"): the state layout z = [s, x], the vector field dz/dt = f(t, z)
(:class:`ClosedLoop`), the one fixed step every fixed-step path takes (:func:`step`: numpy, batches, the compiled
engine), the delay line of a law with one (Law.delay_line), the guard of a law with one (Law.guard) and the divergence
guard.

State z = [s, x]: the plant's state s = [q, q̇] (then θ, θ̇ of elastic joints and the motor currents, see
:mod:`robotadapt.plant`) and the controller's x. A fixed-step run carries (z, line, k): the state, the delay line (a
:class:`Ring`, or None) and the step index; :func:`step` maps them to the next ones without writing into any array, so
that the numpy drivers loop over it and the compiled engine scans over it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any, NamedTuple, cast

import numpy as np

from ..arrays import array_namespace
from ..controllers.base import as_law
from ..plant.plant import Plant, same_model
from ..pytree import Module
from ..trajectories import Reference, Trajectory
from .driver import GUARD, Verdict
from .running import Sample
from .status import Status

Array = Any
Respond = Callable[[Any, Array, Reference], tuple[Array, Array | None, Array, Array]]  # ClosedLoop.respond
MAX_LOG_BYTES = 4e9


@dataclass(frozen=True, eq=False)
class ClosedLoop(Module):
    """The closed-loop vector field dz/dt = f(t, z), z = [s, x]; the plant receives the saturated torque. Controllers
    that need q̈ get the plant's acceleration for the torque they just applied (no algebraic loop: their torque does not
    depend on q̈). A law that filters the torque (Law.applied) is given the torque the plant receives.

    `monitored`: the state also carries, after x, the monitors' integrals w, integrated with the loop at every step
    (never from the logged samples): the passivity integral ∫₀ᵗ −rᵀ Z (φ(t) − φ̂) of (6.4.4) for a law with a
    passivity output (Law.regressor) whose model is the plant's, so its truth φ(t) is known, and its running minimum
    over the steps (:meth:`after_step`). z = [s, x, w]; the divergence guard reads [s, x] only, without the trailing
    `records` of x a law may keep for its monitor alone (the repetitive law's window integrals of V, (7.2.43))
    (:meth:`guarded_part`)."""

    plant: Plant
    controller: Any  # a Law (one with needs_acceleration: its torque, then its update with the plant's q̈)
    n: int
    monitored: bool = False
    m: int = field(init=False)  # the plant's state size, 2n + its extra states
    rigid: bool = field(init=False)  # no extra plant states: the fast path
    guarded: bool = field(init=False)  # the law has a guard, which traced evaluations read
    w: int = field(init=False)  # how many monitor values trail the state (0, or 2: the passivity integral, its min)
    unguarded: int = field(init=False)  # trailing entries the guard skips: w and the law's own records (`records`)

    def __post_init__(self) -> None:  # the law's static facts, read once, not per evaluation
        ctrl = as_law(self.controller)
        object.__setattr__(self, "guarded", ctrl.has("guard"))
        object.__setattr__(self, "m", 2 * self.n + self.plant.n_extra)
        object.__setattr__(self, "rigid", self.plant.n_extra == 0)
        passive = self.monitored and ctrl.has("regressor")  # a passivity output
        object.__setattr__(self, "w", 2 * int(passive and same_model(self.plant.model, ctrl.model)))
        object.__setattr__(self, "unguarded", self.w + ctrl.records)

    def split(self, z: Array) -> tuple[Array, Array, Array]:
        n = self.n
        return z[..., :n], z[..., n : 2 * n], z[..., self.m : z.shape[-1] - self.w]

    def start(self, s0: Array, x0: Array) -> Array:
        """z0 = [s0, x0, w0 = 0] (leading run axes allowed)."""
        return np.concatenate([s0, x0, np.zeros(np.shape(x0)[:-1] + (self.w,))], axis=-1)

    def guarded_part(self, z: Array) -> Array:
        """[s, x] without the records: what the divergence guard reads (the monitors' integrals are records of the run,
        not the loop's state)."""
        return z[..., : z.shape[-1] - self.unguarded] if self.unguarded else z

    def passivity(self, z: Array) -> tuple[Array, Array] | None:
        """(the passivity integral (6.4.4), its minimum over every step so far) carried in z; None where the loop
        carries none."""
        return (z[..., -2], z[..., -1]) if self.w else None

    def dissipation(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The passivity integrand −rᵀ Z (φ(t) − φ̂) = −(Zᵀ r)ᵀ (φ(t) − φ̂) at (q, q̇) as the law sees them, φ̂ as its
        torque uses it (Zᵀ r from the law's regressor products where it has them: the same pass as its torque's)."""
        ctrl = self.controller
        phi_hat = ctrl.phi_hat_at(t, x, q, dq, ref)
        _, Ztr, _ = ctrl.regressor_products(t, x, q, dq, ref, phi_hat)
        return -(Ztr * (self.plant.phi_at(t) - phi_hat)).sum(axis=-1)

    def torque(self, t: Array, z: Array, ref: Reference) -> Array:
        """The controller's commanded torque (before the actuator's saturation)."""
        q, dq, x = self.split(z)
        return self.controller.torque(t, x, q, dq, ref)

    def _plant(self, t: Array, z: Array, q: Array, dq: Array, u: Array) -> tuple[Array, Array]:
        """(the plant's ds/dt without q̇, q̈) for the applied torque."""
        if self.rigid:
            return dq, self.plant.acceleration(t, q, dq, u)
        ds = self.plant.derivative(t, z[..., : self.m], u)
        return ds, ds[..., self.n : 2 * self.n]

    def rate(self, t: Array, z: Array, ref: Reference) -> tuple[Array, Array | None]:
        """(dz/dt, ok). `ok` is the law's guard per run, False where its assumption fails at z (dz/dt then holds NaN);
        None for a law without one."""
        dz, ok, _, _ = self.respond(t, z, ref)
        return dz, ok

    def respond(self, t: Array, z: Array, ref: Reference) -> tuple[Array, Array | None, Array, Array]:
        """(dz/dt, ok, τ, u): :meth:`rate` with the law's command τ and the torque u the plant receives."""
        q, dq, x = self.split(z)
        xp = array_namespace(z)
        ok = self.controller.guard(t, x, q, dq, ref)

        def apply(tau: Array) -> tuple[Array, Array, tuple[Array, Array]]:  # the plant under the torque it receives
            u = self.plant.saturate(tau)
            head, ddq = self._plant(t, z, q, dq, u)
            return u, ddq, (head, ddq)

        tau, u, dx, (head, ddq) = self.controller.respond(t, x, q, dq, ref, apply)
        parts = [head, ddq, dx] if self.rigid else [head, dx]
        if self.w:  # the running minimum is constant within a step and updated after it (after_step)
            d = self.dissipation(t, x, q, dq, ref)[..., None]
            parts += [d, 0.0 * d]
        return xp.concatenate(parts, axis=-1), ok, tau, u

    def __call__(self, t: Array, z: Array, ref: Reference) -> Array:
        return self.rate(t, z, ref)[0]

    def divergence(self, z: Array, max_state: float) -> Array:
        """The divergence guard at z, per run: 0 where the guarded part is finite and within `max_state`, else the code
        of :data:`REASONS` (1 non-finite, 2 beyond `max_state`)."""
        xp = array_namespace(z)
        part = self.guarded_part(z)
        return xp.where(xp.all(xp.isfinite(part), axis=-1), xp.where(xp.max(xp.abs(part), axis=-1) > max_state, 2, 0), 1)

    def stop_reason(self, z: Array) -> str:
        """Why a guarded law stops at the state z (numpy) where its guard fails."""
        q, _, x = self.split(np.asarray(z))
        return str(self.controller.stop_reason(q, x))

    def after_step(self, z: Array) -> Array:
        """The state after a fixed step: x projected (the law's `project`), the passivity integral's running minimum
        updated."""
        x = self.split(z)[2]
        projected = self.controller.project(x)
        if projected is not x:
            z = self.with_x(z, projected)
        if not self.w:
            return z
        xp = array_namespace(z)
        return xp.concatenate([z[..., :-1], xp.minimum(z[..., -1:], z[..., -2:-1])], axis=-1)

    def with_x(self, z: Array, x: Array) -> Array:
        """z with the controller's part replaced by `x` (the monitors' integrals kept)."""
        tail = [z[..., z.shape[-1] - self.w :]] if self.w else []
        return array_namespace(z, x).concatenate([z[..., : self.m], x, *tail], axis=-1)


REASONS = {1: "non-finite state", 2: "state exceeded {max_state:g} in magnitude"}  # why the divergence guard stopped


@dataclass(frozen=True)
class DelayLine:
    """The initial contents `(N, ..., n)` of the delay line of a controller with one (Law.delay_line). A run carries the
    line in its state as a :class:`Ring`, written only through :func:`ring_write`, so the controller stays pure."""

    buffer: Array


class Ring(NamedTuple):
    """A delay line as a run carries it: the slots `(N, ..., n)` and `head`, a copy of the slot the next step reads (slot
    k mod N at step k), taken right after the previous step's write. The step then reads no slot of the line it writes
    into, so that XLA updates the line in place inside a compiled loop instead of copying it every step."""

    slots: Array
    head: Array

    @classmethod
    def start(cls, buffer: Array) -> Ring:
        """The line before step 0 from its initial contents."""
        return cls(buffer, ring_read(buffer, 0))


def ring_read(line: Array, slot: Any) -> Array:
    """Row `slot` of `line`, as a copy that no later write can change."""
    if isinstance(line, np.ndarray):
        return line[slot].copy()
    import jax  # only reached with JAX arrays

    return jax.lax.dynamic_index_in_dim(line, slot, 0, keepdims=False)


def ring_write(line: Array, slot: Any, value: Array) -> Array:
    """`line` with row `slot` replaced by `value`, as a new array; `line` itself is never written (numpy: a copy with
    the row set; JAX: `.at[slot].set`, which XLA does in place inside a scan)."""
    if isinstance(line, np.ndarray):
        new = line.copy()
        new[slot] = value
        return new
    return line.at[slot].set(value)


def sample(loop: ClosedLoop, k: Any, t: Any, z: Array, line: Ring, ref: Reference) -> tuple[Array, Ring]:
    """The delay line at the start of step (or the instant) k: the law gets slot k mod N (`line.head`, a copy) and
    returns its state for the step and the value to store in that slot. Returns (z with that state, the line with the
    value stored and the next slot read)."""
    q, dq, x = loop.split(z)
    x_new, store = loop.controller.sample(t, x, q, dq, ref, line.head)
    n = line.slots.shape[0]
    slots = ring_write(line.slots, k % n, store)
    return loop.with_x(z, x_new), Ring(slots, ring_read(slots, (k + 1) % n))


def rk4_step(loop: ClosedLoop, t: Any, z: Array, dt: float, r0: Reference, rh: Reference, r1: Reference,
             respond: Respond | None = None, rolled: bool = False) -> tuple[Array, Array | None, Array | None, Array, Array]:
    """One classic RK4 step of `respond` (default `loop.respond`): (z at t + dt, ok, z_bad, τ, u), τ and u the law's
    command and the applied torque at the first stage (t, z). For a guarded law, `ok` per run says its guard held in
    all four stages and `z_bad` is the state of the first stage where it did not (else None, None).

    `rolled` (traced by JAX only): the four stages as one `lax.scan`, so the program holds the closed loop's dynamics
    once instead of four times; the same operations on the same numbers, which XLA may fuse otherwise: the same step
    to round-off (the Panda's state over 2 s: 7e-15 apart). XLA's compilation of the Panda's differentiated run:
    55 → 23 s (docs/performance.md)."""
    respond = loop.respond if respond is None else respond
    if rolled:
        return _rolled(loop, t, z, dt, (r0, rh, rh, r1), respond)
    k1, ok1, tau, u = respond(t, z, r0)
    z2 = z + 0.5 * dt * k1
    k2, ok2, _, _ = respond(t + 0.5 * dt, z2, rh)
    z3 = z + 0.5 * dt * k2
    k3, ok3, _, _ = respond(t + 0.5 * dt, z3, rh)
    z4 = z + dt * k3
    k4, ok4, _, _ = respond(t + dt, z4, r1)
    return _combined(loop, z, dt, (k1, k2, k3, k4), (ok1, ok2, ok3, ok4), (z, z2, z3, z4), tau, u)


def _rolled(loop: ClosedLoop, t: Any, z: Array, dt: float, refs: tuple[Reference, ...],
            respond: Respond) -> tuple[Array, Array | None, Array | None, Array, Array]:
    """:func:`rk4_step` with its stages scanned: stage i at t + c_i·dt from z + c_i·dt·k_{i−1} (z itself at i = 0)."""
    from ..tracing import jax_module

    jax = jax_module()
    jnp = jax.numpy
    c = np.array([0.0, 0.5, 0.5, 1.0])

    def stage(k_prev: Array, at: tuple[Array, Array, Reference]) -> tuple[Array, tuple[Array, ...]]:
        i, step_i, ref = at
        z_i = jnp.where(i == 0, z, z + step_i * k_prev)
        k, ok, tau, u = respond(t + step_i, z_i, ref)
        return k, (k, ok, z_i, tau, u)

    stacked = jax.tree_util.tree_map(lambda *a: jnp.stack([jnp.asarray(x) for x in a]), *refs)
    _, (ks, oks, zs, taus, us) = jax.lax.scan(stage, jnp.zeros_like(z), (jnp.arange(4), c * dt, stacked))
    split = tuple(ks[i] for i in range(4))
    return _combined(loop, z, dt, split, (None,) * 4 if oks is None else tuple(oks[i] for i in range(4)),
                     tuple(zs[i] for i in range(4)), taus[0], us[0])


def _combined(loop: ClosedLoop, z: Array, dt: float, ks: tuple[Array, ...], oks: tuple[Array | None, ...],
              zs: tuple[Array, ...], tau: Array, u: Array) -> tuple[Array, Array | None, Array | None, Array, Array]:
    """The step from its four stages' rates `ks`, guards `oks` and states `zs` (:func:`rk4_step`'s result)."""
    k1, k2, k3, k4 = ks
    z_new = loop.after_step(z + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))
    ok1, ok2, ok3, ok4 = oks
    if ok1 is None or ok2 is None or ok3 is None or ok4 is None:
        return z_new, None, None, tau, u
    xp = array_namespace(z)
    z_bad = xp.where(ok1[..., None], xp.where(ok2[..., None], xp.where(ok3[..., None], zs[3], zs[2]), zs[1]), zs[0])
    return z_new, ok1 & ok2 & ok3 & ok4, z_bad, tau, u


class Step(NamedTuple):
    """What :func:`step` returns (a JAX pytree as it stands; None where the loop has no such part)."""

    applied: Array  # the state applied over step k (x read from a delay line): what a log at t_k holds
    line: Ring | None  # the delay line after step k
    z: Array  # the state at t_{k+1}
    ok: Array | None  # a guarded law's guard held in every stage, per run
    z_bad: Array | None  # the first stage state where it did not
    tau: Array  # the law's command at t_k (the first stage)
    u: Array  # the torque the plant receives at t_k


def step(loop: ClosedLoop, k: Any, t: Any, z: Array, line: Ring | None, dt: float, r0: Reference, rh: Reference,
         r1: Reference, respond: Respond | None = None, rolled: bool = False) -> Step:
    """Fixed step k from t = k·dt: the delay line's sample (if any), then RK4 with the sampled part of x held over the
    step's stages (`rolled`: as :func:`rk4_step`). Pure: the step of :class:`RK4Step` and of the differentiable
    rollout."""
    if line is not None:
        z, line = sample(loop, k, t, z, line, r0)
    z_new, ok, z_bad, tau, u = rk4_step(loop, t, z, dt, r0, rh, r1, respond, rolled)
    return Step(z, line, z_new, ok, z_bad, tau, u)


class Logged(NamedTuple):
    """A fixed step's record: the state applied over step k (what the log at t_k holds) and the step's sample for the
    running metrics (:mod:`robotadapt.sim.running`; the driver folds it at every step and logs None in its place)."""

    z: Array
    sample: Sample | None


class StepInputs(NamedTuple):
    """What fixed step k takes from outside: k and the reference at t_k, t_k + dt/2, t_k + dt (t_k = k·dt is computed
    in the step: fed as an input, it costs the compiled step half as much again, measured on Example 6.3.1). None: the
    step evaluates its own trajectory (:attr:`RK4Step.trajectory`)."""

    k: Array
    r0: Reference | None
    rh: Reference | None
    r1: Reference | None


@dataclass(frozen=True, eq=False)
class RK4Step(Module):
    """A continuous-time run's fixed step as a transition of the one driver (:mod:`robotadapt.sim.driver`): carry (z,
    delay line or None), inputs (k, the reference at t_k, t_k + dt/2, t_k + dt); the record is the state applied
    over step k (what the log at t_k holds); the verdict is the divergence guard on z_{k+1} (codes of `REASONS`: a stop
    at t_k + dt) or a guarded law's guard failing in a stage (GUARD: a stop within the step, with the law's reason at
    the stage state where it failed).

    `trajectory`: the reference the step evaluates itself, at k·dt, (k + ½)·dt and (k + 1)·dt, the instants the feed
    would sample (a compiled single run: inside the program, the reference is three evaluations a step in C, not
    arrays of 2n + 1 instants computed and copied in Python); None: fed. `rolled`: the stages scanned (:func:`rk4_step`;
    a step traced by JAX only)."""

    loop: ClosedLoop
    dt: float
    max_state: float
    trajectory: Trajectory | None = None
    rolled: bool = False

    def __call__(self, carry: tuple[Array, Ring | None], inputs: StepInputs,
                 respond: Respond | None = None) -> tuple[tuple[Array, Ring | None], Logged, Verdict]:
        k = inputs.k
        if self.trajectory is not None:
            r0, rh, r1 = (self.trajectory(self.dt * (k + h)) for h in (0.0, 0.5, 1.0))
        else:
            r0, rh, r1 = cast(tuple[Reference, Reference, Reference], inputs[1:])
        s = step(self.loop, k, k * self.dt, carry[0], carry[1], self.dt, r0, rh, r1, respond, self.rolled)
        why = self.loop.divergence(s.z, self.max_state)
        if s.ok is not None:
            why = array_namespace(why).where(s.ok, why, GUARD)
        q, dq, _ = self.loop.split(s.applied)
        e, de = self.loop.controller.tracking_error(q, dq, r0)
        sample = Sample(e, de, s.u, s.tau)
        return (s.z, s.line), Logged(s.applied, sample), Verdict(None, why, s.z_bad)

    def compiled(self, native: bool = False) -> Callable[[Any, Any], Any]:
        """The step with dz/dt as a function of its own (an n-DOF arm's dynamics are thousands of operations: traced
        and lowered once, not once per RK4 stage) and its short sums written out (:func:`robotadapt.sim.compiled.lean`).
        For XLA (not `native`), a step too long for that has its stages rolled (:func:`rk4_step`): XLA inlines the
        function four times, and the Panda's first 2-s run took 6.3 s, rolled 4.5 s, equal to round-off (the C
        program calls the one function it has)."""
        from ..tracing import jax_module
        from .compiled import lean

        respond = jax_module().jit(self.loop.respond)
        large = None if native else partial(replace(self, rolled=True).__call__, respond=respond)
        return lean(partial(self.__call__, respond=respond), large)

    def blanks(self, carry: tuple[Array, Ring | None]) -> tuple[Logged, Array | None]:
        """Zeros like the logged record (the state; its sample is not logged) and like `bad` (the stage state a guard
        failed at; None without one)."""
        zero = array_namespace(carry[0]).zeros_like(carry[0])
        return Logged(zero, None), zero if self.loop.guarded else None

    def feed(self, trajectory: Trajectory, runs: bool = False) -> Callable[[int, int], Any]:
        """The inputs of steps first … first + count − 1: the reference at each step's three stage instants in one
        vectorized call (`runs`: a merged trajectory with a run axis, sampled on `(times, 1)`); the step indices only
        where the step holds the trajectory."""
        def inputs(first: int, count: int) -> Any:
            if self.trajectory is not None:
                return StepInputs(np.arange(first, first + count), None, None, None)
            times = self.dt * (first + 0.5 * np.arange(2 * count + 1))
            ref = trajectory(times[:, None] if runs else times)
            k = np.arange(first, first + count)
            return StepInputs(k, *(Reference(*(a[at : at + 2 * count : 2] for a in ref)) for at in (0, 1, 2)))

        return inputs

    def signals(self, records: Logged, t: Array, ref: Reference) -> tuple[Array, Array]:
        """(z, the torque the plant receives) at the logged instants: the records hold the states; the torque is
        recomputed from them by the pure maps, as :func:`robotadapt.sim.outputs.outputs` does."""
        return records.z, self.loop.plant.saturate(self.loop.torque(t, records.z, ref))

    def start(self, z0: Array, line: Array | None = None) -> tuple[Array, Ring | None]:
        """The carry before step 0: z0 and the delay line from its initial contents `line` (None: no line), in z0's
        array namespace (as :meth:`robotadapt.sim.sampled.Tick.start`)."""
        return z0, None if line is None else Ring.start(array_namespace(z0).asarray(line))

    def status(self, k: int, why: int, bad: Array | None) -> Status:
        t = k * self.dt
        if why == GUARD:
            return Status.within(t, self.dt, self.loop.stop_reason(bad))
        return Status.at(t + self.dt, REASONS[why].format(max_state=self.max_state))
