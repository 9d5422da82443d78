"""Analysis of runs: tracking and parameter metrics, Lyapunov monitor (spec §11)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..sim.result import SimulationResult


def _list(a: Any) -> Any:
    return np.asarray(a, dtype=float).tolist()


def lyapunov_increase(V: np.ndarray) -> float:
    """Largest step-to-step increase of V(t) relative to max(V(0), 1e-12): ≤ round-off for a proof that gives V̇ ≤ 0."""
    if V.size < 2:
        return 0.0
    return float(max(np.max(np.diff(V)), 0.0) / max(float(V[0]), 1e-12))


def metrics(res: SimulationResult) -> dict[str, Any]:
    """Per-joint tracking metrics, torque and energy, final estimate, parameter error and Lyapunov monitor.

    `final_abs_error` is |e| at the last logged instant, per joint; `rms_error` the RMS of e over the logged samples,
    **per joint**: √(mean_k e_i(t_k)²), one entry per joint (rad or m); `rms_error_norm` the one scalar
    √(mean_k ‖e(t_k)‖²) = √(Σ_i rms_error_i²), what `robotadapt compare` tabulates as "RMS ‖e‖"; `max_abs_torque`
    max |τ| per joint; `control_energy` ∫ τᵀτ dt; `final_phi_error` ‖φ − φ̂‖ at the end when the truth is known;
    `lyapunov_max_rel_increase` the largest step increase of V relative to V(0).
    """
    e, t, tau = res.e, res.t, res.tau
    out: dict[str, Any] = {
        "status": res.status,
        "t_end": float(t[-1]),
        "n_samples": int(t.size),
        "final_abs_error": _list(np.abs(e[-1])),
        "final_abs_velocity_error": _list(np.abs(res.de[-1])),
        "max_abs_error": _list(np.max(np.abs(e), axis=0)),
        "rms_error": _list(np.sqrt(np.mean(e**2, axis=0))),
        "rms_error_norm": float(np.sqrt(np.mean(np.sum(e**2, axis=-1)))),
        "max_abs_torque": _list(np.max(np.abs(tau), axis=0)),
        "control_energy": float(np.trapezoid(np.sum(tau**2, axis=-1), t)) if t.size > 1 else 0.0,
        "param_names": list(res.param_names),
        "final_phi_hat": _list(res.phi_hat[-1]),
        "wall_time_s": res.wall_time,
    }
    if "tau_commanded" in res.monitors:
        out["max_abs_commanded_torque"] = _list(np.max(np.abs(res.monitors["tau_commanded"]), axis=0))
    for key in ("plant", "sampling"):  # the real-world effects and the control period the run had
        if key in res.info:
            out[key] = res.info[key]
    if res.phi is not None:
        out["phi_true"] = _list(res.phi)
        out["final_phi_error"] = float(np.linalg.norm(res.phi - res.phi_hat[-1]))
    if res.V is not None:
        out["V_initial"] = float(res.V[0])
        out["V_final"] = float(res.V[-1])
        out["lyapunov_max_rel_increase"] = lyapunov_increase(res.V)
    from .monitors import monitor_metrics

    out.update(monitor_metrics(res, res.monitors))
    return out
