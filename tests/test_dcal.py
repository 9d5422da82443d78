"""DCAL, Table 7.2.1 (spec §8): single instant, the dV/dt identity of the proof (7.2.15)–(7.2.17) at random instants,
Y_d table, Example 7.2.1 and Problem 7.2-2 against the theory."""

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.controllers import Law
from robotadapt.controllers.dcal import DCAL
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, SolveIVP, simulate
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import Reference, sinusoid
from robotadapt.validation import ConfigError
from test_controllers import BOOK, OTHER, spec_G, spec_M, spec_Vm

ARM = TwoLinkArm()
PHI = np.array([0.8, 2.3])


def _yd_by_hand(qd, dqd, ddqd, l1=1.0, l2=1.0, g=9.8):
    """Y_d of spec §8.3, written out."""
    c2, s2 = np.cos(qd[1]), np.sin(qd[1])
    c1, c12 = np.cos(qd[0]), np.cos(qd[0] + qd[1])
    y11 = l1**2 * ddqd[0] + l1 * g * c1
    y12 = ((l1**2 + l2**2 + 2 * l1 * l2 * c2) * ddqd[0] + (l2**2 + l1 * l2 * c2) * ddqd[1]
           - l1 * l2 * s2 * (2 * dqd[0] * dqd[1] + dqd[1] ** 2) + l2 * g * c12 + l1 * g * c1)
    y22 = (l2**2 + l1 * l2 * c2) * ddqd[0] + l2**2 * ddqd[1] + l1 * l2 * s2 * dqd[0] ** 2 + l2 * g * c12
    return np.array([[y11, y12], [0.0, y22]])


def test_single_instant_matches_table_7_2_1():
    rng = np.random.default_rng(1)
    ctrl = DCAL(ARM, Kv=50, Kp=40, Ka=30, Gamma=[20, 10], phi_hat0=[0.5, 1.0])
    ref = sinusoid(2)(0.7)
    q, dq = ref.q_des + 0.1 * rng.normal(size=2), ref.dq_des + 0.1 * rng.normal(size=2)
    x = np.array([0.3, 1.7])
    tau, dx = ctrl(0.7, x, q, dq, ref)
    e, de = ref.q_des - q, ref.dq_des - dq
    r = de + e
    Yd = _yd_by_hand(ref.q_des, ref.dq_des, ref.ddq_des)
    np.testing.assert_allclose(tau, Yd @ x + 50 * r + 40 * e + 30 * (e @ e) * r, rtol=1e-12)
    np.testing.assert_allclose(dx, np.diag([20, 10]) @ Yd.T @ r, rtol=1e-12)


def test_perfect_estimate_and_zero_error_give_inverse_dynamics_and_no_update():
    ctrl = DCAL(ARM, Kv=50, Kp=50, Ka=50, Gamma=20, phi_hat0=PHI)
    ref = sinusoid(2)(1.3)
    tau, dx = ctrl(1.3, PHI, ref.q_des, ref.dq_des, ref)
    np.testing.assert_allclose(tau, ARM.inverse_dynamics(ref.q_des, ref.dq_des, ref.ddq_des, PHI), rtol=1e-12)
    np.testing.assert_allclose(dx, 0.0, atol=1e-14)


# --------------------------------------------------------------------------------------------------------------------
# dV/dt along the closed loop at one instant: (7.2.14)–(7.2.17), written out from spec §1.3 and §8.1


def friction_by_hand(arm, dq, phi):
    """F_d q̇ = diag(fv1, fv2) q̇ (7.2.1) for the arm with friction terms, else 0."""
    return phi[2:4] * dq if arm.friction_terms else np.zeros(2)


def plant_acceleration_by_hand(arm, q, dq, tau, phi):
    """q̈ from (7.2.1): M q̈ = τ − V_m q̇ − G − F_d q̇, with the closed forms of spec §1.3."""
    bias = spec_Vm(arm, q, dq, phi) @ dq + spec_G(arm, q, phi) + friction_by_hand(arm, dq, phi)
    return np.linalg.solve(spec_M(arm, q, phi), tau - bias)


def mass_matrix_rate_by_hand(arm, q, dq, phi):
    """dM/dt along q̇: only cos q2 varies in M (spec §1.3), d(cos q2)/dt = −sin q2 q̇2."""
    return -phi[1] * arm.l1 * arm.l2 * np.sin(q[1]) * dq[1] * np.array([[2.0, 1.0], [1.0, 0.0]])


def y_tilde_by_hand(arm, q, dq, ref, phi):
    """Ỹ = Y(·)φ − Y_d(·)φ (7.2.10) with (7.2.3) Y(·)φ = M(q)(q̈_d + ė) + V_m(q, q̇)(q̇_d + e) + G(q) + F_d q̇ and
    (7.2.4) Y_d(·)φ = M(q_d) q̈_d + V_m(q_d, q̇_d) q̇_d + G(q_d) + F_d q̇_d."""
    e, de = ref.q_des - q, ref.dq_des - dq
    y = (spec_M(arm, q, phi) @ (ref.ddq_des + de) + spec_Vm(arm, q, dq, phi) @ (ref.dq_des + e) + spec_G(arm, q, phi)
         + friction_by_hand(arm, dq, phi))
    y_d = (spec_M(arm, ref.q_des, phi) @ ref.ddq_des + spec_Vm(arm, ref.q_des, ref.dq_des, phi) @ ref.dq_des
           + spec_G(arm, ref.q_des, phi) + friction_by_hand(arm, ref.dq_des, phi))
    return y - y_d


def dcal_lyapunov_by_hand(arm, Kp, Gamma, phi_hat, q, dq, ref, phi):
    """V = ½ rᵀ M(q) r + ½ k_p eᵀe + ½ φ̃ᵀ Γ⁻¹ φ̃ (7.2.14), r = ė + e (7.2.6)."""
    e, de = ref.q_des - q, ref.dq_des - dq
    r, err = de + e, phi - phi_hat
    return 0.5 * r @ spec_M(arm, q, phi) @ r + 0.5 * Kp * e @ e + 0.5 * err @ np.linalg.solve(Gamma, err)


def dcal_dVdt_chain_rule(arm, Kp, Gamma, phi_hat, dphi_hat, tau, q, dq, ref, phi):
    """dV/dt = rᵀ M ṙ + ½ rᵀ Ṁ r + k_p eᵀė − φ̃ᵀ Γ⁻¹ dφ̂/dt with ṙ = ë + ė, ë = q̈_d − q̈ and the plant's q̈."""
    e, de = ref.q_des - q, ref.dq_des - dq
    r, err = de + e, phi - phi_hat
    dr = ref.ddq_des - plant_acceleration_by_hand(arm, q, dq, tau, phi) + de
    return (r @ spec_M(arm, q, phi) @ dr + 0.5 * r @ mass_matrix_rate_by_hand(arm, q, dq, phi) @ r + Kp * e @ de
            - err @ np.linalg.solve(Gamma, dphi_hat))


def dcal_dVdt_difference(ctrl, arm, phi_hat, dphi_hat, tau, q, dq, ref, phi, h=1e-3):
    """dV/dt of the controller's own V (`lyapunov`) along the same motion: q with q̇, q̇ with the plant's q̈, φ̂ with
    dφ̂/dt, q_d and q̇_d with q̇_d and q̈_d; fourth-order central difference."""
    ddq = plant_acceleration_by_hand(arm, q, dq, tau, phi)

    def V(s):
        ref_s = Reference(ref.q_des + s * ref.dq_des, ref.dq_des + s * ref.ddq_des, ref.ddq_des)
        return ctrl.lyapunov(s, phi_hat + s * dphi_hat, q + s * dq, dq + s * ddq, ref_s, phi)

    return (-V(2 * h) + 8 * V(h) - 8 * V(-h) + V(-2 * h)) / (12 * h)


def dcal_instants():
    rng = np.random.default_rng(72)
    for kind, arm in [("book-arm", BOOK), ("other-arm", OTHER), ("friction", TwoLinkArm(friction_terms=True))]:
        for seed in range(4):
            p = arm.p
            B = rng.uniform(-1, 1, (p, p))
            gains = {"Kv": rng.uniform(5, 60), "Kp": rng.uniform(5, 60), "Ka": rng.uniform(5, 60),
                     "Gamma": 5.0 * (B @ B.T + p * np.eye(p))}
            q = rng.uniform(-np.pi, np.pi, 2)
            ref = Reference(q + rng.uniform(-1, 1, 2), rng.uniform(-2, 2, 2), rng.uniform(-3, 3, 2))
            yield pytest.param(arm, gains, rng.uniform(0.3, 3.0, p), q, rng.uniform(-2, 2, 2), rng.uniform(-1.0, 3.0, p),
                               ref, id=f"{kind}-{seed}")


@pytest.mark.parametrize(("arm", "gains", "phi", "q", "dq", "phi_hat", "ref"), list(dcal_instants()))
def test_lyapunov_derivative_along_the_closed_loop(arm, gains, phi, q, dq, phi_hat, ref):
    """(7.2.15)–(7.2.17) at any instant and any φ̂:

        dV/dt = −k_p‖e‖² − k_v‖r‖² − k_a‖e‖²‖r‖² + rᵀỸ

    by the chain rule (all written out but the controller's τ and dφ̂/dt) and by differencing the controller's V along
    the closed loop. Flipping the update's sign adds 2 φ̃ᵀ Γ⁻¹ dφ̂/dt = 2 φ̃ᵀ Y_dᵀ r, which breaks the identity."""
    Kv, Kp, Ka, Gamma = gains["Kv"], gains["Kp"], gains["Ka"], gains["Gamma"]
    ctrl = DCAL(arm, phi_hat0=phi_hat, **gains)
    e, de = ref.q_des - q, ref.dq_des - dq
    r = de + e
    expected = -Kp * e @ e - Kv * r @ r - Ka * (e @ e) * (r @ r) + r @ y_tilde_by_hand(arm, q, dq, ref, phi)
    assert ctrl.lyapunov(0.0, phi_hat, q, dq, ref, phi) == pytest.approx(
        dcal_lyapunov_by_hand(arm, Kp, Gamma, phi_hat, q, dq, ref, phi), rel=1e-12)
    tau, dphi_hat = ctrl(0.0, phi_hat, q, dq, ref)
    args = (tau, q, dq, ref, phi)
    assert dcal_dVdt_chain_rule(arm, Kp, Gamma, phi_hat, dphi_hat, *args) == pytest.approx(expected, rel=1e-10, abs=1e-9)
    assert dcal_dVdt_difference(ctrl, arm, phi_hat, dphi_hat, *args) == pytest.approx(expected, rel=1e-6, abs=1e-6)
    # the update's sign flipped
    gap = 2 * (phi - phi_hat) @ np.linalg.solve(Gamma, dphi_hat)
    assert abs(gap) > 1e-3 * max(1.0, abs(expected))
    wrong = dcal_dVdt_chain_rule(arm, Kp, Gamma, phi_hat, -dphi_hat, *args)
    assert wrong == pytest.approx(expected + gap, rel=1e-10, abs=1e-9)
    wrong = dcal_dVdt_difference(ctrl, arm, phi_hat, -dphi_hat, *args)
    assert abs(wrong - expected) > 1e-3 * max(1.0, abs(expected))



def test_precomputed_table_equals_on_line_evaluation():
    traj = sinusoid(2, amplitude=[1.0, 0.5], omega=[1.0, 2.0])
    ctrl = DCAL(ARM, Kv=50, Kp=50, Ka=50, Gamma=20, phi_hat0=[0, 0], precompute=True).prepare(traj, 1e-3, 2.0)
    assert ctrl.table is not None and ctrl.table.values.shape == (4001, 2, 2)
    t = np.array([0.0, 0.0005, 1.2345, 2.0])
    t[2] = 2469 * 0.0005  # on the half-step grid
    ref = traj(t)
    expected = ARM.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)
    np.testing.assert_allclose(ctrl.desired_regressor(t, ref), expected, rtol=1e-13)
    assert ctrl.table.lookup(np.array([0.00031])) is None  # off the grid: evaluated on line instead


def test_example_7_2_1_converges_with_nonincreasing_lyapunov():
    """Example 7.2.1: e → 0 and φ̂ → (0.8, 2.3); V of (7.2.14) never increases (the gain conditions hold, see gains)."""
    res = load("example-7.2.1", ["simulation.t_final=12"]).run()
    assert res.ok
    assert np.max(np.abs(res.e[-1])) < 1e-6
    np.testing.assert_allclose(res.phi_hat[-1], PHI, atol=1e-4)
    assert metrics(res)["lyapunov_max_rel_increase"] < 1e-9


def test_online_and_precomputed_runs_agree():
    a = load("example-7.2.1", ["simulation.t_final=2", "controller.precompute=false"]).run()
    b = load("example-7.2.1", ["simulation.t_final=2", "controller.precompute=true"]).run()
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)


def test_precompute_with_solve_ivp_falls_back_off_grid():
    s = load("example-7.2.1", ["simulation.t_final=1"]).setup
    res = simulate(s.plant, s.controller, s.trajectory, t_final=1.0, integrator=SolveIVP("RK45", 1e-9, 1e-11, 1e-2))
    ref = simulate(s.plant, s.controller, s.trajectory, t_final=1.0, integrator=RK4(1e-3))
    np.testing.assert_allclose(res.q[-1], ref.q[-1], atol=1e-6)


def test_sign_flip_breaks_convergence():
    s = load("example-7.2.1", ["simulation.t_final=12"]).setup

    @dataclass(frozen=True, eq=False)
    class Flipped(Law):
        """DCAL with its update's sign flipped; everything else forwarded."""

        inner: Any
        model: Any = None

        state_names = property(lambda self: self.inner.state_names)

        def initial_state(self, q0, dq0):
            return self.inner.initial_state(q0, dq0)

        def phi_hat(self, x):
            return self.inner.phi_hat(x)

        def prepare(self, *args):
            return Flipped(self.inner.prepare(*args), self.inner.model)

        def __call__(self, t, x, q, dq, ref):
            tau, dx = self.inner(t, x, q, dq, ref)
            return tau, -dx

    res = simulate(s.plant, Flipped(s.controller, s.controller.model), s.trajectory, t_final=12.0)
    assert not (np.max(np.abs(res.e[-1])) < 1e-6 and np.allclose(res.phi_hat[-1], PHI, atol=1e-4))


def test_problem_7_2_2_polar_arm_converges_locally():
    res = load("problem-7.2-2", ["simulation.t_final=10"]).run()
    assert res.ok and np.max(np.abs(res.e[-1])) < 1e-5
    assert abs(res.phi_hat[-1, 0] - 1.0) < 1e-3


@pytest.mark.parametrize("key,value", [("Kv", -1), ("Ka", "x"), ("Gamma", [[1, 2], [2, 1]]), ("precompute", 1)])
def test_bad_gains_name_the_field(key, value):
    kwargs = dict(Kv=50, Kp=50, Ka=50, Gamma=20, phi_hat0=[0, 0])
    kwargs[key] = value
    with pytest.raises(ConfigError, match=f"controller.{key}"):
        DCAL(ARM, **kwargs)
