"""The numbers a user reads are the theory's, whatever the logging rate (issue 22): the passivity integral (6.4.4)
against ½φ̃ᵀΓ⁻¹φ̃ at both ends, its sampled-data tick sum against the discrete update written out, the bound with a
truth that changes mid-run, the composite law's filter of the held torque written out, its filter's first state,
σ-modification's caveat, and the wind-up warning. Each reference is written here from the equations."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.cli.common import summary
from robotadapt.controllers import Composite
from robotadapt.controllers.adaptation import SwitchingSigma
from robotadapt.controllers.passivity import PassivityBased, pid_servo
from robotadapt.plant import Plant
from robotadapt.plant.sensors import Sensor
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, Sampled, simulate
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid

GAMMA, PHI = 20.0, np.array([0.8, 2.3])  # Example 6.3.1: Γ = 20 I, the true masses


def run(name: str, *overrides: str):
    loaded = load(name, list(overrides))
    return loaded.run(), loaded.setup


def slotine_li_terms(res, ctrl):
    """y_k = Y_kᵀ r_k (6.3.11) at the logged states, from the controller's regressor."""
    Y, r = ctrl.regressor(res.t, res.x, res.q, res.dq, sinusoid(2)(res.t))
    return np.einsum("tkj,tk->tj", Y, r)


def V_phi(phi_hat: np.ndarray, phi: np.ndarray = PHI) -> np.ndarray:
    """½ φ̃ᵀ Γ⁻¹ φ̃ with Γ = γ I."""
    tilde = phi - phi_hat
    return 0.5 * (tilde * tilde).sum(axis=-1) / GAMMA


def test_passivity_is_the_exact_identity_at_any_logging_rate():
    """Slotine–Li: d/dt ½φ̃ᵀΓ⁻¹φ̃ = −rᵀYφ̃ exactly, so ∫₀ᵗ −rᵀYφ̃ = V_φ(t) − V_φ(0) (docs/laws.md#slotine-li). At
    log_every = 1, 10 and 100 the run's integral is that identity, written here from φ̂ at the logged instants, to
    RK4's error, and its minimum and verdict are the same (main before: −0.1482, −0.0707, −19.84 "does not hold")."""
    mins = {}
    for every in (1, 10, 100):
        res, _ = run("example-6.3.1", "simulation.t_final=3", f"simulation.log_every={every}")
        identity = V_phi(res.phi_hat) - V_phi(res.phi_hat[0])
        np.testing.assert_allclose(res.passivity, identity, rtol=0, atol=2e-5 * V_phi(res.phi_hat[0]))  # RK4: 8e-6 β
        m = metrics(res)
        assert m["passivity_form"] == "integral" and m["passivity_holds"] is True
        assert m["passivity_beta"] == pytest.approx(V_phi(np.zeros(2)), rel=1e-12)
        mins[every] = m["passivity_min"]
    assert mins[10] == pytest.approx(mins[1], rel=1e-6) and mins[100] == pytest.approx(mins[1], rel=1e-6)
    assert mins[1] == pytest.approx(-V_phi(np.zeros(2)), rel=1e-3)  # φ̂ converges: the integral tends to −β


@pytest.mark.parametrize("limit", [None, 400.0], ids=["unlimited", "limit-400"])
def test_sampled_passivity_is_the_tick_sum_and_the_excess_the_euler_term(limit):
    """Sampled (Ts = 5 ms, Euler): the integral is Σ_k Ts·(−y_kᵀφ̃_k) over the ticks before the one logged, and the
    discrete gradient step φ̂_{k+1} = φ̂_k + Ts Γ y_k adds V_φ(k+1) − V_φ(k) = −Ts y_kᵀφ̃_k + ½Ts² y_kᵀΓy_k, so
    V_φ(end) − β − Σ = Σ ½Ts² γ‖y_k‖² (`passivity_update_excess`), both written out here from the logged ticks. With
    V_φ ≥ 0 bounds the sum by −β − excess only; with a 400 N·m limit (6.4.4) genuinely fails, by far more than
    RK4's error: main before reported −13.0 from Simpson over the logged ticks."""
    Ts = 0.005
    extra = [] if limit is None else [f"plant.torque_limit={limit}"]
    res, setup = run("example-6.3.1", "simulation.t_final=3", f"simulation.control_period={Ts}", *extra)
    y = slotine_li_terms(res, setup.controller)
    dissipation = -(y * (PHI - res.phi_hat)).sum(axis=-1)
    np.testing.assert_allclose(res.passivity, np.concatenate([[0.0], np.cumsum(Ts * dissipation)[:-1]]),
                               rtol=1e-9, atol=1e-12)
    m = metrics(res)
    assert m["passivity_form"] == "tick sum"
    euler = 0.5 * Ts**2 * GAMMA * (y[:-1] * y[:-1]).sum()
    assert m["passivity_update_excess"] == pytest.approx(euler, rel=1e-8)
    assert m["passivity_min"] == pytest.approx(res.passivity.min(), rel=1e-12)
    assert m["passivity_min"] >= -m["passivity_beta"] - euler  # V_φ ≥ 0: the discrete bound the identity implies
    if limit is not None:
        assert m["passivity_holds"] is False and m["passivity_min"] < -m["passivity_beta"] - 10.0
        assert m["passivity_update_excess"] > 10.0


def test_a_payload_changes_the_bound_by_the_jump_of_V_phi():
    """payload-change (m2: 2.3 → 3.3 kg at 5 s, Slotine–Li, Γ = 20 I): β = V_φ(0) with the arm as it was at t = 0
    (main before: −4.35, with the final masses), and where φ jumps, V_φ jumps by ½(φ₊ − φ̂)ᵀΓ⁻¹(φ₊ − φ̂) −
    ½(φ₋ − φ̂)ᵀΓ⁻¹(φ₋ − φ̂) at φ̂(5 s), so the integral stays above −β − that jump; both written out here."""
    res, _ = run("payload-change", "simulation.t_final=8", "simulation.log_every=10")
    m = metrics(res)
    assert m["passivity_beta"] == pytest.approx(V_phi(np.zeros(2)), rel=1e-12)
    k = int(np.searchsorted(res.t, 5.0 - 1e-9))
    assert res.t[k] == pytest.approx(5.0)
    after = np.array([0.8, 3.3])
    jump = V_phi(res.phi_hat[k], after) - V_phi(res.phi_hat[k])
    assert jump > 0.0 and m["passivity_truth_change"] == pytest.approx(jump, rel=1e-9)
    assert m["passivity_holds"] is True and m["passivity_min"] < -m["passivity_beta"]  # the bound is needed
    after_change = res.t >= 5.0
    identity = V_phi(res.phi_hat, np.where(after_change[:, None], after, PHI)) - V_phi(res.phi_hat[0]) - np.where(
        after_change, jump, 0.0)
    np.testing.assert_allclose(res.passivity, identity, rtol=0, atol=1e-5)  # RK4: 1.1e-6


@pytest.mark.parametrize("limit", [None, 1e9], ids=["no-actuator", "non-binding-limit"])
def test_the_composite_law_filters_the_held_torque(limit):
    """Example 6.6.3 at Ts = 2 ms, "hold" rule: the law's filter is dτ_f/dt = −a τ_f + a u_k over each tick with the
    held u_k, so τ_f(k+1) = e^{−a Ts} τ_f(k) + (1 − e^{−a Ts}) u_k, written here from the logged torque, and τ_f = W_f φ
    (main before, without an actuator: ‖τ_f − W_f φ‖ up to 6.1e-3, the filter fed the torque re-evaluated inside the
    tick; 1.1e-16 with the limit)."""
    Ts = 0.002
    extra = [] if limit is None else [f"plant.torque_limit={limit}"]
    res, setup = run("example-6.6.3", "simulation.t_final=4", f"simulation.control_period={Ts}",
                     "simulation.discretization=hold", *extra)
    ctrl = setup.controller
    tau_f = ctrl._split(res.x)[2]
    decay = np.exp(-ctrl.a * Ts)
    np.testing.assert_allclose(tau_f[1:], decay * tau_f[:-1] + (1 - decay) * res.tau[:-1], rtol=0, atol=1e-12)
    Wf = ctrl.filtered_regressor(res.x, res.q, res.dq)
    assert np.abs(tau_f - Wf @ np.array([1.0, 1.0])).max() < 1e-12


def test_the_composite_filter_starts_from_the_first_measurement():
    """With a noisy encoder, the composite law's filter state Z3(0) = a Y_h(q_m(0), q̇_m(0)) is built from what the law
    measures at tick 0, not from the true (q0, q̇0) it cannot know, so W_f(0) = a Y_h(q_m(0), q̇_m(0)) − Z3(0) = 0."""
    arm = TwoLinkArm()
    sensor = Sensor(2, noise_q=1e-3, velocity="difference", seed=3)
    plant = Plant(arm, PHI, sensor=sensor)
    ctrl = Composite(arm, Lam=2.5, Kv=10.0, a=5.0, P0=10.0, phi_hat0=[0.0, 0.0])
    res = simulate(plant, ctrl, sinusoid(2), t_final=0.02, integrator=Sampled(0.002), q0=[0.1, -0.2])
    q_m, dq_m = res.monitors["q_measured"][0], res.monitors["dq_measured"][0]
    assert np.abs(q_m - [0.1, -0.2]).max() > 1e-4  # the noise is there
    Z3 = ctrl._split(res.x[0])[3]
    np.testing.assert_allclose(Z3, 5.0 * arm.momentum_regressor(q_m, dq_m), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(ctrl.filtered_regressor(res.x[0], q_m, dq_m), 0.0, atol=1e-14)


def test_sigma_modification_with_a_non_scalar_gain_is_reported_not_applicable():
    """The book's σ-modification (S = I) with Γ = diag(100, 1): dV_φ/dt = −yᵀφ̃ + σ_s φ̃ᵀΓ⁻¹φ̂ and the leak term can be
    positive where ‖φ̂‖ > φ₀ (φ₀ = 2.5, φ = (0.8, 2.3), φ̂ = (3, 1): +0.327, written here), so (6.4.4) is not
    implied: `passivity_holds` is None with the reason. With Γ = γI, or S = Γ, the verdict is given."""
    Gamma, phi, phi_hat = np.diag([100.0, 1.0]), PHI, np.array([3.0, 1.0])
    assert np.linalg.norm(phi_hat) > 2.5
    sigma_s = np.linalg.norm(phi_hat) / 2.5 - 1.0  # (6.7.14) with σ0 = 1, between φ0 and 2φ0
    leak = sigma_s * (phi - phi_hat) @ np.linalg.solve(Gamma, phi_hat)
    assert leak == pytest.approx(0.327, abs=5e-4)
    arm = TwoLinkArm()
    verdicts = {}
    for name, law in {"diag": SwitchingSigma(2, Gamma, sigma0=1.0, phi0=2.5),
                      "scaled": SwitchingSigma(2, Gamma, sigma0=1.0, phi0=2.5, scaled=True),
                      "scalar": SwitchingSigma(2, 20.0 * np.eye(2), sigma0=1.0, phi0=2.5)}.items():
        ctrl = PassivityBased(arm, pid_servo(2, 2.5 * np.eye(2), np.eye(2)), 10.0 * np.eye(2), law, np.zeros(2))
        res = simulate(Plant(arm, phi), ctrl, sinusoid(2), t_final=0.5, integrator=RK4(1e-3), log_every=10)
        verdicts[name] = metrics(res)
    assert verdicts["diag"]["passivity_holds"] is None
    assert "not implied" in verdicts["diag"]["passivity_not_applicable"]
    for name in ("scaled", "scalar"):
        assert verdicts[name]["passivity_holds"] is True and "passivity_not_applicable" not in verdicts[name]


def test_wind_up_is_said_out_loud():
    """Example 6.3.1 at Ts = 5 ms with a 200 N·m limit: the torque sits on its limit most of the run and φ̂ grows to
    thousands of kg. `saturated_fraction` is the share of ticks where the limit clipped a joint and `max_phi_hat_norm`
    the largest ‖φ̂‖, both written here from the logged torques and estimates; the summary line warns and names the
    remedies. The unlimited run is not warned about."""
    res, _ = run("example-6.3.1", "simulation.control_period=0.005", "plant.torque_limit=200")
    m = metrics(res)
    commanded = res.monitors["tau_commanded"]
    clipped = np.any(np.abs(commanded) > 200.0, axis=-1)
    assert np.array_equal(np.abs(res.tau).max(axis=-1) <= 200.0, np.ones(len(res.t), bool))
    assert m["saturated_fraction"] == pytest.approx(clipped.mean(), abs=1e-12) and m["saturated_fraction"] > 0.5
    assert m["max_phi_hat_norm"] == pytest.approx(np.linalg.norm(res.phi_hat, axis=-1).max(), rel=1e-12)
    assert m["max_phi_hat_norm"] > 1e3
    line = summary("example-6.3.1", m)
    assert "warning: wind-up" in line and "composite" in line and "sigma" in line
    assert max(map(len, line.splitlines())) <= 100
    quiet, _ = run("example-6.3.1", "simulation.control_period=0.005")
    assert "warning" not in summary("example-6.3.1", metrics(quiet))
