"""Metrics at every step: the running sums, maxima and last values a run's metrics need, folded by the one driver at
every step or tick of the run (:mod:`robotadapt.sim.driver`), on every backend, whatever the logging interval.

A transition's record carries the step's :class:`Sample` (the tracking error, its rate, the applied and the commanded
torque at t_k); the driver turns it into a :func:`row` and :func:`fold_rows` adds a few steps' rows at a time to the
run's :class:`Running` where the record is valid. From the fold, at the end
(:func:`values`, numbers of :func:`robotadapt.analysis.metrics.metrics`, over the instants t_k = k·h of the run grid):

- `rms_error` √(Σ_k e_i(t_k)² / K) per joint and `rms_error_norm` √(Σ_k ‖e(t_k)‖² / K), K the number of instants;
- `ise` ∫‖e‖² dt and `control_energy` ∫ τᵀτ dt by the trapezoid rule on the grid: h (Σ_k s_k − (s_0 + s_last)/2);
- `max_abs_error`, `max_abs_torque` (applied), `max_abs_commanded_torque` per joint, and `max_error_norm` max ‖e‖,
  over every instant;
- `saturated_fraction`, the share of instants whose applied torque differs from the command
  (:func:`robotadapt.analysis.metrics.saturated_fraction`'s rule);
- `convergence_time`, the last instant with ‖e‖ above 1 % of its maximum over the run (None: the last one): the last
  k with ‖e_k‖ > 0.01·max_{j ≤ k} ‖e_j‖ is that instant, since every rise of the maximum is such a k itself.

These equal the same numbers computed from a log of every step, to the order of the additions (1e-12 relative).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..arrays import array_namespace

Array = Any
CONVERGED = 0.01  # the share of the error's maximum that convergence_time measures against (analysis.monitors)


class Sample(NamedTuple):
    """What one step contributes, at t_k, leading run axes: e = q_des − q, ė, the applied torque u, the command τ."""

    e: Array
    de: Array
    tau: Array
    commanded: Array


class Running(NamedTuple):
    """The fold of a run's samples so far (leading run axes; the module docstring)."""

    count: Array
    sum_e2: Array  # Σ e_i², per joint
    sum_norm2: Array  # Σ ‖e‖²
    sum_power: Array  # Σ τᵀτ (applied)
    first: Array  # (‖e‖², τᵀτ) at the first instant
    last: Array  # (‖e‖², τᵀτ) at the last instant
    max_abs_e: Array
    max_abs_tau: Array
    max_abs_commanded: Array
    saturated: Array  # instants at which the actuator changed the command
    max_norm: Array  # max ‖e‖ so far
    above: Array  # the last step index k with ‖e_k‖ > CONVERGED·(max ‖e‖ up to k); −1: none
    k_last: Array  # the last step index folded


def start(xp: Any, runs: tuple[int, ...], n: int, m: int | None = None) -> Running:
    """The fold before step 0: `n` torques, `m` entries of the tracking error (default n; a task-space law's m)."""
    zeros, vector, error = xp.zeros(runs), xp.zeros(runs + (n,)), xp.zeros(runs + (n if m is None else m,))
    return Running(zeros, error, zeros, zeros, xp.zeros(runs + (2,)), xp.zeros(runs + (2,)), error, vector, vector,
                   zeros, zeros, zeros - 1.0, zeros - 1.0)


def row(sample: Sample, valid: Array) -> Array:
    """What a step hands the fold, as one array `(runs..., m + 2n + 1)`: e, the applied torque, the command, and 1.0 where
    the step's record is valid (else 0.0). A compiled loop writes one a step (one array: XLA runs each output's update
    as a kernel of its own) and :func:`fold_rows` folds a call's rows at once on the host: the fold inside the loop
    cost Example 6.3.1's compiled step some 8 µs of kernels, the rows 0.1 µs (benchmarks/bench_single_run.py)."""
    xp = array_namespace(sample.e)
    ok = xp.asarray(valid, dtype=sample.e.dtype)
    return xp.concatenate([sample.e, sample.tau, sample.commanded,
                           xp.broadcast_to(ok, sample.e.shape[:-1])[..., None]], axis=-1)


def fold_rows(acc: Running, rows: Array, ks: Array) -> Running:
    """`acc` with the :func:`row`s of some steps, `(steps, runs..., m + 2n + 1)`, folded in one vectorized pass (numpy);
    `ks` the steps' indices. The same sums as a step-by-step fold to the order of the additions (each run's steps
    added, then to its sum), the same maxima, first and last values."""
    rows = np.asarray(rows)
    if rows.shape[0] == 0:
        return acc
    m, n = acc.sum_e2.shape[-1], acc.max_abs_tau.shape[-1]
    c = np.ascontiguousarray(np.moveaxis(rows, 0, -1))  # (runs..., m + 2n + 1, steps): numpy's loops run along the steps
    e, tau, commanded, ok = c[..., :m, :], c[..., m : m + n, :], c[..., m + n : m + 2 * n, :], c[..., -1, :] > 0.5
    k = np.broadcast_to(np.asarray(ks, dtype=float), ok.shape)
    every = bool(ok.all())  # the common case: no step to leave out (no mask applied)
    zero = ~ok[..., None, :]

    def only(valid: Array, a: Array, fill: float = 0.0) -> Array:  # `a` where the step is valid, else `fill`
        return a if every else np.where(valid, a, fill)

    e2 = e * e
    norm2, power = e2.sum(axis=-2), (tau * tau).sum(axis=-2)
    clipped = np.any(np.abs(commanded - tau) > 1e-9 * (1.0 + np.abs(commanded)), axis=-2)
    norm = np.sqrt(norm2)
    any_ok = np.asarray(ok.any(axis=-1))
    first_i, last_i = ok.argmax(axis=-1), ok.shape[-1] - 1 - ok[..., ::-1].argmax(axis=-1)
    ends = np.stack([norm2, power], axis=-2)  # (runs..., 2, steps)

    def pick(i: Array) -> Array:  # the ends at step i of each run
        return np.take_along_axis(ends, np.broadcast_to(i[..., None, None], ends.shape[:-1] + (1,)), axis=-1)[..., 0]

    def peak(a: Array) -> Array:
        return only(~zero, np.abs(a)).max(axis=-1)

    max_norm = np.maximum.accumulate(np.maximum(only(ok, norm), acc.max_norm[..., None]), axis=-1)
    above = np.where(ok & (norm > CONVERGED * max_norm), k, -1.0).max(axis=-1)
    started = np.asarray(acc.count > 0)
    return Running(acc.count + ok.sum(axis=-1), acc.sum_e2 + only(~zero, e2).sum(axis=-1),
                   acc.sum_norm2 + only(ok, norm2).sum(axis=-1), acc.sum_power + only(ok, power).sum(axis=-1),
                   np.where((started | ~any_ok)[..., None], acc.first, pick(first_i)),
                   np.where(any_ok[..., None], pick(last_i), acc.last),
                   np.maximum(acc.max_abs_e, peak(e)), np.maximum(acc.max_abs_tau, peak(tau)),
                   np.maximum(acc.max_abs_commanded, peak(commanded)), acc.saturated + (ok & clipped).sum(axis=-1),
                   max_norm[..., -1], np.maximum(acc.above, above),
                   np.where(any_ok, only(ok, k, -1.0).max(axis=-1), acc.k_last))


def fold_step(acc: Running, row: Array, k: Array) -> Running:
    """`acc` with one step's :func:`row` folded (array API): the fold a C program runs in its loop, where a step's few
    operations cost nanoseconds (XLA would run each as a kernel). The same numbers as :func:`fold_rows` but for the
    order of the additions (each step added to the sums here, a call's steps summed first there)."""
    xp = array_namespace(row)
    m, n = acc.sum_e2.shape[-1], acc.max_abs_tau.shape[-1]
    e, tau, commanded = row[..., :m], row[..., m : m + n], row[..., m + n : m + 2 * n]
    ok = row[..., -1] > 0.5
    e2 = e * e
    norm2, power = xp.sum(e2, axis=-1), xp.sum(tau * tau, axis=-1)
    norm = xp.sqrt(norm2)
    clipped = xp.any(xp.abs(commanded - tau) > 1e-9 * (1.0 + xp.abs(commanded)), axis=-1)
    kf = xp.asarray(k, dtype=row.dtype) + xp.zeros_like(norm)
    ends = xp.stack([norm2, power], axis=-1)
    valid, counted = ok[..., None], xp.where(ok, 1.0, 0.0)

    def peak(old: Array, a: Array) -> Array:
        return xp.maximum(old, xp.where(valid, xp.abs(a), 0.0))

    max_norm = xp.where(ok, xp.maximum(acc.max_norm, norm), acc.max_norm)
    return Running(acc.count + counted, acc.sum_e2 + xp.where(valid, e2, 0.0), acc.sum_norm2 + xp.where(ok, norm2, 0.0),
                   acc.sum_power + xp.where(ok, power, 0.0), xp.where(((acc.count > 0) | ~ok)[..., None], acc.first, ends),
                   xp.where(valid, ends, acc.last), peak(acc.max_abs_e, e), peak(acc.max_abs_tau, tau),
                   peak(acc.max_abs_commanded, commanded), acc.saturated + xp.where(ok & clipped, 1.0, 0.0), max_norm,
                   xp.where(ok & (norm > CONVERGED * max_norm), kf, acc.above), xp.where(ok, kf, acc.k_last))


def run(acc: Running, i: int) -> Running:
    """Run i's fold, of a fold with a leading run axis."""
    return Running(*(a[i] for a in acc))


def values(acc: Running, h: float) -> dict[str, Any]:
    """The metrics of one run's fold (no run axes; numpy), `h` the grid's step."""
    count = float(acc.count)
    trapezoid = h * (np.stack([acc.sum_norm2, acc.sum_power]) - 0.5 * (acc.first + acc.last)) if count > 1 else (
        np.zeros(2))
    above = int(acc.above)
    return {"rms_error": np.sqrt(acc.sum_e2 / count).tolist(), "rms_error_norm": float(np.sqrt(acc.sum_norm2 / count)),
            "ise": float(trapezoid[0]), "control_energy": float(trapezoid[1]),
            "max_abs_error": acc.max_abs_e.tolist(), "max_error_norm": float(acc.max_norm),
            "max_abs_torque": acc.max_abs_tau.tolist(),
            "max_abs_commanded_torque": acc.max_abs_commanded.tolist(),
            "saturated_fraction": float(acc.saturated) / count,
            "convergence_time": 0.0 if above < 0 else None if above == int(acc.k_last) else above * h}
