"""Monitors against the theory (spec §11): dV/dt ≤ 0 for Slotine–Li and not under a disturbance (6.7.2); the passivity
integral (6.4.4) equals V_φ(t) − V_φ(0) for the gradient law, with β = ½ φ̃(0)ᵀ Γ⁻¹ φ̃(0); λ_min(P⁻¹) of the composite
law is λ_min(P0⁻¹ + ∫ W_fᵀ W_f) (6.6.25); the convergence time on closed forms.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_simpson

from robotadapt.analysis.metrics import metrics
from robotadapt.analysis.monitors import convergence_time, lyapunov_increase_fraction, monitor_metrics
from robotadapt.sim.outputs import controller_series
from robotadapt.studies.scenarios import load

PHI = np.array([0.8, 2.3])  # Example 6.3.1


def run(name: str, *overrides: str):
    scenario = load(name, list(overrides))
    res = scenario.run()
    series = controller_series(res, scenario.setup.controller)
    return scenario, res, series, monitor_metrics(res, series)


def test_slotine_li_monitors_on_example_6_3_1():
    """Gradient law with φ̂(0) = 0, Γ = 20 I: β = ½ ‖φ‖²/20; ∫ −rᵀYφ̃ = V_φ(t) − V_φ(0) exactly (Example 6.4.1), so the
    integral stays above −β and reaches it as φ̂ → φ; V never increases (6.3.17)."""
    _, res, series, m = run("example-6.3.1", "simulation.t_final=3", "simulation.dt=2.5e-4")
    beta = 0.5 * PHI @ PHI / 20.0
    assert m["passivity_beta"] == pytest.approx(beta, rel=1e-12)
    assert m["passivity_holds"] and m["passivity_min"] >= -beta * (1 + 1e-3)
    V_phi = series["parameter_lyapunov"]
    np.testing.assert_allclose(V_phi, 0.5 * ((PHI - res.phi_hat) ** 2).sum(axis=-1) / 20.0, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(res.passivity, V_phi - V_phi[0], atol=1e-6 * beta)  # Simpson on 0.25 ms samples
    assert m["lyapunov_increase_fraction"] == 0.0
    assert m["phi_error_initial"] == pytest.approx(np.linalg.norm(PHI))
    assert m["phi_error_max"] >= m["phi_error_initial"]
    assert 0.0 < m["convergence_time"] < 3.0
    assert "lambda_min_P_inv_initial" not in m  # no least squares here


def test_a_disturbance_makes_V_increase():
    """Example 6.7.1: V̇ = −rᵀK_v r + rᵀT_d (6.7.2) is positive at times, and the monitor sees it."""
    _, _, _, m = run("example-6.7.1", "simulation.t_final=3")
    assert m["lyapunov_increase_fraction"] > 0.05


def test_composite_lambda_min_P_inv_is_the_integral_of_Wf(tmp_path):
    """Without forgetting P⁻¹(t) = P0⁻¹ + ∫ W_fᵀ W_f (6.6.25): λ_min(P⁻¹) starts at 1/10 and grows under sin t."""
    scenario, res, series, m = run("example-6.6.3", "simulation.t_final=5")
    ctrl = scenario.setup.controller
    assert m["lambda_min_P_inv_initial"] == pytest.approx(0.1)
    Wf = ctrl.filtered_regressor(res.x, res.q, res.dq)
    integral = cumulative_simpson(np.einsum("tni,tnk->tik", Wf, Wf), x=res.t, axis=0, initial=0.0)
    expected = np.linalg.eigvalsh(np.linalg.inv(ctrl.P0) + integral)[:, 0]
    np.testing.assert_allclose(series["lambda_min_P_inv"], expected, rtol=1e-5)
    assert m["lambda_min_P_inv_final"] > 10 * m["lambda_min_P_inv_initial"]
    assert m["passivity_holds"]  # the composite law is passive too: ∫ −rᵀYφ̃ = ΔV_φ + ½∫‖W_f φ̃‖² ≥ −V_φ(0)


def test_a_fixed_estimate_law_has_no_lyapunov_or_passivity_monitor_and_does_not_converge():
    _, _, series, m = run("example-6.2.1", "simulation.t_final=8")
    assert series == {}
    assert "lyapunov_increase_fraction" not in m and "passivity_min" not in m
    assert m["convergence_time"] is None  # Example 6.2.1: bounded error that does not decay
    assert m["phi_error_initial"] == m["phi_error_max"] == pytest.approx(np.hypot(0.05, 0.1))


def test_convergence_time_and_increase_fraction_on_closed_forms():
    t = np.linspace(0.0, 10.0, 10001)
    e = np.exp(-t)[:, None] * np.array([0.6, 0.8])  # ‖e‖ = e^{−t}: below 1 % of its maximum after ln 100
    assert convergence_time(t, e) == pytest.approx(np.log(100.0), abs=1e-3)
    assert convergence_time(t, np.sin(t)[:, None]) is None
    assert convergence_time(t, np.zeros((t.size, 2))) == 0.0
    assert lyapunov_increase_fraction(np.array([1.0, 0.5, 0.6, 0.4])) == pytest.approx(1 / 3)
    assert lyapunov_increase_fraction(np.array([1.0, 1.0 + 1e-12, 0.9])) == 0.0  # round-off is not an increase


def test_every_run_carries_its_monitors_in_metrics():
    """Issue 5: the Lyapunov, passivity and least-squares monitors reach metrics.json through every run."""
    from robotadapt.studies.scenarios import load

    m = metrics(load("example-6.6.3", ["simulation.t_final=2"]).run())
    assert m["lambda_min_P_inv_final"] > m["lambda_min_P_inv_initial"] > 0
    assert m["passivity_holds"] is True and m["lyapunov_increase_fraction"] == 0.0
