"""Sweeps: a scenario run over a grid of values × random draws, in chunks, on local processes or a Dask cluster, with
results appended to a table as they arrive so that an interrupted sweep resumes where it stopped (DESIGN "Scale").

Every sweep key is a dotted scenario field (`controller.Kv`, `plant.phi`, `simulation.dt`, ...), as for `--set`.
Grid axes multiply; each grid point gets `n` random draws, uniform between the bounds (numbers, or lists drawn entry by
entry). Run `i`'s seed is derived from its sweep point (the grid values, the draw index and the sweep's base seed) by a
hash, so its random values do not depend on the order, the chunking or the machine that runs it.

A chunk of runs is simulated together by :func:`robotadapt.sim.batch.simulate_batch` when the varied fields allow it (true
parameters, initial states and estimates, Slotine–Li gains, sinusoid parameters), else scenario by scenario. Metrics
come from states logged at most `LOG_SAMPLES` + 1 times per run (the last one at t_final where the step count allows).
The output folder holds `sweep.json` (what was asked: rerunning with other arguments into the same folder is an error),
`runs.jsonl` (one JSON object per run: `run`, `seed`, the swept values, the metrics of
:meth:`~robotadapt.sim.result.SimulationResult.metrics` less the wall time; sorted by run when the sweep completes) and
`sweep.png` (a metric against every swept key; .pdf or .svg with `--format`).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..analysis.metrics import metrics
from ..cores import usable_cores
from ..files import atomic_write, writable_dir
from ..grid import Grid
from ..sim.batch import NotBatchable, simulate_batch
from ..sim.simulation import RK4, Sampled, simulate
from ..validation import ConfigError, as_array
from .scenarios import Scenario
from .scenarios.build import Setup, setup
from .scenarios.loader import assignment, override, parse_value

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

LOG_SAMPLES = 1000  # states logged per run for the metrics (plus the initial one)
MAX_CHUNK = 250  # runs per chunk: bounds a chunk's records in memory (276 MB a process for 10⁴ runs of Example 6.3.1)
MIN_CHUNK_SECONDS = 0.1  # least work per chunk, so that scheduling costs stay small against it
STEP_SECONDS = 2.5e-4  # measured cost of one RK4 step of one chunk, the per-chunk floor (two-link arm, this machine)
TABLE, MANIFEST, FIGURE = "runs.jsonl", "sweep.json", "sweep"  # the figure: sweep.png, .pdf or .svg (--format)


class Point(NamedTuple):
    """One run of a sweep: its index, its seed and the values of the swept keys."""

    run: int
    seed: int
    inputs: dict[str, Any]


def parse_grid(text: str) -> tuple[str, list[Any]]:
    """`section.key=v1,v2,...`: the values are TOML (`5,10,20`, `[1,2],[3,4]`, `'rk4','RK45'`)."""
    key, sep, values = text.partition("=")
    try:
        parsed = tomllib.loads(f"v = [{values}]")["v"] if sep and values.strip() else None
    except tomllib.TOMLDecodeError:
        parsed = None
    if not parsed or not _dotted(key):
        raise ConfigError("--grid", f"expected section.key=v1,v2,... (e.g. controller.Kv=5,10,20), got {text!r}")
    return key.strip(), parsed


def parse_random(text: str) -> tuple[str, Any, Any]:
    """`section.key=lo:hi`, the bounds numbers or equally long lists (drawn entry by entry)."""
    key, sep, bounds = text.partition("=")
    lo_text, colon, hi_text = bounds.partition(":")
    form = f"expected section.key=lo:hi (e.g. controller.Kv=5:20 or plant.phi=[0.6,2]:[1,2.6]), got {text!r}"
    if not (sep and colon and _dotted(key)):
        raise ConfigError("--random", form)
    try:
        lo, hi = as_array(parse_value(lo_text.strip()), "--random"), as_array(parse_value(hi_text.strip()), "--random")
    except ConfigError:
        raise ConfigError("--random", form) from None
    if lo.shape != hi.shape or lo.ndim > 1 or not np.all(lo <= hi):
        raise ConfigError("--random", f"{key.strip()}: the bounds must be numbers or lists of one length with "
                          f"lo ≤ hi, got {lo_text.strip()} and {hi_text.strip()}")
    return key.strip(), lo.tolist(), hi.tolist()


def _dotted(key: str) -> bool:
    parts = key.strip().split(".")
    return len(parts) >= 2 and all(part.strip() for part in parts)


def seed_of(grid_point: dict[str, Any], draw: int, base: int) -> int:
    """The seed of a sweep point: a 64-bit hash of its grid values, its draw index and the base seed."""
    text = json.dumps([base, sorted(grid_point.items()), draw], separators=(",", ":"))
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little")


@dataclass(frozen=True, eq=False)
class Sweep:
    """A scenario (its resolved TOML data) and the swept keys: grid axes (key, values) and random ones (key, lo, hi),
    `n` random draws per grid point, `seed` the base of every run's seed."""

    name: str
    data: dict[str, Any]
    grid: tuple[tuple[str, tuple[Any, ...]], ...] = ()
    random: tuple[tuple[str, Any, Any], ...] = ()
    n: int = 1
    seed: int = 0

    @property
    def keys(self) -> list[str]:
        return [key for key, _ in self.grid] + [key for key, *_ in self.random]

    def __len__(self) -> int:
        return math.prod(len(values) for _, values in self.grid) * self.n

    def points(self) -> Iterator[Point]:
        """Every run, in order: grid points in the order of their axes, then the draws of each."""
        keys = [key for key, _ in self.grid]
        for g, combo in enumerate(itertools.product(*(values for _, values in self.grid))):
            grid_point = dict(zip(keys, combo, strict=True))
            for draw in range(self.n):
                seed = seed_of(grid_point, draw, self.seed)
                rng = np.random.default_rng(seed)
                drawn = {key: np.asarray(rng.uniform(lo, hi)).tolist() for key, lo, hi in self.random}
                yield Point(g * self.n + draw, seed, {**grid_point, **drawn})

    def manifest(self) -> dict[str, Any]:
        """What identifies the sweep (written to sweep.json; a resumed sweep must match it)."""
        return {"scenario": self.name, "data": self.data, "grid": {k: list(v) for k, v in self.grid},
                "random": {k: [lo, hi] for k, lo, hi in self.random}, "n": self.n, "seed": self.seed,
                "runs": len(self), "log_samples": LOG_SAMPLES}


def make_sweep(scenario: Scenario, grid: Sequence[str] = (), random: Sequence[str] = (), n: int = 1,
               seed: int = 0) -> Sweep:
    """Parse and check the `--grid` / `--random` arguments against a loaded scenario: every grid value and both ends
    of every random range must build (errors name the argument and the field)."""
    axes = [parse_grid(text) for text in grid]
    ranges = [parse_random(text) for text in random]
    keys = [key for key, _ in axes] + [key for key, *_ in ranges]
    if not keys:
        raise ConfigError("--grid", "give at least one --grid or --random key to sweep")
    for key in keys:
        if keys.count(key) > 1:
            raise ConfigError("--grid", f"{key} is swept twice")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError("--n", f"must be a positive whole number, got {n!r}")
    if n > 1 and not ranges:
        raise ConfigError("--n", "draws per grid point need a --random key to draw")
    trials = [("--grid", key, value) for key, values in axes for value in values]
    trials += [("--random", key, bound) for key, lo, hi in ranges for bound in (lo, hi)]
    for option, key, value in trials:
        try:
            scenario.variant(assignment(key, value))
        except ConfigError as exc:
            raise ConfigError(option, f"{key}={value!r} does not build: {exc}") from None
    data = {k: v for k, v in scenario.data.items() if k != "study"}
    return Sweep(scenario.name, data, tuple((k, tuple(v)) for k, v in axes), tuple(ranges), n, seed)


def log_every(s: Setup) -> int:
    """Steps (control ticks, sampled-data) between logged states: at least the scenario's own, at most `LOG_SAMPLES`
    samples, and a divisor of the step count where one is close (so t_final is logged)."""
    if not isinstance(s.integrator, Sampled | RK4):
        return s.log_every
    steps = Grid.of(s.integrator, s.t_final).n
    least = max(s.log_every, math.ceil(steps / LOG_SAMPLES))
    return next((k for k in range(least, 2 * least + 1) if steps % k == 0), least)


def _build(data: dict[str, Any], point: Point) -> Setup:
    trial = copy.deepcopy(data)
    for key, value in point.inputs.items():
        override(trial, assignment(key, value))
    return setup(trial)


def _metrics(setups: list[Setup]) -> tuple[list[dict[str, Any] | ConfigError], str]:
    """The metrics of each run, vectorized if the setups allow it (their outputs computed together,
    :meth:`~robotadapt.sim.batch.BatchResult.runs`); and how they ran."""
    first = setups[0]
    try:
        if any((s.t_final, s.integrator, s.max_state) != (first.t_final, first.integrator, first.max_state)
               for s in setups):
            raise NotBatchable("simulation", "t_final, dt, method or max_state differ between runs")
        batch = simulate_batch([s.plant for s in setups], [s.controller for s in setups],
                               [s.trajectory for s in setups], t_final=first.t_final, integrator=first.integrator,
                               q0=np.stack([s.q0 for s in setups]), dq0=np.stack([s.dq0 for s in setups]),
                               log_every=log_every(first), max_state=first.max_state)
        return [metrics(res) for res in batch.runs()], f"batched (simulate_batch, backend {batch.info['backend']})"
    except ConfigError as exc:
        how = f"one scenario per run ({exc})"
    out: list[dict[str, Any] | ConfigError] = []
    for s in setups:
        try:
            out.append(metrics(simulate(s.plant, s.controller, s.trajectory, t_final=s.t_final, integrator=s.integrator,
                                q0=s.q0, dq0=s.dq0, log_every=log_every(s), max_state=s.max_state)))
        except ConfigError as exc:
            out.append(exc)
    return out, how


def _row(point: Point, metrics: dict[str, Any] | ConfigError) -> dict[str, Any]:
    if isinstance(metrics, ConfigError):
        return {"run": point.run, "seed": point.seed, **point.inputs, "status": f"invalid: {metrics}"}
    return {"run": point.run, "seed": point.seed, **point.inputs, **{k: v for k, v in metrics.items() if k != "wall_time_s"}}


def run_chunk(job: tuple[dict[str, Any], list[Point]]) -> tuple[list[dict[str, Any]], str]:
    """Simulate one chunk of sweep points (runs in a worker process or on a Dask worker): the table rows, and how
    the chunk was run. A point whose values do not build gets a row with status ``invalid: …``."""
    data, points = job
    built: list[tuple[Point, Setup]] = []
    rows = []
    for point in points:
        try:
            built.append((point, _build(data, point)))
        except ConfigError as exc:
            rows.append(_row(point, exc))
    if not built:
        return rows, ""
    metrics, how = _metrics([s for _, s in built])
    rows += [_row(point, m) for (point, _), m in zip(built, metrics, strict=True)]
    return sorted(rows, key=lambda row: row["run"]), how


def read_table(path: Path) -> dict[int, dict[str, Any]]:
    """The complete rows of a table by run. A torn last line (an interrupted append) is dropped from the file."""
    if not path.exists():
        return {}
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    rows: dict[int, dict[str, Any]] = {}
    for k, line in enumerate(lines):
        try:
            row = json.loads(line) if line.endswith("\n") else None
        except json.JSONDecodeError:
            row = None
        if not isinstance(row, dict) or not isinstance(row.get("run"), int):
            if k < len(lines) - 1:
                raise ConfigError("--out", f"{path} line {k + 1} is not a row of a sweep table; use a new folder")
            atomic_write(path, lambda f: f.write("".join(lines[:-1])))
            break
        rows[row["run"]] = row
    return rows


def _append(path: Path, rows: list[dict[str, Any]]) -> None:
    """Append whole lines with one write, flushed to disk: a crash can tear at most the last line."""
    data = "".join(json.dumps(row) + "\n" for row in rows).encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)


def _check_manifest(path: Path, manifest: dict[str, Any]) -> None:
    text = json.dumps(manifest, indent=2, default=str)
    if not path.exists():
        atomic_write(path, lambda f: f.write(text))
        return
    try:
        old = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        old = None
    if old != json.loads(text):
        raise ConfigError("--out", f"{path.parent} holds another sweep ({path.name} differs); use a new folder or "
                          "the same arguments to resume it")


def scalar(value: Any) -> float:
    """A metric as one number: a per-joint list by its largest entry (the worst joint); NaN where there is none."""
    def number(v: Any) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool)

    if isinstance(value, list):
        return float(max(value)) if value and all(map(number, value)) else float("nan")
    return float(value) if number(value) else float("nan")


def check_metric(s: Setup, metric: str) -> None:
    """Raise unless `metric` is a numeric metric of this scenario's runs (asked of a one-step run)."""
    integrator = replace(s.integrator, backend="numpy") if isinstance(s.integrator, RK4) else s.integrator
    probe = simulate(s.plant, s.controller, s.trajectory, t_final=integrator.dt, integrator=integrator, q0=s.q0,
                     dq0=s.dq0)
    names = [k for k, v in metrics(probe).items()  # numbers, per-joint lists, or None where not reached yet
             if k != "wall_time_s" and (v is None or not math.isnan(scalar(v)))]
    if metric not in names:
        raise ConfigError("--metric", f"unknown metric {metric!r}; this scenario's runs have {', '.join(names)}")


def worker_init() -> None:
    """A local worker: the parent handles Ctrl-C and terminates it; its compiled step runs on one thread, since every
    core already has a worker (XLA's own threads would contend with the other workers; a user's XLA_FLAGS wins)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")


@contextmanager
def _executor(workers: int, scheduler: str | None) -> Iterator[tuple[int, Callable[[list[Any]], Iterator[Any]]]]:
    """(slots, run): `run(jobs)` yields `run_chunk(job)` for every job as each completes."""
    if scheduler is not None:
        try:
            from dask.distributed import Client, as_completed
        except ImportError:
            raise ConfigError("--scheduler", "needs the [dist] extra: pip install 'robotadapt[dist]'") from None
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:  # unreachable, or not an address
            raise ConfigError("--scheduler", f"cannot reach {scheduler!r}: {exc}") from None
        try:
            slots = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())
            yield max(slots, 1), lambda jobs: (f.result() for f in as_completed(client.map(run_chunk, jobs,
                                                                                              pure=False)))
        finally:
            client.close()
    elif workers == 1:
        yield 1, lambda jobs: map(run_chunk, jobs)
    else:
        import multiprocessing

        # a Pool (not a ProcessPoolExecutor): leaving the block terminates the workers at once, also on Ctrl-C;
        # spawned, not forked: a fork of a process whose JAX (or BLAS) threads are running can deadlock
        with multiprocessing.get_context("spawn").Pool(workers, initializer=worker_init) as pool:
            yield workers, lambda jobs: pool.imap_unordered(run_chunk, jobs)


def chunk_size(pending: int, slots: int, s: Setup) -> int:
    """Runs per chunk: the pending runs spread over the slots, at most `MAX_CHUNK`, and at least enough for
    `MIN_CHUNK_SECONDS` of work (a chunk costs at least its step count times `STEP_SECONDS`)."""
    steps = Grid.of(s.integrator, s.t_final).n
    least = math.ceil(MIN_CHUNK_SECONDS / (steps * STEP_SECONDS))
    return max(1, min(MAX_CHUNK, max(least, math.ceil(pending / slots))))


@dataclass(frozen=True, eq=False)
class SweepReport:
    """Every row of the table by run, how many were simulated by this call, its wall time and how the chunks ran."""

    rows: list[dict[str, Any]]
    computed: int
    seconds: float
    how: str


def run_sweep(sweep: Sweep, out: str | os.PathLike[str], *, workers: int | None = None, scheduler: str | None = None,
              progress: bool = False) -> SweepReport:
    """Run the sweep's pending runs into `out` (resuming: rows already in the table are kept, not rerun), on `workers`
    local processes (default: every core; 1 runs in this process) or on the Dask scheduler at `scheduler`."""
    from tqdm import tqdm

    base = setup(copy.deepcopy(sweep.data))
    folder = writable_dir(out)
    _check_manifest(folder / MANIFEST, sweep.manifest())
    table = folder / TABLE
    done = read_table(table)
    pending = [p for p in sweep.points() if p.run not in done]
    wall = time.perf_counter()
    hows = set()
    with _executor(workers or usable_cores(), scheduler) as (slots, run):
        size = chunk_size(len(pending), slots, base)
        jobs = [(sweep.data, pending[i : i + size]) for i in range(0, len(pending), size)]
        quiet = not (progress and sys.stderr.isatty())  # progress bars on a terminal only
        with tqdm(total=len(pending), disable=quiet, unit="run", file=sys.stderr, smoothing=0) as bar:
            for rows, how in run(jobs):
                _append(table, rows)
                done.update((row["run"], row) for row in rows)
                hows.add(how)
                bar.update(len(rows))
    ordered = [done[i] for i in sorted(done)]
    atomic_write(table, lambda f: f.writelines(json.dumps(row) + "\n" for row in ordered))
    return SweepReport(ordered, len(pending), time.perf_counter() - wall, "; ".join(sorted(hows - {""})))
