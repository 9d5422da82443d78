"""Repetitive control law, Table 7.2.2 and Problem 7.2-4 (spec §9): the learning law on the delay line."""

import numpy as np
import pytest

from robotadapt.controllers.repetitive import Repetitive
from robotadapt.robots import TwoLinkArm
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import Reference, exponential_step, sinusoid
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


KV = KP = KA = KL = 50.0
PHI = np.array([0.8, 2.3])
N_PER = 2000  # steps per period in the hand-written loops (the scenario uses 4000)


def _by_hand(periods: int, sampled: bool) -> tuple[np.ndarray, np.ndarray]:
    """(7.2.31)–(7.2.32) written out: a ring of N samples of û_d, read (held) and written at every step t_k, the torque
    τ = û_d(t_k − T) + k_L r + k_v r + k_p e + k_a‖e‖² r, and RK4 of M q̈ + V_m q̇ + G = τ. Continuous: τ is evaluated at
    every RK4 stage with û_d(t_k − T) held; sampled: τ(t_k) is held over the step. Returns (q, û_d held) per step."""
    traj, dt = sinusoid(2), T / N_PER
    ring = np.zeros((N_PER, 2))
    q, dq = np.zeros(2), np.zeros(2)

    def torque(t, q, dq, held):
        ref = traj(t)
        e, de = ref.q_des - q, ref.dq_des - dq
        r = de + e
        return held + KL * r + KV * r + KP * e + KA * (e @ e) * r, r

    def f(t, s, held, tau_held):
        q, dq = s[:2], s[2:]
        tau = tau_held if sampled else torque(t, q, dq, held)[0]
        ddq = np.linalg.solve(ARM.mass_matrix(q, PHI), tau - ARM.coriolis_matrix(q, dq, PHI) @ dq - ARM.gravity(q, PHI))
        return np.concatenate([dq, ddq])

    qs, helds = [], []
    for k in range(periods * N_PER):
        t = k * dt
        held = ring[k % N_PER].copy()
        tau_k, r_k = torque(t, q, dq, held)
        ring[k % N_PER] = held + KL * r_k
        qs.append(q)
        helds.append(held)
        s = np.concatenate([q, dq])
        k1 = f(t, s, held, tau_k)
        k2 = f(t + dt / 2, s + dt / 2 * k1, held, tau_k)
        k3 = f(t + dt / 2, s + dt / 2 * k2, held, tau_k)
        k4 = f(t + dt, s + dt * k3, held, tau_k)
        s = s + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        q, dq = s[:2], s[2:]
    return np.array(qs), np.array(helds)


def _short(periods: int, *extra: str):
    return load("example-7.2.2", [f"simulation.t_final={periods * T!r}", f"simulation.dt={T / N_PER!r}",
                                  "simulation.log_every=1", *extra])


@pytest.mark.parametrize("sampled", [False, True], ids=["rk4", "sampled"])
def test_two_periods_equal_the_equations_written_out(sampled):
    """Table 7.2.2 on the RK4 and the sampled-data path equals (7.2.31)–(7.2.32) written out here, to round-off; the
    logged state at t_k is the û_d(t_k − T) applied at t_k."""
    extra = [f"simulation.control_period={T / N_PER!r}"] if sampled else []
    res = _short(2, *extra).run()
    q, held = _by_hand(2, sampled)
    assert res.ok
    np.testing.assert_allclose(res.q[:-1], q, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.x[:-1], held, rtol=1e-10, atol=1e-12)


def test_first_period_holds_zero_and_applies_the_feedback_alone():
    """û_d = 0 on [−T, 0) (7.2.32): during the first period the held value is exactly 0 and the torque is
    k_L r + k_v r + k_p e + k_a‖e‖² r, on the single, sampled and batch paths."""
    from robotadapt.sim.batch import simulate_batch

    s = _short(1).setup
    runs = {"rk4": _short(1).run(), "sampled": _short(1, f"simulation.control_period={T / N_PER!r}").run(),
            "batch": simulate_batch(s.plant, s.controller, s.trajectory, t_final=T, integrator=s.integrator,
                                    log_every=1).run(0)}
    for name, res in runs.items():
        first = res.t < T - 1e-9
        assert first.sum() == N_PER, name
        np.testing.assert_array_equal(res.x[first], 0.0, err_msg=name)
        e, r = res.e[first], res.e[first] + (res.dq_des - res.dq)[first]
        feedback = (KL + KV + KA * (e * e).sum(axis=-1, keepdims=True)) * r + KP * e
        np.testing.assert_allclose(res.tau[first], feedback, rtol=1e-12, atol=1e-12, err_msg=name)


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


# --------------------------------------------------------------------------------------------------------------------
# The delay line in the carried state (issue 14): a pure update, the same on numpy and JAX


def test_the_delay_line_is_read_at_slot_k_mod_N_and_written_without_touching_the_old_line():
    """`sample` at step k hands the law slot k mod N (the line's head, a copy), stores û_d(t_k) there in a new array,
    reads slot k + 1 mod N for the next step from that new array, and leaves the line it was given as it was: the one
    step function's update, numpy or traced."""
    from robotadapt.plant import Plant
    from robotadapt.sim.loop import ClosedLoop, Ring, ring_write, sample

    ctrl = Repetitive(ARM, Kv=50, Kp=50, Ka=50, kL=20, period=T)
    loop = ClosedLoop(Plant(ARM, np.array([0.8, 2.3])), ctrl, 2)
    slots = np.arange(10.0).reshape(5, 2)
    before = slots.copy()
    line = Ring(slots, slots[2].copy())  # as the step before step 7 left it: 7 mod 5 = 2
    ref = sinusoid(2)(0.3)
    z = np.array([0.1, -0.2, 0.3, 0.05, 9.0, 9.0])
    applied, new = sample(loop, 7, 0.3, z, line, ref)
    np.testing.assert_array_equal(slots, before)
    np.testing.assert_array_equal(applied[:4], z[:4])
    np.testing.assert_array_equal(applied[4:], before[2])  # x = û_d(t − T), held over the step
    held, store = ctrl.sample(0.3, z[4:], z[:2], z[2:4], ref, before[2])
    np.testing.assert_array_equal(new.slots[2], store)
    np.testing.assert_array_equal(np.delete(new.slots, 2, axis=0), np.delete(before, 2, axis=0))
    np.testing.assert_array_equal(new.head, before[3])
    np.testing.assert_array_equal(Ring.start(before).head, before[0])
    jnp = pytest.importorskip("jax").numpy
    from robotadapt.sim.compiled import jax_module

    jax = jax_module()
    applied_j, new_j = jax.jit(lambda k, z, line: sample(loop, k, 0.3, z, line, Reference(*ref)))(
        jnp.asarray(7), jnp.asarray(z), Ring(jnp.asarray(slots), jnp.asarray(slots[2])))
    np.testing.assert_allclose(np.asarray(applied_j), applied, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(new_j.slots), new.slots, rtol=1e-15)
    np.testing.assert_array_equal(np.asarray(new_j.head), new.head)
    np.testing.assert_array_equal(ring_write(slots, 0, np.zeros(2))[0], 0.0)
    np.testing.assert_array_equal(slots, before)


def test_the_saturated_law_clips_on_jax_arrays_too():
    jnp = pytest.importorskip("jax").numpy
    ctrl = Repetitive(ARM, Kv=50, Kp=50, Ka=50, kL=20, period=T, u_min=-5, u_max=5)
    ref = sinusoid(2)(0.3)
    held, _ = ctrl.sample(0.3, jnp.zeros(2), jnp.zeros(2), jnp.zeros(2), Reference(*ref), jnp.asarray([7.0, -1.0]))
    np.testing.assert_array_equal(np.asarray(held), [5.0, -1.0])
