"""Logged joint data for identification (docs/identification.md#data): time, positions, optional velocities, torques.

Two formats are read, each checked whole before anything is computed:

- a `result.npz` of `robotadapt run`: `t`, the positions the controller saw (`q_measured` when the run had a sensor,
  else `q`), `dq_measured` / `dq` likewise, and `tau`, the torque the plant received (after the actuator: what a joint
  torque sensor or a calibrated motor current reports);
- a CSV file with a header row naming the columns `t`, `q1` … `qn`, optionally `dq1` … `dqn`, and `tau1` … `taun`
  (SI units: s, rad or m, rad/s or m/s, N·m or N; other columns are ignored, so a log with extra channels reads).

Time must increase strictly and every value be finite; velocities, when given, are used as logged (positions are then
differentiated only once, for accelerations).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..validation import ConfigError

Array = np.ndarray


@dataclass(frozen=True, eq=False)
class JointData:
    """`t` (N,), `q` (N, n), `dq` (N, n) or None, `tau` (N, n); `source` names the file for messages."""

    t: Array
    q: Array
    dq: Array | None
    tau: Array
    source: str

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
                         self.source)


def read(path: str | Path, n: int) -> JointData:
    """The joint data of `path` (a `.npz` of ours or a `.csv`, module docstring) for an arm of `n` joints."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("DATA", f"no such file: {str(path)!r}")
    if path.suffix == ".npz":
        columns = _npz(path, n)
    elif path.suffix == ".csv":
        columns = _csv(path, n)
    else:
        raise ConfigError("DATA", f"expected a result.npz of `robotadapt run` or a .csv file, got {path.name!r}")
    return _checked(*columns, source=path.name)


def _npz(path: Path, n: int) -> tuple[Array, Array, Array | None, Array]:
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


def _csv(path: Path, n: int) -> tuple[Array, Array, Array | None, Array]:
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


def _checked(t: Array, q: Array, dq: Array | None, tau: Array, source: str) -> JointData:
    if t.ndim != 1 or t.size < 2 or len(q) != t.size or len(tau) != t.size or (dq is not None and len(dq) != t.size):
        raise ConfigError("DATA", f"{source}: t, q and tau must have one row per sample")
    for name, value in (("t", t), ("q", q), ("dq", dq), ("tau", tau)):
        if value is not None and not np.all(np.isfinite(value)):
            row = int(np.flatnonzero(~np.all(np.isfinite(value.reshape(t.size, -1)), axis=1))[0])
            raise ConfigError("DATA", f"{source}: {name} is missing or not finite at sample {row} (t = {t[row]:.6g} s): "
                              "remove or fill the gap")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ConfigError("DATA", f"{source}: time does not increase at sample {k + 1} (t = {t[k]:.6g} then "
                          f"{t[k + 1]:.6g}): sort the rows and drop repeated samples")
    if np.max(steps) > 1.01 * np.min(steps) + 1e-12:
        raise ConfigError("DATA", f"{source}: the sample period varies from {np.min(steps):.4g} to {np.max(steps):.4g} "
                          "s; resample to a uniform rate (the filters and derivatives assume one)")
    return JointData(t, q, dq, tau, source)
