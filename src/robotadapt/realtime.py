"""A scenario's controller for a real robot's fixed-rate loop (issue 18; docs/realtime.md).

    ctrl = RealtimeController.from_scenario("panda-mujoco")
    ctrl.reset(q, dq)                      # at the robot's measured state
    tau = ctrl.step(t, q, dq)              # every period Ts, from the driver's callback

One step is the sampled-data tick of :mod:`robotadapt.sim.sampled` without its plant: the measurement path (exact
samples; q̈ by the backward difference for a law that needs it), the delay line of a law with one, the law
τ_k, ẋ_k = ctrl(t_k, x_k, q_k, q̇_k, ref(t_k)) and the discrete update x_{k+1} = x_k + Ts ẋ_k ("euler", projected)
— the same function that the simulator scans, so a run in simulation and on the robot differ by the plant only. The
controller's state (x, the measurement memory, the delay line) lives inside the object between calls.

Backends: "jax" compiles the tick once (`jax.jit(...).lower(...).compile()`, cached on disk under
$ROBOTADAPT_CACHE/jax) on one vector each way (:func:`packed`): the state raveled into one device buffer, donated to
the call that replaces it, and [k, t, q, q̇] written into one preallocated input buffer; a step allocates no new state
and runs no Python of the law. The compiled step runs synchronously, on a CPU client of its own
(:func:`sync_cpu_device`): JAX's CPU client dispatches asynchronously by default, which costs a real-time step its
latency (the Panda's step measured p50 54 → 29 µs, p99 217 → 67 µs, max 4189 → 226 µs without it), and
`jax_cpu_enable_async_dispatch` cannot be scoped: JAX reads it once, when it creates its CPU client, so
`jax.config.update` afterwards changes nothing, and it has no context manager. The private client leaves that setting,
and JAX's own client that the rest of a program uses, as they were. "c" translates the same traced tick to C
(:mod:`robotadapt.native`: the export `robotadapt export` writes), builds it with the system's C compiler (cached on
disk by its source) and calls it through ctypes on preallocated buffers. "numpy" calls the law itself (a Pinocchio
model, whose C++ JAX cannot trace, takes it). "auto" takes "c" where the model is traceable and a compiler is present
(else "jax", saying once why), and "jax" where the translator lacks one of the tick's primitives (a user's law
may use one), saying so. A guarded law's guard (adaptive computed torque's M̂ ≻ 0) raises on the numpy backend and is not
read on the compiled ones.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache, partial
from typing import Any

import numpy as np

from .arrays import array_namespace
from .native.build import INSTALL, compiler, library, shared_library, traced
from .native.c99 import Unsupported
from .native.controller import Export, export
from .plant.actuators import Actuator
from .plant.sensors import Sensor
from .sim.integrators import Sampled, check_backend
from .sim.loop import ClosedLoop
from .sim.sampled import Carry, Inputs, Tick
from .studies.scenarios import load
from .tracing import float64, jax_module
from .trajectories import Trajectory
from .validation import ConfigError, as_scalar, as_vector

Array = Any


def start(loop_tick: Tick, Ts: float, q: Array, dq: Array) -> Carry:
    """The carry before tick 0 at the measured (q, q̇): the law's initial state, the measurement memory and the delay
    line's initial contents."""
    ctrl = loop_tick.loop.controller
    xp = array_namespace(q, dq)
    line = ctrl.delay_line(Ts, q, dq) if loop_tick.has_line else None
    return loop_tick.start(xp.concatenate([q, dq, ctrl.initial_state(q, dq)]), line)


def tick(loop_tick: Tick, trajectory: Trajectory, k: Array, t: Array, carry: Carry, q: Array,
         dq: Array) -> tuple[Array, Carry]:
    """(τ_k, the carry for tick k + 1) at the measured (q, q̇): steps 1–4 and the controller's update of step 6 of
    :mod:`robotadapt.sim.sampled`, the plant's state replaced by the measurement."""
    xp = array_namespace(q, dq)
    carry = carry._replace(s=xp.concatenate([q, dq]))
    ref = trajectory(t)
    mid, sample = loop_tick.sample(carry, Inputs(k, t, ref, xp.zeros((2, q.shape[-1]))))
    x, _, _ = loop_tick.next_state(t, ref, mid.x, sample)
    return sample.tau, mid._replace(x=x)


def packed(loop_tick: Tick, trajectory: Trajectory, ravel: Callable[[Any], tuple[Array, Any]],
           unravel: Callable[[Array], Carry], z: Array, inputs: Array) -> tuple[Array, Array]:
    """:func:`tick` on one vector each way: the carry raveled into z, the inputs packed as [k, t, q, q̇]. A compiled
    call's cost grows with its number of buffers: packed, the two-link arm's step measured 14 µs at p50 against 43 µs
    with the carry's nine arrays and four inputs passed apart."""
    n = (inputs.shape[0] - 2) // 2
    tau, carry = tick(loop_tick, trajectory, inputs[0].astype(int), inputs[1], unravel(z), inputs[2 : 2 + n],
                      inputs[2 + n :])
    return tau, ravel(carry)[0]


@dataclass(eq=False)
class RealtimeController:
    """The law of a scenario at a fixed period `Ts` (s), with `reset(q, dq)` and `step(t, q, dq) -> tau` (module
    docstring). Build one with :meth:`from_scenario`; `backend` "c", "jax", "numpy" or "auto"."""

    loop_tick: Tick
    trajectory: Trajectory
    Ts: float
    backend: str = "auto"
    _state: Any = field(default=None, init=False, repr=False)  # the carry: raveled on the device (jax), a Carry (numpy)
    _inputs: np.ndarray = field(default_factory=lambda: np.zeros(0), init=False, repr=False)  # [k, t, q, q̇], reused
    _step: Callable[[Any, np.ndarray], tuple[Array, Any]] | None = field(default=None, init=False, repr=False)
    _unravel: Callable[[Any], Carry] | None = field(default=None, init=False, repr=False)
    _k: int = field(default=0, init=False, repr=False)
    _native: Native | None = field(default=None, init=False, repr=False)
    _auto: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        self.Ts = as_scalar(self.Ts, "simulation.control_period", positive=True)
        check_backend(self.backend)  # "c" without a compiler: one line naming how to install one
        traceable = self.loop_tick.loop.controller.model.traceable
        if self.backend in ("jax", "c") and not traceable:
            raise ConfigError("simulation.backend", "the controller's model calls compiled code JAX cannot trace "
                              f"(Pinocchio), so the {self.backend!r} backend cannot have it: use backend = 'numpy', "
                              "or robot.model = 'tree'")
        self._auto = self.backend == "auto"
        if self.backend == "auto":
            self.backend = "numpy" if not traceable else "c" if compiler() is not None else _without_compiler()

    @classmethod
    def from_scenario(cls, scenario: str, overrides: Sequence[str] = (), backend: str = "auto") -> RealtimeController:
        """The controller, trajectory and control period (`simulation.control_period`, or `dt`) of a scenario (a
        packaged name or a TOML path), with `--set`-style `overrides`; a law that prepares for a run (the repetitive
        law's table) is prepared for the scenario's `t_final`."""
        setup = load(scenario, list(overrides)).setup
        period = (setup.integrator.control_period if isinstance(setup.integrator, Sampled)
                  else getattr(setup.integrator, "dt", 1e-3))
        controller = setup.controller
        controller = controller.prepare(setup.trajectory, period, setup.t_final)
        n = setup.plant.model.n
        opts = Sampled(period)
        loop_tick = Tick(ClosedLoop(setup.plant, controller, n), opts, Sensor(n), Actuator(n), np.inf,
                         controller.has("delay_line"))
        return cls(loop_tick, setup.trajectory, period, backend)

    @property
    def n(self) -> int:
        return self.loop_tick.loop.n

    @float64
    def programs(self) -> tuple[Any, Any]:
        """The traced programs of the export (:mod:`robotadapt.native.controller`): `tick` (state, [k, t, q, q̇]) ->
        (τ, state) and `init` (q, q̇) -> state, the state the carry raveled into one float64 vector."""
        jax = jax_module()
        from jax.flatten_util import ravel_pytree

        n = self.n
        zeros = np.zeros(n)
        flat, unravel = ravel_pytree(jax.tree_util.tree_map(jax.numpy.asarray, start(self.loop_tick, self.Ts, zeros,
                                                                                     zeros)))
        step, _ = traced(partial(packed, self.loop_tick, self.trajectory, ravel_pytree, unravel), flat,
                         np.zeros(2 + 2 * n))
        init, _ = traced(lambda q, dq: ravel_pytree(start(self.loop_tick, self.Ts, q, dq))[0], zeros, zeros)
        return step, init

    def export(self, prefix: str = "ra", what: str = "") -> Export:
        """The controller as C (:func:`robotadapt.native.controller.export`)."""
        step, init = self.programs()
        return export(step, init, self.n, prefix, what)

    @float64
    def reset(self, q: Any, dq: Any) -> None:
        """Start at the measured (q, q̇): the law's initial state, the measurement memory, tick k = 0; compiles the step
        on first use (the only slow call)."""
        n = self.n
        q, dq = as_vector(q, n, "q"), as_vector(dq, n, "dq")
        carry = start(self.loop_tick, self.Ts, q, dq)
        self._inputs, self._k = np.zeros(2 + 2 * n), 0
        if self.backend == "c" and self._native is None:
            self._native = self._build(carry)
        if self.backend == "c" and self._native is not None:
            self._native.reset(q, dq)
            self._state, self._unravel = self._native.state, self._native.unravel
            return
        if self.backend == "numpy":  # the carry as it is; q and q̇ copied out of the reused input buffer
            self._state, self._unravel = carry, _same
            self._step = partial(packed, self.loop_tick, self.trajectory, _unchanged, _same)
            return
        jax = jax_module()
        from jax.flatten_util import ravel_pytree

        flat, unravel = ravel_pytree(jax.tree_util.tree_map(jax.numpy.asarray, carry))
        flat = jax.device_put(flat, sync_cpu_device())  # the program runs where its arguments are
        if self._step is None:
            program = jax.jit(partial(packed, self.loop_tick, self.trajectory, ravel_pytree, unravel),
                              donate_argnums=(0,))
            self._step = program.lower(flat, self._inputs).compile()
        self._state, self._unravel = flat, unravel

    @float64  # the step's input buffer is float64, as the program was compiled (1.4 µs here)
    def step(self, t: float, q: Array, dq: Array) -> np.ndarray:
        """τ_k for the measured (q, q̇) at time t (s) of the trajectory; the state moves on to tick k + 1."""
        if self._native is not None:
            return self._native.step(t, q, dq)
        if self._step is None:
            raise ConfigError("realtime", "call reset(q, dq) before step(t, q, dq)")
        n, inputs = self.n, self._inputs
        inputs[0], inputs[1], inputs[2 : 2 + n], inputs[2 + n :] = self._k, t, q, dq
        tau, self._state = self._step(self._state, inputs if self.backend == "jax" else inputs.copy())
        self._k += 1
        return np.asarray(tau)

    @property
    @float64
    def x(self) -> np.ndarray:
        """The controller's state x_k (φ̂ and filter states), a copy."""
        if self._unravel is None:
            return np.zeros(0)
        return np.array(self._unravel(self._state[1:] if self._native is not None else self._state).x)

    def _build(self, carry: Carry) -> Native | None:
        """The C backend's library, its state laid out as `carry` raveled (None, and "jax" from now on, where "auto"
        chose C and the translator lacks a primitive of this tick)."""
        from jax.flatten_util import ravel_pytree

        try:
            code = self.export("ra_rt")
        except Unsupported as exc:
            if not self._auto:
                raise
            warnings.warn(f"robotadapt: {exc}; this controller runs on the 'jax' backend", RuntimeWarning, stacklevel=3)
            self.backend = "jax"
            return None
        unravel = ravel_pytree(carry)[1]
        return Native(shared_library(code.standalone, "simulation.backend"), code.prefix, self.n, code.state_size,
                      unravel)


class Native:
    """An exported controller's library (`PREFIX_reset`, `PREFIX_step`) called through ctypes: the state, q, q̇ and τ in
    buffers allocated once, their addresses passed as integers."""

    def __init__(self, path: Any, prefix: str, n: int, size: int, unravel: Callable[[Any], Carry]) -> None:
        import ctypes

        lib = library(path)
        self._reset, self._step = getattr(lib, f"{prefix}_reset"), getattr(lib, f"{prefix}_step")
        pointer = ctypes.c_void_p
        self._reset.argtypes, self._reset.restype = [pointer, pointer, pointer], None
        self._step.argtypes, self._step.restype = [pointer, ctypes.c_double, pointer, pointer, pointer], None
        self.state, self.unravel = np.zeros(size), unravel
        self._q, self._dq, self._tau = np.zeros(n), np.zeros(n), np.zeros(n)
        self._addresses = tuple(a.ctypes.data for a in (self.state, self._q, self._dq, self._tau))

    def reset(self, q: Array, dq: Array) -> None:
        self._q[:], self._dq[:] = q, dq
        state, q_at, dq_at, _ = self._addresses
        self._reset(state, q_at, dq_at)

    def step(self, t: float, q: Array, dq: Array) -> np.ndarray:
        self._q[:], self._dq[:] = q, dq
        self._step(self._addresses[0], t, *self._addresses[1:])
        return self._tau.copy()


@cache
def _without_compiler() -> str:
    """'jax', having said once that the C backend needs a compiler."""
    warnings.warn(f"robotadapt: no C compiler found, so backend = 'auto' runs the controller on 'jax' ({INSTALL})",
                  RuntimeWarning, stacklevel=4)
    return "jax"


@cache
def sync_cpu_device() -> Any:
    """The CPU device of a PJRT CPU client made for real-time steps, with asynchronous dispatch off (one per process):
    a program whose arguments live on it runs inline in the calling thread and returns ready results. JAX's own client
    keeps the process's `jax_cpu_enable_async_dispatch`, which JAX reads only when it creates that client."""
    from jax._src.lib import xla_client

    client: Any = xla_client.make_cpu_client(asynchronous=False)
    return client.devices()[0]


def _same(carry: Any) -> Any:
    return carry


def _unchanged(carry: Any) -> tuple[Any, None]:
    return carry, None
