"""Metrics at every step: the running sums, maxima and last values a run's metrics need, folded by the one driver at
every step or tick of the run (:mod:`robotadapt.sim.driver`), on every backend, whatever the logging interval.

A transition's record carries the step's :class:`Sample` (the tracking error, its rate, the applied and the commanded
torque at t_k); :func:`fold` adds it to the run's :class:`Running` where the record is valid. From the fold, at the end
(:func:`values`, numbers of :func:`robotadapt.analysis.metrics.metrics`, over the instants t_k = k·h of the run grid):

- `rms_error` √(Σ_k e_i(t_k)² / K) per joint and `rms_error_norm` √(Σ_k ‖e(t_k)‖² / K), K the number of instants;
- `ise` ∫‖e‖² dt and `control_energy` ∫ τᵀτ dt by the trapezoid rule on the grid: h (Σ_k s_k − (s_0 + s_last)/2);
- `max_abs_error`, `max_abs_torque` (applied), `max_abs_commanded_torque` per joint, over every instant;
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


def start(xp: Any, runs: tuple[int, ...], n: int) -> Running:
    """The fold before step 0."""
    zeros, vector = xp.zeros(runs), xp.zeros(runs + (n,))
    return Running(zeros, vector, zeros, zeros, xp.zeros(runs + (2,)), xp.zeros(runs + (2,)), vector, vector, vector,
                   zeros, zeros, zeros - 1.0, zeros - 1.0)


def fold(acc: Running, sample: Sample, k: Array, valid: Array) -> Running:
    """`acc` with step k's `sample` added where `valid` (per run); unchanged elsewhere."""
    xp = array_namespace(sample.e)
    e2 = sample.e * sample.e
    norm2, power = e2.sum(axis=-1), (sample.tau * sample.tau).sum(axis=-1)
    ends = xp.stack([norm2, power], axis=-1)
    clipped = xp.any(xp.abs(sample.commanded - sample.tau) > 1e-9 * (1.0 + xp.abs(sample.commanded)), axis=-1)
    norm = xp.sqrt(norm2)
    max_norm = xp.maximum(acc.max_norm, norm)
    new = Running(acc.count + 1.0, acc.sum_e2 + e2, acc.sum_norm2 + norm2, acc.sum_power + power,
                  xp.where((acc.count == 0)[..., None], ends, acc.first), ends,
                  xp.maximum(acc.max_abs_e, xp.abs(sample.e)), xp.maximum(acc.max_abs_tau, xp.abs(sample.tau)),
                  xp.maximum(acc.max_abs_commanded, xp.abs(sample.commanded)), acc.saturated + clipped,
                  max_norm, xp.where(norm > CONVERGED * max_norm, k + 0.0 * norm, acc.above), k + 0.0 * norm)
    return Running(*(xp.where(valid.reshape(valid.shape + (1,) * (a.ndim - valid.ndim)), a, b)
                     for a, b in zip(new, acc, strict=True)))


def fold_steps(acc: Running, samples: list[Sample], ks: list[int], valid: list[Array]) -> Running:
    """:func:`fold` of several steps at once (numpy: the Python loop folds a few steps in one vectorized pass): the
    same sums to the order of the additions (each run's steps added in order, then to its sum), the same maxima, first
    and last values."""
    if not samples:
        return acc
    s = Sample(*(np.stack(parts) for parts in zip(*samples, strict=True)))
    ok = np.stack([np.broadcast_to(v, acc.count.shape) for v in valid])  # (steps, runs...)
    k = np.asarray(ks, dtype=float).reshape((-1,) + (1,) * acc.count.ndim) + np.zeros(ok.shape)
    mask = ok[..., None]
    e2 = s.e * s.e
    norm2, power = e2.sum(axis=-1), (s.tau * s.tau).sum(axis=-1)
    ends = np.stack([norm2, power], axis=-1)
    clipped = np.any(np.abs(s.commanded - s.tau) > 1e-9 * (1.0 + np.abs(s.commanded)), axis=-1)
    norm = np.sqrt(norm2)
    any_ok = np.asarray(ok.any(axis=0))
    first_i, last_i = ok.argmax(axis=0), ok.shape[0] - 1 - ok[::-1].argmax(axis=0)
    pick = (lambda a, i: np.take_along_axis(a, i[None, ..., None], axis=0)[0])  # noqa: E731  row i per run
    max_norm = np.maximum.accumulate(np.maximum(np.where(ok, norm, 0.0), acc.max_norm), axis=0)
    above = np.where(ok & (norm > CONVERGED * max_norm), k, -1.0).max(axis=0)
    started = np.asarray(acc.count > 0)
    return Running(acc.count + ok.sum(axis=0), acc.sum_e2 + np.where(mask, e2, 0.0).sum(axis=0),
                   acc.sum_norm2 + np.where(ok, norm2, 0.0).sum(axis=0), acc.sum_power + np.where(ok, power, 0.0).sum(0),
                   np.where((started | ~any_ok)[..., None], acc.first, pick(ends, first_i)),
                   np.where(any_ok[..., None], pick(ends, last_i), acc.last),
                   np.maximum(acc.max_abs_e, np.where(mask, np.abs(s.e), 0.0).max(axis=0)),
                   np.maximum(acc.max_abs_tau, np.where(mask, np.abs(s.tau), 0.0).max(axis=0)),
                   np.maximum(acc.max_abs_commanded, np.where(mask, np.abs(s.commanded), 0.0).max(axis=0)),
                   acc.saturated + (ok & clipped).sum(axis=0), max_norm[-1], np.maximum(acc.above, above),
                   np.where(any_ok, np.where(ok, k, -1.0).max(axis=0), acc.k_last))


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
            "max_abs_error": acc.max_abs_e.tolist(), "max_abs_torque": acc.max_abs_tau.tolist(),
            "max_abs_commanded_torque": acc.max_abs_commanded.tolist(),
            "saturated_fraction": float(acc.saturated) / count,
            "convergence_time": 0.0 if above < 0 else None if above == int(acc.k_last) else above * h}
