"""Monitors of a run against its stability proof (docs/laws.md, the laws' proofs): the sign of dV/dt, the passivity
integral (6.4.4) against
its bound −β, λ_min(P⁻¹) for least squares (6.6.27), ‖φ̃‖ when the truth is known, and the time the error takes to
converge.

:func:`robotadapt.sim.outputs.controller_series` evaluates the signals that need the controller (stored in a result's
`monitors`);
:func:`monitor_metrics` turns a result and those signals into JSON-ready numbers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..sim.result import SimulationResult

Array = np.ndarray
V_ROUNDOFF = 1e-9  # an increase of V by more than this times V(0) in one step is not round-off
CONVERGED = 0.01  # converged: ‖e‖ stays below 1 % of its maximum
PASSIVITY_RTOL = 1e-6  # the integral is carried in the integrated state: RK4's error on it, ~dt⁴, not quadrature's


def lyapunov_increase_fraction(V: Array, rtol: float = V_ROUNDOFF) -> float:
    """The fraction of logged steps over which V increases by more than `rtol`·max(V(0), 1e-12): 0 for a proof that
    gives dV/dt ≤ 0, up to the integrator's error."""
    if V.size < 2:
        return 0.0
    return float(np.mean(np.diff(V) > rtol * max(float(V[0]), 1e-12)))


def convergence_time(t: Array, e: Array, fraction: float = CONVERGED) -> float | None:
    """The last logged time at which ‖e(t)‖ exceeds `fraction` of its maximum (0 if never after the start), or None if
    it still does at the end (no convergence within the run)."""
    norm = np.linalg.norm(e, axis=-1)
    above = np.nonzero(norm > fraction * norm.max())[0]
    if above.size == 0:
        return 0.0
    if above[-1] == norm.size - 1:
        return None
    return float(t[above[-1]])


def monitor_metrics(res: SimulationResult, series: dict[str, Array]) -> dict[str, Any]:
    """The monitors as numbers: `lyapunov_increase_fraction` (where V is defined); where the passivity integral is
    defined, `passivity_min` (its minimum over every integration step or control tick, carried in the run's state, so
    it does not depend on the logging rate), `passivity_beta` (β = V_φ(0)), `passivity_holds` (min ≥ −β up to 1e-6·β of
    integration error; where the true φ changed mid-run, min ≥ −β − `passivity_truth_change`, the sum of V_φ's upward
    jumps at the changes, since (6.4.4) is for a constant φ) and `passivity_form`: "integral" (continuous time: ∫
    −rᵀZφ̃ dt at the integration step) or "tick sum" (sampled-data: Σ_k Ts·(−r_kᵀ Z_k φ̃_k) over the ticks, the sum
    that matches the discrete update; then `passivity_update_excess` = V_φ(t_end) − V_φ(0) − Σ, what the discrete
    update added to V_φ beyond the sum: for the Euler gradient law ½Ts²·(Z_kᵀr_k)ᵀΓ(Z_kᵀr_k) ≥ 0 per tick, why (6.4.4)
    can genuinely fail in sampled time). Where the law's gains do not imply the claim (`info["passivity_caveat"]`, e.g.
    σ-modification with S = I and a non-scalar Γ), `passivity_holds` is None and `passivity_not_applicable` gives the
    reason. `lambda_min_P_inv_initial` / `_final` for least squares; `phi_error_initial` / `_max` when φ is known;
    `convergence_time` (s, None if ‖e‖ is still above 1 % of its maximum at the end)."""
    out: dict[str, Any] = {"convergence_time": convergence_time(res.t, res.e)}
    if res.V is not None:
        out["lyapunov_increase_fraction"] = lyapunov_increase_fraction(res.V)
    if res.passivity is not None:
        running = series.get("passivity_running_min")
        out["passivity_min"] = float(res.passivity.min() if running is None else running[-1])
        sampled = "sampling" in res.info
        out["passivity_form"] = "tick sum" if sampled else "integral"
        if "parameter_lyapunov" in series:
            V_phi = series["parameter_lyapunov"]
            beta = float(V_phi[0])
            out["passivity_beta"] = beta
            bound = beta
            if "parameter_lyapunov_jump" in series:  # the truth changed mid-run: V_φ jumped with it
                out["passivity_truth_change"] = float(np.maximum(series["parameter_lyapunov_jump"], 0.0).sum())
                bound += out["passivity_truth_change"]
            out["passivity_holds"] = bool(out["passivity_min"] >= -bound * (1 + PASSIVITY_RTOL))
            if sampled:
                out["passivity_update_excess"] = float(V_phi[-1] - beta - res.passivity[-1])
        if "passivity_caveat" in res.info:
            out["passivity_holds"] = None
            out["passivity_not_applicable"] = res.info["passivity_caveat"]
    if "lambda_min_P_inv" in series:
        out["lambda_min_P_inv_initial"] = float(series["lambda_min_P_inv"][0])
        out["lambda_min_P_inv_final"] = float(series["lambda_min_P_inv"][-1])
    if res.phi_err is not None:
        norm = np.linalg.norm(res.phi_err, axis=-1)
        out["phi_error_initial"] = float(norm[0])
        out["phi_error_max"] = float(norm.max())
    return out

