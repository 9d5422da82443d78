"""Analysis of runs: tracking and parameter metrics, Lyapunov monitor (the laws' proofs, docs/laws.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..arrays import array_namespace
from ..robots.consistency import consistency_metrics

if TYPE_CHECKING:
    from ..robots.base import RobotModel
    from ..robots.identifiability import BaseParameters
    from ..sim.result import SimulationResult

#: base parameters by model identity: id → (the model, kept alive so the id stays its own; its base parameters or None)
_BASES: dict[int, tuple[Any, BaseParameters | None]] = {}


def _list(a: Any) -> Any:
    return np.asarray(a, dtype=float).tolist()


def lyapunov_increase(V: np.ndarray) -> float:
    """Largest step-to-step increase of V(t) relative to max(V(0), 1e-12): ≤ round-off for a proof that gives V̇ ≤ 0."""
    if V.size < 2:
        return 0.0
    return float(max(np.max(np.diff(V)), 0.0) / max(float(V[0]), 1e-12))


#: the objectives `robotadapt tune` minimises (docs/tuning.md) → the key of :func:`metrics` that holds each
OBJECTIVES = {"rms_error": "rms_error_norm", "ise": "ise", "final_error": "final_error_norm", "energy": "control_energy"}


def objective_terms(t: Any, e: Any, tau: Any) -> dict[str, Any]:
    """The run's objectives and its peak torque from the logged samples (numpy or JAX arrays: the tuner differentiates
    the very same code that scores a run): `rms_error` √(mean_k ‖e(t_k)‖²), `ise` ∫‖e‖² dt, `final_error` ‖e(t_final)‖,
    `energy` ∫ τᵀτ dt (trapezoid rule over the samples) and `max_abs_torque` max over joints and samples of |τ_i(t_k)|.
    """
    xp = array_namespace(e, tau)
    square = (e**2).sum(axis=-1)
    power = (tau**2).sum(axis=-1)
    many = t.shape[0] > 1
    return {"rms_error": xp.sqrt(xp.mean(square)), "ise": xp.trapezoid(square, t) if many else 0.0 * square[0],
            "final_error": xp.sqrt(square[-1]), "energy": xp.trapezoid(power, t) if many else 0.0 * power[0],
            "max_abs_torque": xp.max(xp.abs(tau))}


def base_of(model: RobotModel | None) -> BaseParameters | None:
    """The base parameters of `model` (:func:`robotadapt.robots.base_parameters`) when it has fewer than its p standard
    parameters, else None; computed once per model object. Models with no more parameters than joints (the book's
    arms: the two-link arm's m1, m2) are skipped without sampling: their columns are taken as independent."""
    if model is None or model.p <= model.n:
        return None
    hit = _BASES.get(id(model))
    if hit is None or hit[0] is not model:
        from ..robots.identifiability import base_parameters

        basis = base_parameters(model)
        hit = (model, basis if basis.count < model.p else None)
        _BASES[id(model)] = hit
    return hit[1]


def base_metrics(res: SimulationResult, model: RobotModel | None) -> dict[str, Any]:
    """For a model with unidentifiable directions (p_b < p): `base_parameters` p_b, `base_param_names`,
    `unidentifiable_directions` p − p_b, and when the truth is known `final_base_phi_error` ‖K(φ − φ̂)‖ at the end and
    `final_base_phi_error_relative` ‖K(φ − φ̂)‖ / ‖K φ‖ (what the dynamics can see of the estimate's error). Empty
    otherwise, or when `model` is not the run's controller model (another parameter count)."""
    basis = base_of(model)
    if basis is None or res.phi_hat.shape[-1] != basis.K.shape[1]:
        return {}
    out: dict[str, Any] = {"base_parameters": basis.count, "base_param_names": list(basis.names),
                           "unidentifiable_directions": basis.K.shape[1] - basis.count}
    truth = res.phi_true
    if truth is not None:
        err = float(np.linalg.norm(basis.base(truth[-1] - res.phi_hat[-1])))
        size = float(np.linalg.norm(basis.base(truth[-1])))
        out["final_base_phi_error"] = err
        out["final_base_phi_error_relative"] = err / size if size > 0 else None
    return out


def saturated_fraction(commanded: np.ndarray, applied: np.ndarray) -> float:
    """The share of the logged control instants (every tick or step at `log_every` = 1) at which the actuator changed
    the command on any joint (a torque or rate limit clipped it): |τ − u| > 1e-9·(1 + |τ|)."""
    clipped = np.any(np.abs(commanded - applied) > 1e-9 * (1.0 + np.abs(commanded)), axis=-1)
    return float(np.mean(clipped)) if clipped.size else 0.0


#: the wind-up warning: the torque sat on its limit over this share of the run, and ‖φ̂‖ grew this many times beyond its
#: start (and beyond ‖φ‖ when known); the same share alone is the saturation warning, the same growth alone the drift one
WINDUP_SATURATED, WINDUP_GROWTH = 0.5, 10.0
LYAPUNOV_GROWTH = 10.0  #: V(t_final) beyond this many times V(0): the warning that V grew where the theory has V̇ ≤ 0
SINGULAR = 0.01  #: m/rad: σ_min of the hand's Jacobian below this, the arm passes near a singularity (a task-space law)


def health_warnings(m: dict[str, Any]) -> list[str]:
    """What the summary line warns of, from a run's metrics, each with its remedy: integrator wind-up (the torque on its
    limit most of the run while the estimates grew far beyond their start); else saturation alone (the numbers are the
    actuator's, not the law's) and estimate drift alone (‖φ̂‖ ending far beyond its start: a transient that settles is
    not drift); and V(t_final) ≫ V(0)."""
    out = []
    sat, grown = float(m.get("saturated_fraction") or 0.0), float(m.get("max_phi_hat_norm") or 0.0)
    start = max(float(np.linalg.norm(m.get("initial_phi_hat", [0.0]))), float(np.linalg.norm(m.get("phi_true", [0.0]))),
                1e-12)
    final = float(np.linalg.norm(m.get("final_phi_hat", [0.0])))
    saturated, grew = sat > WINDUP_SATURATED, grown > WINDUP_GROWTH * start
    if saturated and grew:
        out.append(f"wind-up: the torque sat on its limit {100 * sat:.0f} % of the run and ‖φ̂‖ grew to {grown:.4g} "
                   f"(from {start:.4g}); the update law integrates an error the saturated torque cannot remove — use a "
                   "law that filters the applied torque (controller kind 'composite'), σ-modification (law kind "
                   "'sigma') or a projection box (controller.phi_min, phi_max)")
    elif saturated:
        out.append(f"saturation: the torque sat on its limit {100 * sat:.0f} % of the run, so these numbers are the "
                   "actuator's, not the law's — raise plant.torque_limit, lower the gains or slow the trajectory")
    elif final > WINDUP_GROWTH * start:  # not a transient: the estimate ends far out
        out.append(f"estimate drift: ‖φ̂‖ ends at {final:.4g} (from {start:.4g}) — σ-modification (law kind 'sigma') or a "
                   "projection box (controller.phi_min, phi_max) bounds it")
    v0, v1 = m.get("V_initial"), m.get("V_final")
    if v0 is not None and v1 is not None and v1 > LYAPUNOV_GROWTH * max(v0, 1e-300) and \
            "lyapunov_not_applicable" not in m:  # a law that holds φ̂: V is no Lyapunov function of its loop
        out.append(f"Lyapunov growth: V grew from {v0:.4g} to {v1:.4g} where the theory has V̇ ≤ 0 — its assumptions fail "
                   "here (a torque limit, a disturbance, measurement noise, unmodelled dynamics, sampling)")
    if m.get("near_singularity_t") is not None:
        out.append(f"singularity: the hand's Jacobian fell to σ_min = {m['min_hand_sigma']:.3g} (below {SINGULAR:g}) at "
                   f"t = {m['near_singularity_t']:.4g} s, where only the damping (controller.damping) keeps J⁺ finite — "
                   "keep the path away from the arm's stretched or folded poses")
    return out


def metrics(res: SimulationResult, model: RobotModel | None = None) -> dict[str, Any]:
    """Per-joint tracking metrics, torque and energy, final estimate, parameter error and Lyapunov monitor.

    `final_abs_error` is |e| at the last logged instant, per joint; `rms_error` the RMS of e over the logged samples,
    **per joint**: √(mean_k e_i(t_k)²), one entry per joint (rad or m); `rms_error_norm` the one scalar
    √(mean_k ‖e(t_k)‖²) = √(Σ_i rms_error_i²), what `robotadapt compare` tabulates as "RMS ‖e‖"; `ise` ∫‖e‖² dt;
    `final_error_norm` ‖e(t_final)‖; `max_abs_torque` max |τ| per joint; `control_energy` ∫ τᵀτ dt (the objectives of
    `robotadapt tune` come from :func:`objective_terms`, the same code the tuner differentiates); `stop` (a run that
    did not finish: its Status as a record, code, t, t_end, reason); `saturated_fraction`
    (:func:`saturated_fraction`, with an actuator) and `max_phi_hat_norm` max ‖φ̂‖ over the run; `final_phi_error`
    ‖φ − φ̂‖ at the end when the truth is known; `lyapunov_max_rel_increase` the largest step increase of V relative to
    V(0); `min_pseudo_inertia_eigenvalue`, `physically_consistent`, `left_consistent_set_t`,
    `left_consistent_set_part`, `consistency_parts` and `final_min_eigenvalues` of φ̂
    (:func:`robotadapt.robots.consistency.consistency_metrics`). With the controller's `model`, when its dynamics see
    fewer combinations than its parameters (an n-DOF arm),
    also the base-parameter keys of :func:`base_metrics`.

    A fixed-step run folds its error and torque metrics at every step or tick (`res.running`,
    :mod:`robotadapt.sim.running`): `rms_error`, `rms_error_norm`, `ise`, `control_energy`, `max_abs_error`,
    `max_abs_torque`, `max_abs_commanded_torque`, `saturated_fraction` and `convergence_time` are then those of every
    instant of the run grid, whatever `simulation.log_every` (the logged samples give the same numbers at log_every = 1).
    """
    e, t, tau = res.e, res.t, res.tau
    terms = {k: float(v) for k, v in objective_terms(t, e, tau).items()}
    out: dict[str, Any] = {
        "status": str(res.status),
        "t_end": float(t[-1]),
        "n_samples": int(t.size),
        "final_abs_error": _list(np.abs(e[-1])),
        "final_abs_velocity_error": _list(np.abs(res.de[-1])),
        "max_abs_error": _list(np.max(np.abs(e), axis=0)),
        "rms_error": _list(np.sqrt(np.mean(e**2, axis=0))),
        "rms_error_norm": terms["rms_error"],
        "ise": terms["ise"],
        "final_error_norm": terms["final_error"],
        "max_abs_torque": _list(np.max(np.abs(tau), axis=0)),
        "control_energy": terms["energy"],
        "param_names": list(res.param_names),
        "initial_phi_hat": _list(res.phi_hat[0]),
        "final_phi_hat": _list(res.phi_hat[-1]),
        "wall_time_s": res.wall_time,
    }
    if res.status.code != "ok":  # the stop as a record: when (t, or the step from t to t_end) and why
        out["stop"] = res.status.record()
    if "tau_commanded" in res.monitors:
        commanded = res.monitors["tau_commanded"]
        out["max_abs_commanded_torque"] = _list(np.max(np.abs(commanded), axis=0))
        out["saturated_fraction"] = saturated_fraction(commanded, tau)
    norms = np.linalg.norm(res.phi_hat, axis=-1)
    out["max_phi_hat_norm"] = float(norms.max()) if norms.size else 0.0
    for key in ("plant", "sampling"):  # the real-world effects and the control period the run had
        if key in res.info:
            out[key] = res.info[key]
    if res.phi is not None:
        out["phi_true"] = _list(res.phi)
        out["final_phi_error"] = float(np.linalg.norm(res.phi - res.phi_hat[-1]))
    out.update(base_metrics(res, model))
    out.update(consistency_metrics(t, res.phi_hat, res.param_names))
    if res.V is not None:
        out["V_initial"] = float(res.V[0])
        out["V_final"] = float(res.V[-1])
        out["lyapunov_max_rel_increase"] = lyapunov_increase(res.V)
        if "lyapunov_caveat" in res.info:
            out["lyapunov_not_applicable"] = res.info["lyapunov_caveat"]
    from .monitors import monitor_metrics

    out.update(monitor_metrics(res, res.monitors))
    out.update(task_metrics(res, out))
    out.update({k: v for k, v in (res.running or {}).items() if k in out})  # every step's, not the logged samples'
    if res.space == "task":  # the hand's error in metres, under the names a task-space user looks for
        out.update(task_rms_error=out["rms_error_norm"], task_final_error=out["final_error_norm"],
                   task_max_error=out["max_error_norm"])
    return out


def task_metrics(res: SimulationResult, m: dict[str, Any]) -> dict[str, Any]:
    """What a task-space law's run adds (docs/task-space.md): `error_space` "task" (its e is x_d − x, metres),
    `max_error_norm` max ‖e‖, `min_hand_sigma` the smallest singular value of the hand's Jacobian over the logged
    instants and `near_singularity_t` the first instant it was below :data:`SINGULAR` (None: never), and for a law
    that estimates kinematic parameters (the adaptive Jacobian) their names, `final_theta_hat` and `theta_true` (m).
    `task_rms_error`, `task_final_error` and `task_max_error` (m) are `rms_error_norm`, `final_error_norm` and
    `max_error_norm` of every step (:func:`metrics`)."""
    if res.space != "task":
        return {}
    out: dict[str, Any] = {"error_space": "task",
                           "max_error_norm": float(np.max(np.linalg.norm(res.e, axis=-1)))}
    if "hand_sigma_min" in res.monitors:  # where the arm passed near a singularity (docs/task-space.md)
        sigma = res.monitors["hand_sigma_min"]
        near = np.flatnonzero(sigma < SINGULAR)
        out["min_hand_sigma"] = float(sigma.min())
        out["near_singularity_t"] = float(res.t[near[0]]) if near.size else None
    if "theta_hat" in res.monitors:
        out["kinematic_names"] = [name[len("theta_hat["):-1] for name in res.state_names if name.startswith("theta_hat[")]
        out["final_theta_hat"] = _list(res.monitors["theta_hat"][-1])
        out["theta_true"] = _list(res.monitors["theta_true"][-1])
    return out
