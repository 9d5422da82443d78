"""Repetitive control law, Table 7.2.2 and Problem 7.2-4 (spec §9): the learning law on the delay line, and its
Lyapunov function (7.2.43) for the V monitor."""

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
    """The sample holds sat(û_d(t − T)), stores û_d(t) = that + k_L r(t) with the last step's increment c of V's window
    integrals, moves the window (w ← w + c − c one period ago) and resets c; the torque is (7.2.31) and the state's
    derivative is that of c alone: [Y_dᵀ û_d / k_L, ‖û_d‖² / 2k_L]."""
    ctrl = Repetitive(ARM, Kv=50, Kp=50, Ka=50, kL=20, period=T, u_min=-5, u_max=5)
    assert ctrl.state_names == ("u_hat_past1", "u_hat_past2", "w_Ydu_m1", "w_Ydu_m2", "w_uu", "step_w_Ydu_m1",
                                "step_w_Ydu_m2", "step_w_uu")
    ref = sinusoid(2)(0.3)
    q, dq = ref.q_des - [0.1, -0.2], ref.dq_des - [0.3, 0.05]
    r = (ref.dq_des - dq) + (ref.q_des - q)
    x = np.array([0.0, 0.0, 1.0, 2.0, 3.0, 0.5, 0.25, 0.125])
    past = np.array([7.0, -1.0, 0.1, 0.2, 0.3])
    state, store = ctrl.sample(0.3, x, q, dq, ref, past)
    held = state[:2]
    np.testing.assert_allclose(held, [5.0, -1.0])  # sat(û_d(t − T))
    np.testing.assert_allclose(state[2:5], [1.0 + 0.5 - 0.1, 2.0 + 0.25 - 0.2, 3.0 + 0.125 - 0.3])
    np.testing.assert_array_equal(state[5:], 0.0)
    np.testing.assert_allclose(store, np.concatenate([held + 20 * r, [0.5, 0.25, 0.125]]))
    tau, dx = ctrl(0.3, state, q, dq, ref)
    e = ref.q_des - q
    np.testing.assert_allclose(tau, held + 20 * r + 50 * r + 50 * e + 50 * (e @ e) * r)
    u_hat = held + 20 * r
    Yd = ARM.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)
    np.testing.assert_array_equal(dx[:5], 0.0)
    np.testing.assert_allclose(dx[5:], np.concatenate([Yd.T @ u_hat / 20, [u_hat @ u_hat / 40]]), rtol=1e-14)


KV = KP = KA = KL = 50.0
PHI = np.array([0.8, 2.3])
N_PER = 2000  # steps per period in the hand-written loops (the scenario uses 4000)


def _u_d(t):
    """The repeatable dynamics (7.2.29) along q_d = sin t: u_d = M(q_d) q̈_d + V_m(q_d, q̇_d) q̇_d + G(q_d), from the
    arm's M, V_m and G (no regressor)."""
    ref = sinusoid(2)(t)
    return (ARM.mass_matrix(ref.q_des, PHI) @ ref.ddq_des + ARM.coriolis_matrix(ref.q_des, ref.dq_des, PHI) @ ref.dq_des
            + ARM.gravity(ref.q_des, PHI))


def _by_hand(periods: int, sampled: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(7.2.31)–(7.2.32) written out: a ring of N samples of û_d, read (held) and written at every step t_k, the torque
    τ = û_d(t_k − T) + k_L r + k_v r + k_p e + k_a‖e‖² r, and RK4 of M q̈ + V_m q̇ + G = τ. Continuous: τ is evaluated at
    every RK4 stage with û_d(t_k − T) held; sampled: τ(t_k) is held over the step. Alongside, RK4 of ‖ũ_d‖² =
    ‖u_d − û_d‖² (7.2.33) over each step, with û_d as the torque uses it (held + k_L r at each stage; sampled: its value
    at t_k, held). Returns (q, q̇, û_d held, ∫ ‖ũ_d‖² over step k) per step."""
    traj, dt = sinusoid(2), T / N_PER
    ring = np.zeros((N_PER, 2))
    q, dq = np.zeros(2), np.zeros(2)

    def torque(t, q, dq, held):
        ref = traj(t)
        e, de = ref.q_des - q, ref.dq_des - dq
        r = de + e
        return held + KL * r + KV * r + KP * e + KA * (e @ e) * r, r

    def f(t, s, held, tau_held, u_tilde_held):
        q, dq = s[:2], s[2:4]
        tau = tau_held if sampled else torque(t, q, dq, held)[0]
        ddq = np.linalg.solve(ARM.mass_matrix(q, PHI), tau - ARM.coriolis_matrix(q, dq, PHI) @ dq - ARM.gravity(q, PHI))
        u_tilde = u_tilde_held if sampled else _u_d(t) - (held + KL * torque(t, q, dq, held)[1])
        return np.concatenate([dq, ddq, [u_tilde @ u_tilde]])

    qs, dqs, helds, steps = [], [], [], []
    for k in range(periods * N_PER):
        t = k * dt
        held = ring[k % N_PER].copy()
        tau_k, r_k = torque(t, q, dq, held)
        ring[k % N_PER] = held + KL * r_k
        qs.append(q)
        dqs.append(dq)
        helds.append(held)
        s = np.concatenate([q, dq, [0.0]])
        args = (held, tau_k, _u_d(t) - (held + KL * r_k))
        k1 = f(t, s, *args)
        k2 = f(t + dt / 2, s + dt / 2 * k1, *args)
        k3 = f(t + dt / 2, s + dt / 2 * k2, *args)
        k4 = f(t + dt, s + dt * k3, *args)
        s = s + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        q, dq = s[:2], s[2:4]
        steps.append(s[4])
    return np.array(qs), np.array(dqs), np.array(helds), np.array(steps)


def _lyapunov_by_hand(k: int, q, dq, steps) -> float:
    """V (7.2.43) at t_k = k·dt: ½ rᵀ M(q) r + ½ k_p eᵀe + (1/2k_L) ∫_{t_k−T}^{t_k} ‖ũ_d‖², the integral the sum of the
    last N steps' integrals and, before the first period is over, ∫_{t_k−T}^0 ‖u_d‖² (û_d = 0 on [−T, 0), so ũ_d = u_d;
    by quadrature, as ∫_{t_k}^T by periodicity (7.2.30))."""
    from scipy.integrate import quad

    t = k * T / N_PER
    ref = sinusoid(2)(t)
    e, r = ref.q_des - q[k], (ref.dq_des - dq[k]) + (ref.q_des - q[k])
    window = steps[max(0, k - N_PER) : k].sum()
    if k < N_PER:
        window += quad(lambda s: _u_d(s) @ _u_d(s), t, T, epsabs=1e-11, epsrel=1e-13, limit=200)[0]
    return 0.5 * r @ ARM.mass_matrix(q[k], PHI) @ r + 0.5 * KP * e @ e + window / (2 * KL)


def _short(periods: int, *extra: str):
    return load("example-7.2.2", [f"simulation.t_final={periods * T!r}", f"simulation.dt={T / N_PER!r}",
                                  "simulation.log_every=1", *extra])


@pytest.mark.parametrize("sampled", [False, True], ids=["rk4", "sampled"])
def test_two_periods_equal_the_equations_written_out(sampled):
    """Table 7.2.2 on the RK4 and the sampled-data path equals (7.2.31)–(7.2.32) written out here, to round-off; the
    logged state at t_k is the û_d(t_k − T) applied at t_k; V is (7.2.43) written out, at instants of both periods
    (sampled: of the second, a full period of ticks, where V's sums over the ticks are the written-out rectangle rule;
    within the first its window's part [t_k − T, 0) is exact, the rest sums, O(Ts) apart)."""
    extra = [f"simulation.control_period={T / N_PER!r}"] if sampled else []
    res = _short(2, *extra).run()
    q, dq, held, steps = _by_hand(2, sampled)
    assert res.ok
    np.testing.assert_allclose(res.q[:-1], q, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.x[:-1, :2], held, rtol=1e-10, atol=1e-12)
    assert res.V is not None
    instants = [N_PER, N_PER + 1, 3 * N_PER // 2, 2 * N_PER - 1] + ([] if sampled else [0, 1, 7, N_PER // 2, N_PER - 1])
    for k in instants:
        assert res.V[k] == pytest.approx(_lyapunov_by_hand(k, q, dq, steps), rel=1e-11), k


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
        np.testing.assert_array_equal(res.x[first, :2], 0.0, err_msg=name)
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
    assert np.all(np.abs(saturated.x[:, :2]) <= 60.0 + 1e-12)
    assert np.abs(plain.x[:, :2]).max() > 60.0  # the plain law's learned signal leaves those bounds (the spike of spec §9.3)
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


def test_the_delay_line_is_read_at_slot_k_mod_N_and_written_without_touching_the_old_line(x64):
    """`sample` at step k hands the law slot k mod N (the line's head, a copy), stores û_d(t_k) there in a new array,
    reads slot k + 1 mod N for the next step from that new array, and leaves the line it was given as it was: the one
    step function's update, numpy or traced."""
    from robotadapt.plant import Plant
    from robotadapt.sim.loop import ClosedLoop, Ring, ring_write, sample

    ctrl = Repetitive(ARM, Kv=50, Kp=50, Ka=50, kL=20, period=T)
    loop = ClosedLoop(Plant(ARM, np.array([0.8, 2.3])), ctrl, 2)
    slots = np.arange(25.0).reshape(5, 5)  # per slot: û_d (n = 2), the increment of w (p + 1 = 3)
    before = slots.copy()
    line = Ring(slots, slots[2].copy())  # as the step before step 7 left it: 7 mod 5 = 2
    ref = sinusoid(2)(0.3)
    z = np.array([0.1, -0.2, 0.3, 0.05, 9.0, 9.0, 1.0, 2.0, 3.0, 0.5, 0.25, 0.125])
    applied, new = sample(loop, 7, 0.3, z, line, ref)
    np.testing.assert_array_equal(slots, before)
    np.testing.assert_array_equal(applied[:4], z[:4])
    np.testing.assert_array_equal(applied[4:6], before[2, :2])  # x = û_d(t − T), held over the step
    held, store = ctrl.sample(0.3, z[4:], z[:2], z[2:4], ref, before[2])
    np.testing.assert_array_equal(applied[4:], held)
    np.testing.assert_array_equal(new.slots[2], store)
    np.testing.assert_array_equal(np.delete(new.slots, 2, axis=0), np.delete(before, 2, axis=0))
    np.testing.assert_array_equal(new.head, before[3])
    np.testing.assert_array_equal(Ring.start(before).head, before[0])
    jnp = pytest.importorskip("jax").numpy
    from robotadapt.tracing import jax_module

    jax = jax_module()
    applied_j, new_j = jax.jit(lambda k, z, line: sample(loop, k, 0.3, z, line, Reference(*ref)))(
        jnp.asarray(7), jnp.asarray(z), Ring(jnp.asarray(slots), jnp.asarray(slots[2])))
    np.testing.assert_allclose(np.asarray(applied_j), applied, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(new_j.slots), new.slots, rtol=1e-15)
    np.testing.assert_array_equal(np.asarray(new_j.head), new.head)
    np.testing.assert_array_equal(ring_write(slots, 0, np.zeros(5))[0], 0.0)
    np.testing.assert_array_equal(slots, before)


def test_the_saturated_law_clips_on_jax_arrays_too(x64):
    jnp = pytest.importorskip("jax").numpy
    ctrl = Repetitive(ARM, Kv=50, Kp=50, Ka=50, kL=20, period=T, u_min=-5, u_max=5)
    ref = sinusoid(2)(0.3)
    state, _ = ctrl.sample(0.3, jnp.zeros(8), jnp.zeros(2), jnp.zeros(2), Reference(*ref),
                           jnp.asarray([7.0, -1.0, 0.0, 0.0, 0.0]))
    np.testing.assert_array_equal(np.asarray(state[:2]), [5.0, -1.0])


# --------------------------------------------------------------------------------------------------------------------
# The Lyapunov function (7.2.43) for the V monitor (issue 22): carried by the law, not read from the log


def _repetitive_scenarios() -> list[str]:
    from robotadapt.studies.scenarios import available

    return [name for name in available() if load(name).data["controller"].get("kind") == "repetitive"]


def test_every_packaged_repetitive_scenario_gives_V_to_the_monitor():
    """Example 7.2.2, Problem 7.2-4 and Problem 7.2-5 (polar arm) log V (7.2.43), and the monitors read it."""
    from robotadapt.analysis.metrics import metrics

    names = _repetitive_scenarios()
    assert {"example-7.2.2", "problem-7.2-4", "problem-7.2-5"} <= set(names)
    for name in names:
        res = load(name, [f"simulation.t_final={T!r}"]).run()
        assert res.ok and res.V is not None, name
        assert np.all(np.isfinite(res.V)) and np.all(res.V > 0), name
        m = metrics(res)
        assert "lyapunov_increase_fraction" in m and "lyapunov_max_rel_increase" in m, name


def test_lyapunov_does_not_depend_on_the_logging_rate(plain):
    """V's integral over the last period is carried in the law's state at every step, so logging every 4th step gives
    the same V at the same instants (the issue's point: no monitor depends on the logging rate)."""
    sparse = load("example-7.2.2", [f"simulation.t_final={PERIODS * T!r}", "simulation.log_every=4"]).run()
    np.testing.assert_array_equal(sparse.t, plain.t[::4])
    np.testing.assert_allclose(sparse.V, plain.V[::4], rtol=1e-12)


def test_saturated_law_lyapunov_decreases_at_every_step(saturated):
    """Problem 7.2-4: with bounds that contain u_d, ‖u_d − sat(û_d)‖ ≤ ‖u_d − û_d‖, so (7.2.47) holds for the same V;
    the gains satisfy (7.2.22), (7.2.25), (7.2.48) (`robotadapt gains example-7.2.2`), so dV/dt ≤ −λ₃‖[e, r]‖² < 0
    (7.2.49): V falls over every logged step of six periods."""
    from robotadapt.analysis.monitors import lyapunov_increase_fraction

    assert np.all(np.diff(saturated.V) < 0)
    assert lyapunov_increase_fraction(saturated.V) == 0.0
    assert saturated.V[-1] < 0.02 * saturated.V[0]


def test_plain_law_lyapunov_increases_only_by_the_held_delay_and_less_with_a_smaller_step(plain):
    """Example 7.2.2: (7.2.44)–(7.2.49) give dV/dt < 0 for û_d(t) = û_d(t − T) + k_L r(t); the law holds û_d(t_k − T)
    over each step, O(dt) from û_d(t − T). V falls overall, and rises only over the first steps of a period, where the
    plain law's learned spike makes r(t − T) change fastest; those rises shrink faster than dt (measured: the largest
    ×4.9 and their sum ×9 smaller with dt halved)."""
    V, dt = plain.V, T / 4000
    assert V[-1] < 0.05 * V[0]
    rises = np.nonzero(np.diff(V) > 0)[0]
    assert 0 < rises.size < 10
    assert np.all(np.mod(plain.t[rises] + 1e-9, T) < 2.5 * dt)  # at most two steps into a period
    finer = load("example-7.2.2", [f"simulation.t_final={PERIODS * T!r}", f"simulation.dt={T / 8000!r}",
                                   "simulation.log_every=1"]).run()
    coarse_rise, fine_rise = np.diff(V).clip(0), np.diff(finer.V).clip(0)
    assert fine_rise.max() < 0.3 * coarse_rise.max() and coarse_rise.max() < 1e-4 * V[0]
    assert fine_rise.sum() < 0.2 * coarse_rise.sum()


def test_the_divergence_guard_skips_the_monitors_window_integrals_in_sampled_time():
    """V's window integrals (w, c) are records for the monitor, not the loop's state: a sampled run (q_d = sin 10t,
    Ts = T/400) whose records pass max_state = 650 while q, q̇ and û_d stay below it runs to the end, as the
    continuous guard (ClosedLoop.guarded_part) lets it."""
    from robotadapt.sim import Sampled, simulate

    s = load("example-7.2.2", ["trajectory.omega=10.0", "controller.period=0.6283185307179586"]).setup
    res = simulate(s.plant, s.controller, s.trajectory, t_final=0.7, max_state=650.0,
                   integrator=Sampled(0.6283185307179586 / 400, backend="numpy"))
    assert res.ok, res.status
    assert np.abs(res.x[:, 2:]).max() > 650.0  # the records went past the bound
    assert np.abs(np.concatenate([res.q, res.dq, res.x[:, :2]], axis=1)).max() < 650.0
