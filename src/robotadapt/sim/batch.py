"""N closed loops at once over a leading batch axis (DESIGN "Scale"): Monte-Carlo over the true parameters, studies
over initial states, initial estimates, Slotine–Li gains or sinusoid parameters, in one vectorized fixed-step RK4 loop.

Each of plant, controller and trajectory is one object shared by every run or a sequence of N objects, one per run,
each validated when it was constructed. A sequence is merged into one object of the same class whose fields that
differ between runs are stacked along a leading axis (:func:`stack`); models and controllers broadcast over it, so the
step is the very code :func:`~robotadapt.sim.simulate` runs. A field may differ only where the class's math
broadcasts it (the class's `per_run`); anything else raises :class:`NotBatchable` (simulate those runs one by one).

Per run: a run whose state becomes non-finite or exceeds `max_state`, or whose law's guard fails, stops there with its
own status and partial record; the others go on (the one driver, :mod:`robotadapt.sim.driver`). States are logged every
`log_every` steps into one `(T, N, d)` array, so memory is bounded by the log; outputs (τ, V, r, passivity) and metrics
are recomputed per run on demand by the same code as `simulate`, whose results a batch reproduces to round-off."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, fields, is_dataclass
from typing import Any, TypeVar

import numpy as np

from .. import pytree, trajectories
from ..grid import Grid
from ..plant.plant import Plant
from ..pytree import Module
from ..validation import ConfigError, as_array, as_scalar, as_vector
from . import running
from .backends import Run, execute
from .driver import drive
from .integrators import RK4, Sampled, SolveIVP, check_plant_step
from .loop import MAX_LOG_BYTES, ClosedLoop, Ring, RK4Step
from .outputs import batch_outputs, outputs
from .result import SimulationResult
from .status import Status

Array = Any
T = TypeVar("T")

class NotBatchable(ConfigError):
    """The runs differ in something one vectorized loop cannot carry; simulate them one by one."""


def _same(a: Any, b: Any) -> bool:
    if a is b:
        return True
    if type(a) is not type(b):
        return False
    if is_dataclass(a):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a) if f.compare)
    if isinstance(a, np.ndarray):
        return a.shape == b.shape and bool(np.array_equal(a, b))
    if isinstance(a, tuple | list):  # e.g. a model's per-joint tables
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return bool(a == b)


def stack(items: Sequence[T], name: str) -> T:
    """One object of the items' class whose fields that differ between the items are stacked along a new leading axis
    (nested dataclasses field by field). Raises :class:`NotBatchable` unless every differing field is one the class
    declares `per_run` (:class:`robotadapt.pytree.Module`: its math broadcasts over a leading run axis; `phi_hat0` is
    read only by `initial_state`, which the batch calls per run).

    The items were validated when constructed; the merged object is not constructed again (its derived constants are
    dropped, to be recomputed from the stacked fields: :func:`robotadapt.pytree.replace`).
    """
    first = items[0]
    if all(item is first for item in items):
        return first
    cls = type(first)
    if any(type(item) is not cls for item in items) or not is_dataclass(first):
        raise NotBatchable(name, f"the runs mix {', '.join(sorted({type(i).__name__ for i in items}))}; one batch "
                           "runs one kind")
    allowed = cls.per_run if isinstance(first, Module) else ()
    changes = {}
    for f in fields(first):
        values = [getattr(item, f.name) for item in items]
        if all(_same(v, values[0]) for v in values[1:]):
            continue
        if is_dataclass(values[0]):
            changes[f.name] = stack(values, f"{name}.{f.name}")
        elif f.name in allowed:
            arrays = [np.asarray(v, dtype=float) for v in values]
            if any(a.shape != arrays[0].shape for a in arrays):
                raise NotBatchable(f"{name}.{f.name}", "has different shapes in different runs")
            changes[f.name] = np.stack(arrays)
        else:
            raise NotBatchable(f"{name}.{f.name}", f"differs between runs; in one batch {cls.__name__} varies only "
                               f"{', '.join(allowed)} per run" if allowed else
                               f"differs between runs; one batch holds one {cls.__name__}")
    out = first
    for key, value in changes.items():
        out = pytree.replace(out, (key,), value)
    return out


@dataclass(frozen=True, eq=False)
class BatchResult:
    """The logged states of N runs on one time grid: `z[k, i]` = [s, x] of run i at `t[k]` (plant state s = [q, q̇, …],
    controller state x), valid for `k < n_logged[i]` (a frozen run's record ends where it stopped). `status[i]` is a
    :class:`~robotadapt.sim.status.Status` (``"ok"`` or ``"diverged at t=… s: reason"``), as for
    :func:`~robotadapt.sim.simulate`. `wall_time` is the whole batch's; each run's metrics report its share, `wall_time
    / N`."""

    t: Array
    z: Array
    n_logged: Array
    status: tuple[Status, ...]
    plants: tuple[Plant, ...]
    controllers: tuple[Any, ...]
    trajectories: tuple[Any, ...]
    wall_time: float
    info: dict[str, Any]
    logged: dict[str, Array] | None = None  # sampled-data runs: the signals the ticks logged, `(T, N, n)` each
    folded: running.Running | None = None  # the runs' metrics folded at every step (robotadapt.sim.running), run axis
    h: float = 0.0  # the grid's step (dt, or the control period): what the folded integrals are summed with

    def __len__(self) -> int:
        return int(self.z.shape[1])

    @property
    def ok(self) -> Array:
        """Per run: True where it ran to the end."""
        return np.array([s == "ok" for s in self.status])

    def _info(self, i: int) -> dict[str, Any]:
        plant = self.plants[i]
        return {**self.info, "run": i} | ({"plant": plant.describe()} if plant.describe() else {})

    def _folded(self, i: int) -> dict[str, Any] | None:
        return None if self.folded is None else running.values(running.run(self.folded, i), self.h)

    def run(self, i: int) -> SimulationResult:
        """Run `i` as a :class:`~robotadapt.sim.result.SimulationResult` (outputs recomputed as `simulate` does)."""
        i = range(len(self))[i]
        k, plant = int(self.n_logged[i]), self.plants[i]
        with np.errstate(all="ignore"):
            logged = None if self.logged is None else {name: a[:k, i] for name, a in self.logged.items()}
            return outputs(ClosedLoop(plant, self.controllers[i], plant.model.n, monitored=True), self.trajectories[i],
                           self.t[:k], self.z[:k, i], self.status[i], self.wall_time / len(self), self._info(i), logged,
                           self._folded(i))

    def runs(self) -> list[SimulationResult]:
        """Every run's record, equal to `[self.run(i) for i in range(N)]`; their outputs computed together, by the
        merged loop over the batch axis, when every run was logged to the end and the true φ is constant in time
        (what a sweep's chunk asks: its metrics, not N recomputations)."""
        N = len(self)
        if (self.n_logged < len(self.t)).any() or any(p.varies for p in self.plants) or N < 2:
            return [self.run(i) for i in range(N)]
        try:
            loop = ClosedLoop(stack(self.plants, "plant"), stack(self.controllers, "controller"),
                              self.plants[0].model.n, monitored=True)
        except NotBatchable:  # sampled-data runs may differ in more than `per_run`: their outputs run by run
            return [self.run(i) for i in range(N)]
        with np.errstate(all="ignore"):
            return batch_outputs(loop, self.controllers, stack(self.trajectories, "trajectory"), self.t, self.z,
                                 self.status, self.wall_time / N, [self._info(i) for i in range(N)], self.logged,
                                 [self._folded(i) for i in range(N)])



def _sequence(value: Any) -> tuple[Any, ...]:
    return tuple(value) if isinstance(value, list | tuple) else (value,)


def _leading(value: Any) -> int:
    return int(np.shape(value)[0]) if np.ndim(value) == 2 else 1


def _per_run(value: Any, N: int, width: int, field: str) -> Array:
    """A `(N, width)` array from one vector (the same for every run) or one row per run."""
    arr = as_array(value, field)
    if arr.ndim <= 1:
        return np.tile(as_vector(arr, width, field), (N, 1))
    if arr.shape != (N, width):
        raise ConfigError(field, f"expected {width} numbers or one row of {width} per run ({N}, {width}), "
                          f"got shape {arr.shape}")
    return arr.copy()


@dataclass(frozen=True, eq=False)
class _Runs:
    """The N runs' objects (tuples of N, shared objects repeated) and initial states `(N, ·)`, validated; `s0` the
    plants' initial states [q, q̇, and any extra plant state]."""

    plants: tuple[Plant, ...]
    controllers: tuple[Any, ...]
    trajectories: tuple[Any, ...]
    q0: Array
    dq0: Array
    s0: Array
    x0: Array


def _runs(plant: Any, controller: Any, trajectory: Any, q0: Any, dq0: Any, x0: Any,
          integrator: RK4 | Sampled) -> _Runs:
    seqs = _sequence(plant), _sequence(controller), _sequence(trajectory)
    sizes = {"plant": len(seqs[0]), "controller": len(seqs[1]), "trajectory": len(seqs[2]), "plant.q0": _leading(q0),
             "plant.dq0": _leading(dq0), "x0": _leading(x0)}
    N = max(sizes.values())
    for name, size in sizes.items():
        if size not in (1, N):
            raise ConfigError(name, f"has {size} runs where another argument has {N}")
    plants, controllers, trajectories = (seq * N if len(seq) == 1 else seq for seq in seqs)
    n = plants[0].model.n
    if controllers[0].model.n != n or trajectories[0].n != n:
        raise ConfigError("controller", f"the controller and trajectory must have the plant's {n} joints")
    q0s = _per_run(0.0 if q0 is None else q0, N, n, "plant.q0")
    dq0s = _per_run(0.0 if dq0 is None else dq0, N, n, "plant.dq0")
    runs_of: dict[int, list[int]] = {}
    for i, p in enumerate(plants):
        runs_of.setdefault(id(p), []).append(i)
    for idx in runs_of.values():
        plants[idx[0]].check_state(q0s[idx])
        check_plant_step(plants[idx[0]], integrator)
    s0 = np.stack([p.initial_state(q0s[i], dq0s[i]) for i, p in enumerate(plants)])
    if x0 is None:  # from what each law sees first, as in `simulate`: the sensor's tick-0 measurement when sampled
        def seen(i: int) -> tuple[Array, Array]:
            sensor = plants[i].sensor
            if isinstance(integrator, Sampled) and sensor is not None:
                return sensor.first_measurement(q0s[i], dq0s[i], integrator.control_period)
            return q0s[i], dq0s[i]

        x0s = np.stack([np.asarray(c.initial_state(*seen(i)), dtype=float) for i, c in enumerate(controllers)])
    else:
        x0s = _per_run(x0, N, int(np.shape(x0)[-1]), "x0")
    return _Runs(plants, controllers, trajectories, q0s, dq0s, s0, x0s)


def simulate_batch(plant: Plant | Sequence[Plant], controller: Any, trajectory: Any, *, t_final: float,
                   integrator: RK4 | SolveIVP | Sampled | None = None, q0: Any = None, dq0: Any = None, x0: Any = None,
                   log_every: int = 1, max_state: float = 1e6, progress: bool = False,
                   info: dict[str, Any] | None = None) -> BatchResult:
    """Simulate N closed loops from t = 0 to `t_final` (s) with fixed-step RK4, all in one vectorized loop.

    `plant`, `controller`, `trajectory`: one object for every run, or a list of N (one per run; what may differ between
    them is each class's `per_run`). `q0, dq0`: shape `(n,)` or `(N, n)`, default zero; `x0`: `(s,)` or `(N, s)`, default
    each run's `controller.initial_state(q0, dq0)`. N is the common length of the per-run arguments. Logging, the
    divergence guard and the statuses are those of :func:`~robotadapt.sim.simulate`, per run.

    Examples
    --------
    Slotine–Li (Table 6.3.1) on the two-link arm, 20 runs with the true masses drawn ±20 % around (0.8, 2.3) kg:

    >>> import numpy as np
    >>> from robotadapt.controllers import InertiaRelated
    >>> from robotadapt.analysis.metrics import metrics
    >>> from robotadapt.robots import TwoLinkArm
    >>> from robotadapt.trajectories import sinusoid
    >>> arm, rng = TwoLinkArm(), np.random.default_rng(0)
    >>> phis = np.array([0.8, 2.3]) * rng.uniform(0.8, 1.2, size=(20, 2))
    >>> res = simulate_batch([Plant(arm, phi) for phi in phis], InertiaRelated(arm, 2.5, 10, 20, [0, 0]),
    ...                      sinusoid(2), t_final=10, log_every=100)
    >>> bool(res.ok.all()), metrics(res.run(7))["final_phi_error"] < 1e-3
    (True, True)
    """
    integrator = RK4() if integrator is None else integrator
    if not isinstance(integrator, RK4 | Sampled):
        raise NotBatchable("simulation.method", "a batch steps every run with fixed steps ('rk4', or sampled-data "
                           f"ticks); simulate {type(integrator).__name__} runs one by one")
    t_final = as_scalar(t_final, "simulation.t_final", positive=True)
    if isinstance(log_every, bool) or not isinstance(log_every, int) or log_every < 1:
        raise ConfigError("simulation.log_every", f"must be a positive integer, got {log_every!r}")
    runs = _runs(plant, controller, trajectory, q0, dq0, x0, integrator)
    if isinstance(integrator, Sampled):
        return _sampled_batch(runs, integrator, t_final, log_every, max_state, progress, dict(info or {}))
    dt, (N, n) = integrator.dt, runs.q0.shape
    grid = Grid(dt, t_final, log_every)
    n_steps = grid.n
    log_bytes = 8.0 * (n_steps // log_every + 1) * N * (runs.s0.shape[1] + runs.x0.shape[1])
    if log_bytes > MAX_LOG_BYTES:
        raise ConfigError("simulation.log_every", f"{N} runs of {n_steps} steps would keep a {log_bytes / 1e9:.3g} GB "
                          "log; log every more steps")
    controllers = _prepared(runs.controllers, runs.trajectories, dt, t_final)
    loop = ClosedLoop(stack(runs.plants, "plant"), stack(controllers, "controller"), n, monitored=True)
    buffers = [c.delay_line(dt, runs.q0[i], runs.dq0[i]) for i, c in enumerate(controllers)]
    line = None if buffers[0] is None else Ring.start(np.stack(buffers, axis=1))  # slots (N_slots, N, n), one per run

    singles = [RK4Step(ClosedLoop(p, controllers[i], n, monitored=True), dt, max_state)
               for i, p in enumerate(runs.plants)]  # what words each run's status
    wall = time.perf_counter()
    rk4 = RK4Step(loop, dt, max_state)
    z0 = loop.start(runs.s0, runs.x0)
    feed = rk4.feed(stack(runs.trajectories, "trajectory"), runs=True)
    traceable = all(p.model.traceable for p in runs.plants) and all(c.model.traceable for c in controllers)
    asked = Run(rk4, (z0, line), feed, n_steps * len(controllers), traceable=traceable)

    def run(backend: str) -> Any:
        if backend == "c" and all(map(trajectories.traceable, runs.trajectories)):  # each run through the single-run program
            own = [RK4Step(single.loop, dt, max_state, tr) for single, tr in zip(singles, runs.trajectories, strict=True)]
            carries = [step.start(z0[i], buffers[i]) for i, step in enumerate(own)]
            return drive(own, carries, own[0].feed(runs.trajectories[0]), n_steps, log_every, backend=backend,
                         mapped=False)
        return drive(singles, [], feed, n_steps, log_every, backend=backend, stacked=(rk4, (z0, line)),
                     progress=progress)

    trace, backend = execute(integrator.backend, asked, run)
    z = trace.records.z
    return BatchResult(grid.times(len(z)), z, trace.n_logged, tuple(trace.status), runs.plants,
                       controllers, runs.trajectories, time.perf_counter() - wall, {**(info or {}), "backend": backend},
                       folded=trace.running, h=grid.h)


def _sampled_batch(runs: _Runs, opts: Sampled, t_final: float, log_every: int, max_state: float, progress: bool,
                   info: dict[str, Any]) -> BatchResult:
    """:func:`simulate_batch` of sampled-data runs (:func:`robotadapt.sim.sampled.integrate_batch`): the runs' ticks
    compiled into one program mapped over the runs, or stepped in lockstep by numpy; the runs must share one program's
    shape (they differ in arrays: gains, tables, true parameters), else NotBatchable."""
    from .sampled import integrate_batch
    from .simulation import host_sampling

    for plant in runs.plants:  # MuJoCo steps its plant on the host: numpy ("auto"), or the single run's refusal
        if plant.stepped_on_host:
            opts = host_sampling(plant, opts)
    Ts, (N, n) = opts.control_period, runs.q0.shape
    grid = Grid(Ts, t_final, log_every)
    n_ticks = grid.n
    log_bytes = 8.0 * (n_ticks // log_every + 1) * N * (runs.s0.shape[1] + runs.x0.shape[1] + 2 + 4 * n)
    if log_bytes > MAX_LOG_BYTES:
        raise ConfigError("simulation.log_every", f"{N} runs of {n_ticks} ticks would keep a {log_bytes / 1e9:.3g} "
                          "GB log; log every more ticks")
    controllers = _prepared(runs.controllers, runs.trajectories, Ts, t_final)
    loops = [ClosedLoop(p, controllers[i], n, monitored=True) for i, p in enumerate(runs.plants)]
    buffers = [c.delay_line(Ts, runs.q0[i], runs.dq0[i]) for i, c in enumerate(controllers)]
    lines = None if buffers[0] is None else [np.array(b, dtype=float) for b in buffers]
    first = runs.trajectories[0]
    traj = first if all(_same(tr, first) for tr in runs.trajectories[1:]) else list(runs.trajectories)
    z0 = np.stack([loop.start(runs.s0[i], runs.x0[i]) for i, loop in enumerate(loops)])
    traceable = all(p.model.traceable for p in runs.plants) and all(c.model.traceable for c in controllers)
    step = RK4Step(loops[0], Ts, max_state)  # the first run's loop: what the backends are asked about
    asked = Run(step, step.start(z0[0], None if lines is None else lines[0]), step.feed(runs.trajectories[0]),
                n_ticks * N, traceable=traceable)
    wall = time.perf_counter()
    try:
        (t, z, n_logged, status, folded, logged), backend = execute(
            opts.backend, asked, lambda b: integrate_batch(loops, traj, z0, opts, grid, max_state, progress, lines, b))
    except ConfigError as exc:
        if exc.field == "simulation":
            raise NotBatchable(exc.field, exc.reason) from None
        raise
    info = {**info, "sampling": opts.describe(), "backend": backend}
    return BatchResult(t, z, n_logged, tuple(status), runs.plants, controllers, runs.trajectories,
                       time.perf_counter() - wall, info, logged, folded, grid.h)


def _prepared(controllers: tuple[Any, ...], trajectories: tuple[Any, ...], dt: float, t_final: float) -> tuple[Any, ...]:
    """Each run's controller with its tables computed (the law's `prepare`), once per distinct (controller,
    trajectory) pair."""
    done: dict[tuple[int, int], Any] = {}
    for c, traj in zip(controllers, trajectories, strict=True):
        if (id(c), id(traj)) not in done:
            done[id(c), id(traj)] = c.prepare(traj, dt, t_final)
    return tuple(done[id(c), id(traj)] for c, traj in zip(controllers, trajectories, strict=True))
