"""A run as the page draws it: the panels of `robotadapt run`'s figures (tracking error on a linear and a log axis, the
estimates with their truths, the torques with their limits) and V(t), their curves in one table of columns with at most
`MAX_POINTS` samples (one message to the browser for every figure), and the metrics as rows of metrics.json's names and
values."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..report.figures import (
    EFFORT,
    EFFORT_NAME,
    MAX_PARAMETER_LINES,
    POSITION,
    joint_types,
    norm_unit,
    parameter_units,
    positive,
)
from ..studies.compare import number_text
from .catalogue import Run

#: the samples a curve keeps (every k-th of the run's, the last one too): about two a pixel of a figure's width. More
#: cost the redraw: Example 6.3.1's five figures at 2000 points in double precision took 12 ms longer from a slider's
#: release to the redrawn figures (benchmarks/bench_explorer.py's drags, alternated between two servers)
MAX_POINTS = 1000
#: a list in metrics.json up to this long is a row of the table; a longer one (an n-DOF arm's φ̂) is left to the file
MAX_LIST = 8


@dataclass(frozen=True)
class Series:
    """A curve: its column, legend label, colour index and whether it is a truth (dashed)."""

    column: str
    label: str
    color: int
    truth: bool = False


@dataclass(frozen=True)
class Panel:
    """A figure: name, title, y-axis label, log axis or not, curves, horizontal limit lines (value, colour index) and
    whether it has a legend (not when another panel's names the same colours, nor for one curve: each legend costs the
    browser time at every redraw)."""

    name: str
    title: str
    ylabel: str
    log: bool
    series: tuple[Series, ...]
    limits: tuple[tuple[float, int], ...] = ()
    legend: bool = True


@dataclass(frozen=True, eq=False)
class Curves:
    """A run's panels and their data: `t` and a column per curve (`e0`, `abs_e1`, …)."""

    panels: list[Panel]
    data: dict[str, np.ndarray] = field(default_factory=dict)


def thinned(n: int, limit: int = MAX_POINTS) -> np.ndarray:
    """Indices of at most about `limit` of `n` samples, evenly strided, the last one included."""
    step = max(1, -(-n // limit))
    return np.unique(np.r_[np.arange(0, n, step), n - 1]) if n else np.arange(0)


def single(values: np.ndarray) -> np.ndarray:
    """`values` in single precision, as the browser draws them (seven digits, half the bytes to send): magnitudes
    beyond single precision's range kept at its ends (not ±inf, nor 0 on a log axis); NaN stays NaN."""
    info = np.finfo(np.float32)
    magnitude = np.clip(np.abs(values), info.tiny, info.max)
    return np.where(values == 0, 0.0, np.sign(values) * magnitude).astype(np.float32)


def _curves(name: str, values: list[np.ndarray]) -> dict[str, np.ndarray]:
    """The columns `name0`, `name1`, … of `values`, in single precision."""
    return {f"{name}{i}": single(np.asarray(v, dtype=float)) for i, v in enumerate(values)}


def _estimates(run: Run, keep: np.ndarray) -> tuple[Panel, list[np.ndarray]]:
    """φ̂_i with the true φ_i dashed; the relative error ‖φ − φ̂‖/‖φ‖ (‖φ̂‖ without the truth) for many parameters; at
    the samples `keep`."""
    res = run.result
    names = res.param_names
    if not names:
        return Panel("phi", "this law estimates no parameters", "", False, ()), []
    phi_hat, truth = res.phi_hat[keep], res.phi_true
    truth = None if truth is None else truth[keep]
    if len(names) > MAX_PARAMETER_LINES:
        if truth is None:
            return Panel("phi", f"‖φ̂‖ of {len(names)} parameters", "‖φ̂‖ (mixed units)", False,
                         (Series("phi0", "‖φ̂‖", 0),)), [np.linalg.norm(phi_hat, axis=-1)]
        rel = np.linalg.norm(truth - phi_hat, axis=-1) / np.maximum(np.linalg.norm(truth, axis=-1), 1e-300)
        return Panel("phi", f"parameter error, {len(names)} parameters", "‖φ − φ̂‖ / ‖φ‖", True,
                     (Series("phi0", "‖φ − φ̂‖ / ‖φ‖", 0),)), [positive(rel)]
    units = parameter_units(run.model, names)
    series = [Series(f"phi{i}", f"{name}" + (f" ({unit})" if unit else ""), i) for i, (name, unit) in
              enumerate(zip(names, units, strict=True))]
    values = list(phi_hat.T)
    if truth is not None:
        series += [Series(f"phi{len(names) + i}", f"{name} true", i, truth=True) for i, name in enumerate(names)]
        values += list(truth.T)
    title = "estimates φ̂ (solid), true φ (dashed)" if truth is not None else "estimates φ̂"
    return Panel("phi", title, "φ̂, φ", False, tuple(series)), values


def curves(run: Run) -> Curves:
    """The run's panels — e, |e| (log), φ̂ with φ, τ with ±τ_max, V (log) — and their data."""
    res = run.result
    keep = thinned(res.t.size)
    task = res.space == "task"
    e = res.e[keep]
    n = e.shape[-1]
    joints = "P" * n if task else joint_types(run.model)
    unit = norm_unit(POSITION, joints)
    names = [f"e_{'xyz'[i]}" if task else f"e_{i + 1}" for i in range(n)]
    effort = norm_unit(EFFORT, joints)
    limit = res.info.get("plant", {}).get("actuator", {}).get("torque_limit")
    tau_n = res.tau.shape[-1]
    limits = () if limit is None else tuple(
        (sign * float(v), i) for i, v in enumerate(np.broadcast_to(np.asarray(limit, dtype=float), (tau_n,)))
        for sign in (1.0, -1.0))
    kinds = set(joints or "?")
    estimates, phi = _estimates(run, keep)
    panels = [
        Panel("e", "hand error e = x_d − x" if task else "tracking error e = q_d − q", f"e ({unit})", False,
              tuple(Series(f"e{i}", name, i) for i, name in enumerate(names))),
        Panel("abs_e", "|e|, log scale (colours as e)", f"|e| ({unit})", True,
              tuple(Series(f"abs_e{i}", name, i) for i, name in enumerate(names)), legend=False),
        estimates,
        Panel("tau", "control input τ" + (", limits ±τ_max dotted" if limits else ""),
              f"{EFFORT_NAME[kinds.pop()] if len(kinds) == 1 else 'torque or force'} τ ({effort})", False,
              tuple(Series(f"tau{i}", f"τ_{i + 1}", i) for i in range(tau_n)), limits),
        Panel("V", "this law has no Lyapunov function V", "", False, ()) if res.V is None else
        Panel("V", "Lyapunov function V, log scale", "V", True, (Series("V0", "V", 0),), legend=False),
    ]
    data = {"t": res.t[keep], **_curves("e", list(e.T)), **_curves("abs_e", [positive(np.abs(c)) for c in e.T]),
            **_curves("phi", phi), **_curves("tau", list(res.tau[keep].T)),
            **_curves("V", [] if res.V is None else [positive(res.V[keep])])}
    return Curves(panels, data)


def metric_rows(m: dict[str, Any]) -> dict[str, str]:
    """metrics.json's entries that fit a table's cell, by name, as `robotadapt compare` writes numbers (4 significant
    digits): numbers, text, short lists and the record of a stop."""
    out = {}
    for key, value in m.items():
        short = isinstance(value, list) and len(value) <= MAX_LIST and not any(isinstance(v, list | dict) for v in value)
        if value is None or isinstance(value, int | float | str) or short or key == "stop":
            out[key] = number_text(value)
    return out
