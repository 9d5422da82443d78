"""Repetitive control law, Table 7.2.2 and Problem 7.2-4 (spec §9): the learning law on the delay line."""

import numpy as np
import pytest

from robotadapt.controllers.repetitive import Repetitive
from robotadapt.robots import TwoLinkArm
from robotadapt.scenarios import load
from robotadapt.trajectories import exponential_step, sinusoid
from robotadapt.validation import ConfigError

T = 2 * np.pi
ARM = TwoLinkArm()
PERIODS = 6


def _peaks(res, periods):
    k = np.floor(res.t / T + 1e-9).astype(int)
    return np.array([np.abs(res.e[k == i]).max() for i in range(periods)])


@pytest.fixture(scope="module")
def plain():
    return load("example-7.2.2", [f"simulation.t_final={PERIODS * T!r}", "simulation.log_every=1"]).run()


@pytest.fixture(scope="module")
def saturated():
    return load("problem-7.2-4", [f"simulation.t_final={PERIODS * T!r}", "simulation.log_every=1"]).run()


def test_learning_law_stores_past_plus_kL_r():
    ctrl = Repetitive(ARM, Kv=50, Kp=50, Ka=50, kL=20, period=T, u_min=-5, u_max=5)
    ref = sinusoid(2)(0.3)
    q, dq = ref.q_des - [0.1, -0.2], ref.dq_des - [0.3, 0.05]
    r = (ref.dq_des - dq) + (ref.q_des - q)
    held, store = ctrl.sample(0.3, np.zeros(2), q, dq, ref, np.array([7.0, -1.0]))
    np.testing.assert_allclose(held, [5.0, -1.0])  # sat(û_d(t − T))
    np.testing.assert_allclose(store, held + 20 * r)
    tau, dx = ctrl(0.3, held, q, dq, ref)
    e = ref.q_des - q
    np.testing.assert_allclose(tau, held + 20 * r + 50 * r + 50 * e + 50 * (e @ e) * r)
    np.testing.assert_array_equal(dx, 0.0)


def test_peak_error_decreases_period_over_period(plain):
    """Example 7.2.2: once learning takes hold, each period's peak error is below the previous one."""
    assert plain.ok
    peaks = _peaks(plain, PERIODS)
    assert np.all(np.diff(peaks[1:]) < 0), peaks
    assert peaks[-1] < 0.5 * peaks[1]


def test_saturated_law_stays_in_bounds_and_converges(saturated, plain):
    """Problem 7.2-4: û_d(t − T) is kept within ±60 while the error still shrinks period over period."""
    assert saturated.ok
    assert np.all(np.abs(saturated.x) <= 60.0 + 1e-12)
    assert np.abs(plain.x).max() > 60.0  # the plain law's learned signal leaves those bounds (the spike of spec §9.3)
    peaks = _peaks(saturated, PERIODS)
    assert np.all(np.diff(peaks[1:]) < 0) and peaks[-1] < 0.5 * peaks[1], peaks


def test_learned_feedforward_approaches_the_repeatable_dynamics(saturated):
    """û_d → u_d = Y_d φ (7.2.29): the RMS mismatch falls every period (slowly: about ×0.7 a period here)."""
    s = load("problem-7.2-4").setup
    ctrl = s.controller.prepare(s.trajectory, s.integrator.dt, 1.0)
    ref = s.trajectory(saturated.t)
    u_hat = ctrl.learned(saturated.t, saturated.x, saturated.q, saturated.dq, ref)
    u_d = ARM.inverse_dynamics(ref.q_des, ref.dq_des, ref.ddq_des, np.array([0.8, 2.3]))
    k = np.floor(saturated.t / T + 1e-9).astype(int)
    rms = np.array([np.sqrt(np.mean((u_hat - u_d)[k == i] ** 2)) for i in range(PERIODS)])
    assert np.all(np.diff(rms) < 0) and rms[-1] < 0.3 * rms[0], rms


@pytest.mark.slow
def test_example_7_2_2_twenty_periods():
    res = load("example-7.2.2").run()
    peaks = _peaks(res, 20)
    assert res.ok and peaks[-1] < 0.02 * peaks[0]


def test_period_and_step_are_checked():
    ctrl = Repetitive(ARM, Kv=50, Kp=50, Ka=50, kL=50)
    with pytest.raises(ConfigError, match="controller.period"):
        ctrl.prepare(exponential_step(2), 1e-3, 10.0)
    with pytest.raises(ConfigError, match="simulation.dt"):
        ctrl.prepare(sinusoid(2), 1e-3, 10.0)
    assert ctrl.prepare(sinusoid(2), T / 4000, 10.0).period == pytest.approx(T)


def test_needs_fixed_step_integrator():
    with pytest.raises(ConfigError, match="rk4"):
        load("example-7.2.2", ["simulation.method='RK45'", "simulation.t_final=1"]).run()


@pytest.mark.parametrize("over", [dict(kL=0), dict(u_min=-1), dict(u_min=1, u_max=-1)])
def test_bad_settings_name_the_field(over):
    kwargs = dict(Kv=50, Kp=50, Ka=50, kL=50) | over
    with pytest.raises(ConfigError, match="controller"):
        Repetitive(ARM, **kwargs)
