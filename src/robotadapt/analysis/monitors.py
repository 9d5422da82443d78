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
PASSIVITY_RTOL = 1e-3  # Simpson on 1 ms samples of the fast initial transient: errors ~1e-4·β, falling as dt⁴


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
    """The monitors as numbers: `lyapunov_increase_fraction` (where V is defined); `passivity_min`, `passivity_beta`
    (β = V_φ(0)) and `passivity_holds` (min ∫ ≥ −β up to 1e-3·β of quadrature error) where the passivity integral is
    defined; `lambda_min_P_inv_initial` / `_final` for least squares; `phi_error_initial` / `_max` when φ is known;
    `convergence_time` (s, None if ‖e‖ is still above 1 % of its maximum at the end)."""
    out: dict[str, Any] = {"convergence_time": convergence_time(res.t, res.e)}
    if res.V is not None:
        out["lyapunov_increase_fraction"] = lyapunov_increase_fraction(res.V)
    if res.passivity is not None:
        out["passivity_min"] = float(res.passivity.min())
        if "parameter_lyapunov" in series:
            beta = float(series["parameter_lyapunov"][0])
            out["passivity_beta"] = beta
            out["passivity_holds"] = bool(out["passivity_min"] >= -beta * (1 + PASSIVITY_RTOL))
    if "lambda_min_P_inv" in series:
        out["lambda_min_P_inv_initial"] = float(series["lambda_min_P_inv"][0])
        out["lambda_min_P_inv_final"] = float(series["lambda_min_P_inv"][-1])
    if res.phi_err is not None:
        norm = np.linalg.norm(res.phi_err, axis=-1)
        out["phi_error_initial"] = float(norm[0])
        out["phi_error_max"] = float(norm.max())
    return out

