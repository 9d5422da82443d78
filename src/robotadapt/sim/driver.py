"""The one driver (DESIGN "The engine"): every fixed-step run is a transition

    carry_{k+1}, record_k, verdict_k = transition(carry_k, inputs_k),     k = 0 … n,

a continuous RK4 step (:class:`robotadapt.sim.loop.RK4Step`) or a sampled-data tick (:class:`robotadapt.sim.sampled.Tick`),
and :func:`drive` runs it, once for every mode: it feeds the inputs a chunk at a time, keeps every `log_every`-th record,
stops each run where its verdict says (the divergence guard, a law's own guard) and builds each run's status. Step n
(t_final) is recorded, not stepped. Under it two loops run the same transition and the same bookkeeping
(:func:`_judge`): a Python loop (numpy: the readable reference, and plants stepped on the host such as MuJoCo's) and
`lax.scan` under `jax.jit` (JAX, float64) — or the very program that scan is, traced once and translated to C
(:mod:`robotadapt.native`; backend "c": no per-kernel dispatch, one native call per chunk). The checkpointed form for
gradients is :mod:`robotadapt.sim.gradient`.

Runs: one transition stepping every run on leading run axes (`stacked`: a batch merged by
:func:`robotadapt.sim.batch.stack`), or N transitions of one shape (`mapped`): numpy steps them one by one, JAX maps one
program over them (`jax.vmap`; their float arrays, gains and true parameters, may differ). A stopped run's log repeats
its last record; the others go on. Compiled programs are kept by the transition's structure as a pytree
(:func:`robotadapt.pytree.key`: its float arrays are the program's arguments) in the package's one bounded cache
(:data:`robotadapt.tracing.PROGRAMS`), and on disk.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple, Protocol

import numpy as np

from .. import pytree
from ..arrays import array_namespace
from ..tracing import PROGRAMS, float64, jax_module
from ..validation import ConfigError
from . import running
from .compiled import stable_key
from .status import Status

Array = Any
Feed = Callable[[int, int], Any]  # inputs of steps first … first + count − 1: a NamedTuple whose first field is `k`
GUARD = 3  # the stop code of a law's own guard (Law.guard); 1 and 2 are the divergence guard's (loop.REASONS)
CHUNK = 64  # steps fed to the Python loop at a time: one vectorized reference call for them, a small peak memory
CHUNK_STEPS = 16384  # most steps per compiled call (the last call is padded)
INPUT_BYTES = 64e6  # most bytes of inputs fed to one compiled call (all runs together)
FOLD_STEPS = 4  # the Python loop folds its steps' samples for the metrics this many steps at a time (a run's sums are
# then grouped the same whatever the batch it runs in: a sweep's row does not depend on its chunk)


class Verdict(NamedTuple):
    """How step k ended, per run (leading run axes, or none)."""

    held: Array | None  # the step's record is valid; False: the run stops at step k, unrecorded (None: always valid)
    why: Array  # 0: it goes on; else the stop code the transition words (Transition.status)
    bad: Any  # what the transition words a guard's stop from (a pytree, run axes leading), or None


class Transition(Protocol):
    """One step of a fixed-step run (the module docstring), pure, in the array API of its inputs."""

    @property
    def loop(self) -> Any:
        """The closed loop it steps (its law and plant name a program that cannot be traced)."""

    def __call__(self, carry: Any, inputs: Any) -> tuple[Any, Any, Verdict]:
        """(carry_{k+1}, record_k, verdict_k)."""

    def compiled(self, native: bool = False) -> Callable[[Any, Any], tuple[Any, Any, Verdict]]:
        """The transition as a compiled program calls it (traced; e.g. the dynamics as a function of their own), for
        XLA or, `native`, for the C translator."""

    def blanks(self, carry: Any) -> tuple[Any, Any]:
        """Zeros shaped like a step's record and like its verdict's `bad` (None without a guard), from the carry."""

    def status(self, k: int, why: int, bad: Any) -> Status:
        """The status of a run stopped at step k for the code `why` (`bad`: the verdict's, this run's)."""


@dataclass(frozen=True)
class Trace:
    """What :func:`drive` returns: the logged records `(T, N, ...)` (a stopped run's rows after its stop repeat its last
    one), each run's number of logged records `(N,)` and its status."""

    records: Any
    n_logged: Array
    status: list[Status]
    running: running.Running  # each run's metrics folded at every step (robotadapt.sim.running), run axis first


def map_tree(fn: Callable[..., Any], tree: Any, *rest: Any) -> Any:
    """`fn` over the arrays of nested tuples (the carries, records and inputs of the transitions; None stays None)."""
    if tree is None:
        return None
    if isinstance(tree, tuple):
        parts = [map_tree(fn, *leaves) for leaves in zip(tree, *rest, strict=True)]
        return type(tree)(*parts) if hasattr(tree, "_fields") else tuple(parts)
    return fn(tree, *rest)


def _where(now: Array, new: Array, old: Array) -> Array:
    """`new` where `now` (per run) else `old`, `now` broadcast over each leaf's trailing axes."""
    xp = array_namespace(now, new, old)
    now = xp.asarray(now)
    return xp.where(now.reshape(now.shape + (1,) * (new.ndim - now.ndim)), new, old)


def _judge(alive: Array, k: Any, n: int, verdict: Verdict) -> tuple[Array, Array, Array]:
    """(the live runs that stop at step k, their stop code, whether step k's record is valid): a run stops at a failed
    `held` (code GUARD, the step unrecorded) or, before step n, at a non-zero `why` (the step recorded). The one
    bookkeeping of both loops."""
    exists, active = k <= n, k < n
    if verdict.held is None:
        return alive & active & (verdict.why != 0), verdict.why, alive & exists
    at_sample = alive & exists & ~verdict.held
    after = alive & active & verdict.held & (verdict.why != 0)
    code = array_namespace(verdict.why).where(at_sample, GUARD, verdict.why)
    return at_sample | after, code, alive & exists & verdict.held


def take_run(inputs: Any, i: int, mapped: Any) -> Any:
    """Run i's inputs: its row (axis 1) of the leaves `mapped` marks as per run."""
    if isinstance(mapped, tuple):
        parts = [take_run(a, i, m) for a, m in zip(inputs, mapped, strict=True)]
        return type(inputs)(*parts) if hasattr(inputs, "_fields") else tuple(parts)
    return map_tree(lambda a: a[:, i], inputs) if mapped else inputs


def _fold(acc: running.Running, steps: list[tuple[Any, int, Array]]) -> running.Running:
    """`acc` with the buffered (sample, k, valid) of some steps folded in one vectorized pass."""
    if not steps:
        return acc
    return running.fold_rows(acc, np.stack([running.row(sample, ok) for sample, _, ok in steps]),
                             np.array([k for _, k, _ in steps]))


def _python(lanes: Sequence[tuple[Any, Any]], feed: Feed, mapped: Any, n: int, log_every: int,
            progress: bool) -> tuple[Any, Array, Array, Array, Any, running.Running]:
    """The Python loop over steps: (the logged records `(T, ...)`, whether each is valid, the stop step, the stop code,
    the verdicts' `bad`, the running metrics). `lanes`: one (transition, carry), a single run or the runs on its leading
    axes, or one per run (mapped), stepped in lockstep so that each chunk of inputs is fed once."""
    from tqdm import tqdm

    one = len(lanes) == 1
    shape = _runs_shape(lanes[0][1]) if one else (len(lanes),)
    alive, k_stop, why = np.ones(shape, bool), np.zeros(shape, int), np.zeros(shape, int)
    bad: list[Any] = [None] * len(lanes)
    logs: list[Any] = [None] * len(lanes)
    valid, T = np.zeros((n // log_every + 1,) + shape, bool), 0
    carries = [carry for _, carry in lanes]
    accs = [running.start(np, shape if one else (), transition.loop.n, transition.loop.controller.error_size)
            for transition, _ in lanes]
    quiet = not (progress and sys.stderr.isatty())  # progress bars on a terminal only
    with tqdm(total=n + 1, delay=1.0, disable=quiet, unit="step", leave=False, file=sys.stderr) as bar, \
            np.errstate(all="ignore"):
        for first in range(0, n + 1, CHUNK):
            count = min(CHUNK, n + 1 - first)
            xs = feed(first, count)
            rows = [xs] if one else [take_run(xs, i, mapped) for i in range(len(lanes))]
            pending: list[list[Any]] = [[] for _ in lanes]
            for j in range(count):
                k = first + j
                for i, (transition, _) in enumerate(lanes):
                    lane = ... if one else i
                    if not alive[lane].any():
                        continue
                    new, record, verdict = transition(carries[i], map_tree(lambda a: a[j], rows[i]))  # noqa: B023
                    now, code, ok = _judge(alive[lane], k, n, verdict)
                    pending[i].append((record.sample, k, ok))  # folded with other steps of the chunk, at once
                    if len(pending[i]) >= FOLD_STEPS:
                        accs[i], pending[i] = _fold(accs[i], pending[i]), []
                    record = record._replace(sample=None)
                    if k % log_every == 0:  # into a log allocated once, at the first record
                        if logs[i] is None:
                            logs[i] = map_tree(lambda a: np.empty((len(valid),) + np.shape(a)), record)
                        map_tree(lambda log, a: log.__setitem__(T, a), logs[i], record)  # noqa: B023
                        valid[T, lane] = ok
                    if np.any(now):
                        k_stop[lane], why[lane] = np.where(now, k, k_stop[lane]), np.where(now, code, why[lane])
                        bad[i] = verdict.bad if bad[i] is None else map_tree(
                            lambda a, b: _where(now, a, b), verdict.bad, bad[i])  # noqa: B023
                        alive[lane] = alive[lane] & ~now
                    carries[i] = new
                    del new, record, verdict  # the previous step's arrays are not held through the next one
                T += k % log_every == 0
                if not alive.any():
                    break
            accs = [_fold(acc, steps) for acc, steps in zip(accs, pending, strict=True)]
            bar.update(count)
            if not alive.any():
                break
    if one:
        return map_tree(lambda a: a[:T], logs[0]), valid[:T], k_stop, why, bad[0], accs[0]
    records = map_tree(lambda *a: np.stack([log[:T] for log in a], axis=1), *logs)
    return records, valid[:T], k_stop, why, bad, map_tree(lambda *a: np.stack(a), *accs)




def _program(transition: Any, log_every: int, mapped: Any, native: bool = False) -> Callable[..., Any]:
    """The jitted scan over blocks of `log_every` steps for transitions shaped like this one (`mapped`: vmapped over
    runs, None: not). `run(arrays, state, xs, n)` scans the blocks of `xs` (`(blocks, log_every, ...)`), keeps each
    block's first record and its validity, and computes no step after n (the padding of the last call). `native`: the
    program to translate to C, where a padded step is skipped by a branch (XLA computes it and judges it as nothing:
    cheaper there than a loop of one)."""
    structure = pytree.key(transition)
    return PROGRAMS.get(("scan", structure, log_every, mapped, native), lambda: _scan_program(structure, mapped, native))


def _scan_program(structure: Any, mapped: Any, native: bool) -> Callable[..., Any]:
    """The jitted scan of :func:`_program` for transitions of `structure`."""
    jax = jax_module()
    jnp, lax = jax.numpy, jax.lax

    def run(arrays: list[Array], state: Any, xs: Any, n: Array) -> Any:
        def block(state: Any, xs: Any) -> tuple[Any, Any]:
            """The block's steps that exist (none of the padding after step n): the first one's record, and every
            step's row for the running metrics (:func:`robotadapt.sim.running.row`; zeros for the padding). `native`:
            the rows folded in the loop (the state's last part, :func:`robotadapt.sim.running.fold_step`), none
            returned."""
            traced = pytree.unflatten(structure, arrays)  # its cached constants computed from the traced leaves
            step = traced.compiled(native)

            def one(state: Any, inputs: Any) -> tuple[Any, Any]:
                (carry, alive, k_stop, why, bad), acc = state[:5], state[5:]
                new, record, verdict = step(carry, inputs)
                now, code, ok = _judge(alive, inputs.k, n, verdict)
                row = running.row(record.sample, ok)
                state = (new, alive & ~now, jnp.where(now, inputs.k, k_stop), jnp.where(now, code, why),
                         None if bad is None else map_tree(lambda a, b: _where(now, a, b), verdict.bad, bad),
                         *(running.fold_step(a, row, inputs.k) for a in acc))
                return state, (record._replace(sample=None), ok, row)

            count = jnp.clip(n + 1 - xs.k[0], 0, xs.k.shape[0])  # the padding after step n: not computed
            blank = (traced.blanks(state[0])[0], jnp.zeros_like(state[1]))
            if native:
                def folded(i: Array, carried: Any) -> Any:  # one copy of the step; its record kept at i = 0
                    state, (record, ok, _) = one(carried[0], map_tree(lambda a: a[i], xs))
                    return state, map_tree(lambda a, b: jnp.where(i == 0, a, b), (record, ok), carried[1])

                state, kept = lax.fori_loop(0, count, folded, (state, blank))
                return state, kept
            if xs.k.shape[0] == 1:  # log_every = 1: the block is its step (padding: judged as nothing)
                state, (record, ok, row) = one(state, map_tree(lambda a: a[0], xs))
                return state, (record, ok, row[None])

            def body(i: Array, carried: Any) -> Any:  # one copy of the step in the program: its record kept at i = 0
                state, (record, ok, row) = one(carried[0], map_tree(lambda a: a[i], xs))
                kept = map_tree(lambda a, b: jnp.where(i == 0, a, b), (record, ok), carried[1])
                return state, kept, lax.dynamic_update_index_in_dim(carried[2], row, i, 0)

            width = traced.loop.controller.error_size + 2 * traced.loop.n + 1  # a running.row
            rows = jnp.zeros((xs.k.shape[0],) + state[1].shape + (width,))
            state, kept, rows = lax.fori_loop(0, count, body, (state, blank, rows))
            return state, (*kept, rows)

        return lax.scan(block, state, xs)

    return jax.jit(run if mapped is None else jax.vmap(run, in_axes=(0, 0, mapped, None)))


def _axes(mapped: Any) -> Any:
    """`jax.vmap`'s in_axes for the inputs of a call: shared leaves `(blocks, log_every, ...)`, per-run ones
    `(N, blocks, log_every, ...)`."""
    if isinstance(mapped, tuple):
        parts = [_axes(m) for m in mapped]
        return type(mapped)(*parts) if hasattr(mapped, "_fields") else tuple(parts)
    return 0 if mapped else None


def _native(make: Callable[[], Any], static: Any, arrays: list[Array], state: Any, xs: Any, n: int) -> Any:
    """`make()(arrays, state, xs, n)` run as C: the program traced on these shapes, translated and built once
    (:mod:`robotadapt.native`); found again, without JAX, in this process or on disk where `static` (the program's
    description: the transition's structure, log_every, mapping) is stable across processes
    (:func:`~robotadapt.sim.compiled.stable_key`)."""
    from ..native import build

    leaves = [*arrays, *_flatten(state), *_flatten(xs), n]
    zeros = [np.asarray(a) == 0 for a in arrays]  # structural zeros of gains and tables: folded by the translator
    key = (static, tuple((np.shape(a), np.asarray(a).dtype.str) for a in leaves),
           tuple(np.packbits(z).tobytes() for z in zeros))

    def found() -> tuple[Any, Any]:
        stable = stable_key(key)
        program = build.remembered(stable) if stable is not None else None
        if program is None:
            program = build.compiled(make(), arrays, state, xs, n, name="chunk", zeros=zeros, key=key)
            if stable is not None:
                build.remember(stable, *program)
        return program

    native, outputs = PROGRAMS.get(("native", key), found)
    values = native(*leaves)
    return map_tree(lambda i: values[i], outputs)


def _scan(runs: Sequence[Any], transition: Any, carry: Any, feed: Feed, n: int, log_every: int,
          mapped: Any, native: bool = False) -> tuple[Any, Array, Array, Array, Any, running.Running]:
    """The compiled loop: :func:`_python`'s results, from `lax.scan` over blocks of steps (`mapped`: the runs'
    transitions vmapped; None: one `transition`, on leading run axes or none), run by XLA or, `native`, as C. Tracing
    that meets code needing concrete values (numpy-only code) is a ConfigError naming `simulation.backend` and the
    law."""
    try:
        run = _compiled if native else float64(_compiled)  # C: JAX only where a program is traced
        return run(runs, transition, carry, feed, n, log_every, mapped, native)
    except ConfigError:
        raise
    except Exception as exc:  # tracing met code that needs concrete values
        loop = runs[0].loop
        name = f"{type(loop.controller).__name__} on {type(loop.plant.model).__name__}"
        raise ConfigError("simulation.backend", f"{name} cannot be compiled with JAX ({type(exc).__name__}: "
                          f"{(str(exc).splitlines() or [''])[0][:120]}); use backend = 'numpy'") from None


@dataclass
class _Lane:
    """One compiled program's share of a loop: its transition, arguments and state, and what its calls returned."""

    one: Any  # the transition the program is traced from
    arrays: list[Array]  # its leaves: the program's arguments
    static: Any  # what the C program is (None: XLA's)
    axes: Any  # vmap's in_axes (None: not mapped)
    state: tuple[Any, ...]
    folded: running.Running
    records: list[Any]
    valid: list[Array]

    def outputs(self) -> tuple[Any, Array, Array, Array, Any, running.Running]:
        out = map_tree(lambda *a: np.concatenate(a), *self.records)
        bad = None if self.state[4] is None else map_tree(np.asarray, self.state[4])
        return out, np.concatenate(self.valid), np.asarray(self.state[2]), np.asarray(self.state[3]), bad, self.folded


def _compiled(runs: Sequence[Any], transition: Any, carry: Any, feed: Feed, n: int, log_every: int,
              mapped: Any, native: bool = False) -> tuple[Any, Array, Array, Array, Any, running.Running]:
    """:func:`_scan`'s loop. Mapped runs as C (`each`): each run through the single run's program (the one `robotadapt
    run` builds, found on disk by every sweep worker), the runs in lockstep over the calls (the inputs fed once a call).
    A run's steps stay in the cache: the runs vmapped into one program would loop over the runs inside every operation
    (Example 6.3.1: 5.7 ms a run against 3.5 ms)."""
    jnp = np if native else jax_module().numpy  # the C program takes host arrays as they are
    each = native and mapped is not None
    flat = [pytree.flatten(r) for r in runs] if mapped is not None else []  # each run's (leaves, structure), once
    if flat:
        key = flat[0][1]
        if any(other != key for _, other in flat[1:]):
            raise ConfigError("simulation", "the runs differ in more than their arrays (a law's kind, a flag, a "
                              "scalar setting); one batch of sampled-data runs varies gains, tables and true "
                              "parameters only")
    shape: tuple[int, ...] = (len(runs),) if mapped is not None else _runs_shape(carry)
    one = transition if mapped is None else runs[0]
    blocks = n // log_every + 1  # a block per logged step; the last one runs on to n and is padded
    folds = 0 if native else 8 * int(np.prod(shape)) * (one.loop.controller.error_size + 2 * one.loop.n + 1)  # C: none
    step_bytes = sum(np.asarray(a).nbytes for a in _flatten(feed(0, 1))) + folds
    most = max(1, int(min(CHUNK_STEPS, INPUT_BYTES // max(step_bytes, 1))) // log_every)
    # XLA: a power of two, few shapes and compilations; C: one shape per program whatever the run's length (gcc builds
    # a large program once, not per t_final)
    per_call = most if native else min(most, 1 << max(0, blocks - 1).bit_length())

    def lane(one: Any, arrays: list[Array], key: Any, carry: Any, shape: tuple[int, ...], axes: Any) -> _Lane:
        one_carry = carry if axes is None else map_tree(lambda a: a[0], carry)
        lead = shape if not _runs_shape(one_carry) else ()  # a mapped run's carry has no run axes; a stacked one has
        bad = map_tree(lambda a: jnp.zeros(lead + np.shape(a)), one.blanks(one_carry)[1])
        folded = running.start(np, shape, one.loop.n, one.loop.controller.error_size)
        state = (map_tree(jnp.asarray, carry), jnp.ones(shape, bool), jnp.zeros(shape, int), jnp.zeros(shape, int),
                 bad, *((folded,) if native else ()))  # C folds the running metrics in its loop
        return _Lane(one, arrays, (key, log_every, axes) if native else None, axes, state, folded, [], [])

    if each:
        lanes = [lane(r, leaves, key, map_tree(lambda a: a[i], carry), (), None)  # noqa: B023
                 for i, (r, (leaves, _)) in enumerate(zip(runs, flat, strict=True))]
    elif mapped is not None:
        arrays = [jnp.asarray(np.stack(parts)) for parts in zip(*(leaves for leaves, _ in flat), strict=True)]
        lanes = [lane(one, arrays, key, carry, shape, _axes(mapped))]
    else:
        leaves, key = pytree.flatten(transition)
        lanes = [lane(one, [jnp.asarray(a) for a in leaves], key, carry, shape, None)]
    live = list(range(len(lanes)))
    for first in range(0, blocks, per_call):
        size = per_call * log_every
        real = min(size, n + 1 - first * log_every)
        fed = map_tree(lambda a: np.concatenate([a, np.zeros((size - real,) + a.shape[1:], a.dtype)]),  # noqa: B023
                       feed(first * log_every, real))  # the padding: zeros, with its step indices after n (not computed)
        fed = fed._replace(k=np.arange(first * log_every, first * log_every + size))
        for i in live:
            ln = lanes[i]
            xs = _blocked(take_run(fed, i, mapped) if each else fed, None if each else mapped, per_call, log_every)
            move = partial(_rows, keep=min(per_call, blocks - first), runs_first=ln.axes is not None)
            if native:
                ln.state, (record, ok) = _native(lambda: _program(ln.one, log_every, ln.axes, True),  # noqa: B023
                                                 ln.static, ln.arrays, ln.state, xs, n)
                ln.folded = ln.state[5]
            else:
                ln.state, (record, ok, rows) = _program(ln.one, log_every, ln.axes)(ln.arrays, ln.state, xs, n)
                steps = np.asarray(rows) if ln.axes is None else np.moveaxis(np.asarray(rows), 0, 2)  # (blocks, L, runs, w)
                ln.folded = running.fold_rows(ln.folded, steps.reshape((-1,) + steps.shape[2:])[:real],  # no padding
                                              np.arange(first * log_every, first * log_every + real))
            ln.records.append(map_tree(move, record))
            ln.valid.append(move(ok))
        live = [i for i in live if bool(np.asarray(lanes[i].state[1]).any())]
        if not live:
            break
    if not each:
        return lanes[0].outputs()
    records, valid, k_stop, why, bad, acc = zip(*(ln.outputs() for ln in lanes), strict=True)
    T = max(len(v) for v in valid)  # a run that stopped left its last calls out: its rows end early

    def padded(*parts: Array) -> Array:
        return np.stack([np.concatenate([a, np.repeat(a[-1:], T - len(a), axis=0)]) for a in parts], axis=1)

    valid = tuple(np.concatenate([v, np.zeros(T - len(v), bool)]) for v in valid)
    return (map_tree(padded, *records), np.stack(valid, axis=1), np.stack(k_stop), np.stack(why),
            None if bad[0] is None else map_tree(lambda *a: np.stack(a), *bad), map_tree(lambda *a: np.stack(a), *acc))


def _rows(a: Array, keep: int, runs_first: bool) -> Array:
    """A call's output `(blocks, ...)` (`(N, blocks, ...)` from a mapped program) as `(blocks, N, ...)`, the first
    `keep` blocks."""
    return (np.moveaxis(np.asarray(a), 0, 1) if runs_first else np.asarray(a))[:keep]


def _blocked(xs: Any, mapped: Any, per_call: int, log_every: int) -> Any:
    """The inputs of a call `(size, ...)` laid out as `(blocks, log_every, ...)`; per-run leaves (axis 1) with the runs
    first."""
    if isinstance(mapped, tuple):
        parts = [_blocked(a, m, per_call, log_every) for a, m in zip(xs, mapped, strict=True)]
        return type(xs)(*parts) if hasattr(xs, "_fields") else tuple(parts)

    def layout(a: Array) -> Array:
        if mapped:
            a = np.moveaxis(a, 1, 0)
            return a.reshape((a.shape[0], per_call, log_every) + a.shape[2:])
        return a.reshape((per_call, log_every) + a.shape[1:])

    return map_tree(layout, xs)


def _flatten(tree: Any) -> list[Array]:
    out: list[Array] = []
    map_tree(out.append, tree)
    return out


def _runs_shape(carry: Any) -> tuple[int, ...]:
    """The run axes of a stacked carry: those of its first leaf without its last axis (the state z `(..., d)`)."""
    return tuple(np.shape(_flatten(carry)[0])[:-1])


def drive(runs: Sequence[Any], carries: Sequence[Any], feed: Feed, n: int, log_every: int, *, backend: str,
          mapped: Any = None, stacked: tuple[Any, Any] | None = None, progress: bool = False) -> Trace:
    """Steps 0 … n of every run, logged every `log_every` steps (module docstring).

    `runs`: each run's transition (what words its status); `carries`: each run's carry before step 0. `stacked`: (one
    transition, its carry) stepping all the runs at once on a leading run axis; else the runs are mapped. `feed(first,
    count)`: the inputs of those steps for every run, leaves marked True in `mapped` (a prefix of the inputs' tuples)
    holding the runs on axis 1, the others shared. `backend`: "numpy" (the Python loop), "jax" (`lax.scan`) or "c"
    (that program as C)."""
    N = len(runs)
    listed = False
    if stacked is not None or N == 1:
        transition, carry = stacked if stacked is not None else (runs[0], carries[0])
        one_feed = feed if stacked is not None else (lambda first, count: take_run(feed(first, count), 0, mapped))
        if backend in ("jax", "c"):
            out = _scan(runs, transition, carry, one_feed, n, log_every, None, backend == "c")
        else:
            out = _python([(transition, carry)], one_feed, None, n, log_every, progress)
        records, valid, k_stop, why, bad, acc = out
        if stacked is None:  # a single run: a run axis of one
            records, valid = map_tree(lambda a: a[:, None], records), valid[:, None]
            k_stop, why, bad = k_stop[None], why[None], map_tree(lambda a: a[None], bad)
            acc = map_tree(lambda a: a[None], acc)
    elif backend in ("jax", "c"):
        records, valid, k_stop, why, bad, acc = _scan(runs, None, map_tree(lambda *a: np.stack(a), *carries), feed, n,
                                                      log_every, mapped, backend == "c")
    else:
        records, valid, k_stop, why, bad, acc = _python(list(zip(runs, carries, strict=True)), feed, mapped, n,
                                                        log_every, progress)
        listed = True
    return _trace(runs, records, valid, k_stop, why, bad, listed, acc)


def _trace(runs: Sequence[Any], records: Any, valid: Array, k_stop: Array, why: Array, bad: Any,
           listed: bool, acc: running.Running) -> Trace:
    """The records thinned to each run's valid rows (the rows after a stop repeat the last valid one) and the statuses,
    built here once."""
    n_logged = valid.sum(axis=0)
    T = int(n_logged.max()) if n_logged.size else 0

    def fill(a: Array) -> Array:
        a = a[:T] if a.flags.writeable else np.array(a[:T])  # the Python loop's own log: filled in place
        if not T:
            return a
        for i, k in enumerate(n_logged):
            a[k:, i] = a[max(k - 1, 0), i]
        return a

    status = []
    for i, run in enumerate(runs):
        if why[i] == 0:
            status.append(Status.ok())
            continue
        one = (bad[i] if listed else map_tree(lambda a: a[i], bad)) if bad is not None else None  # noqa: B023
        status.append(run.status(int(k_stop[i]), int(why[i]), one))
    return Trace(map_tree(fill, records), n_logged, status, acc)
