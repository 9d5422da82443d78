"""DCAL, Table 7.2.1 (spec §8): single instant, Y_d table, Example 7.2.1 and Problem 7.2-2 against the theory."""

import numpy as np
import pytest

from robotadapt.controllers.dcal import DCAL
from robotadapt.robots import TwoLinkArm
from robotadapt.scenarios import load
from robotadapt.simulation import RK4, SolveIVP, simulate
from robotadapt.trajectories import sinusoid
from robotadapt.validation import ConfigError

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
    assert res.metrics()["lyapunov_max_rel_increase"] < 1e-9


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

    class Flipped:
        def __init__(self, inner):
            self.inner = inner

        def __getattr__(self, name):
            return getattr(self.inner, name)

        def prepare(self, *args):
            return Flipped(self.inner.prepare(*args))

        def __call__(self, t, x, q, dq, ref):
            tau, dx = self.inner(t, x, q, dq, ref)
            return tau, -dx

    res = simulate(s.plant, Flipped(s.controller), s.trajectory, t_final=12.0)
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
