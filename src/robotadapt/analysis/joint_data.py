"""Logged joint data for identification (docs/identification.md#data): time, positions, optional velocities, torques.

Three kinds of DATA are read, each checked whole before anything is computed:

- a `result.npz` of `robotadapt run`: `t`, the positions the controller saw (`q_measured` when the run had a sensor,
  else `q`), `dq_measured` / `dq` likewise, and `tau`, the torque the plant received (after the actuator: what a joint
  torque sensor or a calibrated motor current reports);
- a CSV file with a header row naming the columns `t`, `q1` … `qn`, optionally `dq1` … `dqn`, and `tau1` … `taun`
  (SI units: s, rad or m, rad/s or m/s, N·m or N; other columns are ignored, so a log with extra channels reads);
- a ROS 2 bag (its folder, or its `.db3` / `.mcap` file) or a ROS 1 `.bag` of `sensor_msgs/msg/JointState`, read by
  :mod:`robotadapt.analysis.bag` (the `rosbags` package of the `[identify]` extra, no ROS install): joints matched to
  the model's by name, time from the header stamps.

Every value must be finite and time must not go back; velocities, when given, are used as logged (positions are then
differentiated only once, for accelerations).

**Time stamps as a robot writes them.** A log whose sample period varies by at most 1 % is passed on untouched. Any
other is resampled onto a uniform grid (the filters and derivatives of the identification assume one) and says so in
one line of :attr:`JointData.notes`, the jitter found and the rate chosen:

- the rate is the inverse of the median sample period rounded to three significant figures (a Panda's 1 kHz log with
  periods of 0.7 to 8.8 ms: 1000 Hz; a 1250-Hz log with samples lost: 1250 Hz), within 0.5 % of the logged rate, the
  grid starting at the first stamp and never extrapolating past the last;
- q and a logged q̇ by a cubic spline (not-a-knot, C²: positions and velocities of rigid bodies are smooth, q is
  differentiated twice downstream, and the spline's O(h⁴) error is 2.5e-7 of a 2 Hz sine against linear interpolation's
  6e-4 at periods of 0.7–9 ms); τ linearly, so that a step (Coulomb friction at a velocity reversal, a changed command)
  never overshoots or rings, each value staying between its two logged neighbours; q̇ is never made from q here;
- a gap longer than `max_gap` (default 10 median periods: a Panda's 8.8-ms drop at 1 kHz passes, a lost stretch of a
  log does not) is refused, naming its time, since no interpolation bridges it honestly;
- a repeated time stamp whose sample repeats the previous one exactly is dropped (a note counts them); one with
  different values, or a stamp that goes back, is refused, naming the sample and its time.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..validation import ConfigError

Array = np.ndarray


MAX_GAP_PERIODS = 10.0
"""The longest gap between time stamps bridged by default, in median sample periods."""

BAG_SUFFIXES = (".db3", ".mcap", ".bag")

Columns = tuple[Array, Array, Array | None, Array]


@dataclass(frozen=True, eq=False)
class JointData:
    """`t` (N,), `q` (N, n), `dq` (N, n) or None, `tau` (N, n); `source` names the file for messages; `notes` one line
    each on what reading changed (a resampling, dropped repeats, the topic and joints of a bag), to print."""

    t: Array
    q: Array
    dq: Array | None
    tau: Array
    source: str
    notes: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        return int(self.q.shape[1])

    @property
    def dt(self) -> float:
        """The median sample period."""
        return float(np.median(np.diff(self.t)))

    def slice(self, keep: slice) -> JointData:
        """The samples `keep`."""
        return JointData(self.t[keep], self.q[keep], None if self.dq is None else self.dq[keep], self.tau[keep],
                         self.source, self.notes)


def read(path: str | Path, n: int, *, joint_names: Sequence[str] | None = None, topic: str | None = None,
         max_gap: float | None = None) -> JointData:
    """The joint data of `path` (module docstring) for an arm of `n` joints, on a uniform time grid.

    `joint_names` (the model's, n of them) match a bag's joints by name, `topic` picks its JointState topic when it has
    several; a CSV or .npz names its joints by column and ignores them. `max_gap` (s) is the longest gap between time
    stamps that resampling bridges (default :data:`MAX_GAP_PERIODS` median periods).
    """
    path = Path(path)
    if max_gap is not None and not max_gap > 0:
        raise ConfigError("max_gap", f"the longest gap bridged must be a positive number of seconds, got {max_gap!r}")
    if not path.exists():
        raise ConfigError("DATA", f"no such file or folder: {str(path)!r}")
    notes: tuple[str, ...] = ()
    if path.is_dir() or path.suffix in BAG_SUFFIXES:
        from .bag import read_bag

        t, q, dq, tau, notes = read_bag(path, n, joint_names=joint_names, topic=topic)
        columns: Columns = (t, q, dq, tau)
    elif topic is not None:
        raise ConfigError("DATA", f"a topic ({topic!r}) was given but {path.name!r} is no ROS bag: a topic chooses "
                          "among a bag's JointState topics")
    elif path.suffix == ".npz":
        columns = _npz(path, n)
    elif path.suffix == ".csv":
        columns = _csv(path, n)
    else:
        raise ConfigError("DATA", f"expected a result.npz of `robotadapt run`, a .csv file or a ROS bag (folder, .db3, "
                          f".mcap or .bag), got {path.name!r}")
    return _checked(*columns, source=path.name or str(path), notes=notes, max_gap=max_gap)


def _npz(path: Path, n: int) -> Columns:
    try:
        with np.load(path) as f:
            arrays = {k: np.asarray(f[k], dtype=float) for k in f.files if k in
                      ("t", "q", "q_measured", "dq", "dq_measured", "tau")}
    except (OSError, ValueError) as exc:
        raise ConfigError("DATA", f"cannot read {path.name!r} as a .npz archive: {exc}") from None
    for key in ("t", "q", "tau"):
        if key not in arrays:
            raise ConfigError("DATA", f"{path.name} has no array {key!r}: expected a result.npz of `robotadapt run`")
    q = arrays.get("q_measured", arrays["q"])
    dq = arrays.get("dq_measured", arrays.get("dq"))
    for name, value in (("q", q), ("dq", dq), ("tau", arrays["tau"])):
        if value is not None and (value.ndim != 2 or value.shape[1] != n):
            raise ConfigError("DATA", f"{path.name}: {name} has shape {value.shape}, expected (samples, {n}) for the "
                              f"robot's {n} joints")
    return arrays["t"], q, dq, arrays["tau"]


def _csv(path: Path, n: int) -> Columns:
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError("DATA", f"cannot read {path.name!r}: {exc}") from None
    if not rows:
        raise ConfigError("DATA", f"{path.name} is empty: expected a header row t, q1…q{n}, tau1…tau{n}")
    header = [h.strip() for h in rows[0]]
    joints = sorted({int(h[1:]) for h in header if h[:1] == "q" and h[1:].isdigit()})
    if joints and joints != list(range(1, n + 1)):
        raise ConfigError("DATA", f"{path.name} has position columns q{joints[0]}…q{joints[-1]} ({len(joints)} "
                          f"joints), the robot has {n}: give q1…q{n}")
    wanted = ["t", *(f"q{i}" for i in range(1, n + 1)), *(f"tau{i}" for i in range(1, n + 1))]
    missing = [h for h in wanted if h not in header]
    if missing:
        raise ConfigError("DATA", f"{path.name} lacks the column{'s' * (len(missing) > 1)} {', '.join(missing[:4])}"
                          f"{' …' * (len(missing) > 4)}: a CSV needs t, q1…q{n}, tau1…tau{n} (dq1…dq{n} optional)")
    dq_names = [f"dq{i}" for i in range(1, n + 1)]
    given = [h for h in dq_names if h in header]
    if given and len(given) != n:
        raise ConfigError("DATA", f"{path.name} has {len(given)} of the {n} velocity columns dq1…dq{n}: give all or none")
    width = len(header)
    values = np.full((len(rows) - 1, width), np.nan)
    for i, row in enumerate(rows[1:]):
        if len(row) != width:
            raise ConfigError("DATA", f"{path.name} row {i + 2} has {len(row)} fields, the header {width}")
        try:
            values[i] = [float(x) if x.strip() else np.nan for x in row]
        except ValueError:
            raise ConfigError("DATA", f"{path.name} row {i + 2} has a field that is not a number") from None

    def cols(names: list[str]) -> Array:
        return values[:, [header.index(h) for h in names]]

    return (values[:, header.index("t")], cols(wanted[1 : n + 1]), cols(dq_names) if given else None,
            cols(wanted[n + 1 :]))


def _checked(t: Array, q: Array, dq: Array | None, tau: Array, source: str, notes: tuple[str, ...] = (),
             max_gap: float | None = None) -> JointData:
    if t.ndim != 1 or t.size < 2 or len(q) != t.size or len(tau) != t.size or (dq is not None and len(dq) != t.size):
        raise ConfigError("DATA", f"{source}: t, q and tau must have one row per sample")
    for name, value in (("t", t), ("q", q), ("dq", dq), ("tau", tau)):
        if value is not None and not np.all(np.isfinite(value)):
            row = int(np.flatnonzero(~np.all(np.isfinite(value.reshape(t.size, -1)), axis=1))[0])
            raise ConfigError("DATA", f"{source}: {name} is missing or not finite at sample {row} (t = {t[row]:.6g} s): "
                              "remove or fill the gap")
    steps = np.diff(t)
    if np.any(steps < 0):
        k = int(np.flatnonzero(steps < 0)[0])
        raise ConfigError("DATA", f"{source}: time does not increase at sample {k + 1} (t = {t[k]:.6g} then "
                          f"{t[k + 1]:.6g}): sort the rows and drop repeated samples")
    if np.any(steps == 0):
        t, q, dq, tau, note = _without_repeats(t, q, dq, tau, source)
        notes, steps = (*notes, note), np.diff(t)
        if t.size < 2:
            raise ConfigError("DATA", f"{source}: every sample repeats the first: nothing moves in time")
    if np.max(steps) <= 1.01 * np.min(steps) + 1e-12:
        return JointData(t, q, dq, tau, source, notes)
    return _resampled(t, q, dq, tau, source, notes, max_gap)


def _without_repeats(t: Array, q: Array, dq: Array | None, tau: Array,
                     source: str) -> tuple[Array, Array, Array | None, Array, str]:
    """The samples without those that repeat the previous one exactly (time and values), and a note counting them;
    a repeated time stamp with other values is refused."""
    rows = np.column_stack([q, tau] if dq is None else [q, dq, tau])
    same_time = np.diff(t) == 0
    same_values = np.all(rows[1:] == rows[:-1], axis=1)
    if np.any(same_time & ~same_values):
        k = int(np.flatnonzero(same_time & ~same_values)[0])
        raise ConfigError("DATA", f"{source}: samples {k} and {k + 1} share the time stamp t = {t[k]:.6g} s but differ "
                          "in value: keep the right one (or fix the clock that stamped them)")
    drop = np.flatnonzero(same_time) + 1
    keep = np.ones(t.size, dtype=bool)
    keep[drop] = False
    note = (f"{source}: dropped {drop.size} sample{'s' * (drop.size > 1)} repeating the previous one exactly (time "
            f"and values; the first at sample {drop[0]}, t = {t[drop[0]]:.6g} s)")
    return t[keep], q[keep], None if dq is None else dq[keep], tau[keep], note


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3g} ms"


def _resampled(t: Array, q: Array, dq: Array | None, tau: Array, source: str, notes: tuple[str, ...],
               max_gap: float | None) -> JointData:
    """The log on a uniform grid at the median rate rounded to three significant figures: q and q̇ by cubic spline, τ
    linearly (module docstring); gaps longer than `max_gap` refused."""
    from scipy.interpolate import CubicSpline

    steps = np.diff(t)
    median = float(np.median(steps))
    limit = MAX_GAP_PERIODS * median if max_gap is None else float(max_gap)
    if np.max(steps) > limit:
        k = int(np.argmax(steps > limit))
        raise ConfigError("DATA", f"{source}: a gap of {_ms(steps[k])} in the time stamps at t = {t[k]:.6g} s (samples "
                          f"{k} to {k + 1}), {steps[k] / median:.3g} median periods of {_ms(median)}, longer than the "
                          f"{_ms(limit)} interpolation may bridge: cut the log there, or allow it with a larger "
                          f"max_gap (--max-gap {float(f'{steps[k] * 1.1:.2g}'):g})")
    rate = float(f"{1 / median:.3g}")
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate)) + 1) / rate  # never past the last stamp
    q_new = CubicSpline(t, q, axis=0)(grid)
    dq_new = None if dq is None else CubicSpline(t, dq, axis=0)(grid)
    k = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, t.size - 2)
    w = ((grid - t[k]) / steps[k])[:, None]
    tau_new = (1 - w) * tau[k] + w * tau[k + 1]
    note = (f"{source}: time stamps jittered, sample period {_ms(float(np.min(steps)))} to {_ms(float(np.max(steps)))} "
            f"(median {_ms(median)}, standard deviation {_ms(float(np.std(steps)))}); resampled to a uniform "
            f"{rate:g} Hz, {t.size} → {grid.size} samples (q{' and q̇' * (dq is not None)} by cubic spline, τ linearly)")
    return JointData(grid, q_new, dq_new, tau_new, source, (*notes, note))
