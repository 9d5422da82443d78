"""Controllers at one instant, no simulation (STYLE "Tests we keep" 2; spec §2.1, §3).

The expected torques and updates are written out from the spec's formulas for the two-link arm (§1.3: M, V_m, G and the
regressor entries Y11..Y22), not taken from the library.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from robotadapt.controllers import PD, ComputedTorque, InertiaRelated, PDGravity
from robotadapt.robots import OneLinkArm, PolarArm, TwoLinkArm
from robotadapt.trajectories import Reference, constant
from robotadapt.validation import ConfigError

BOOK = TwoLinkArm()  # Example 6.3.1: l1 = l2 = 1, g = 9.8
OTHER = TwoLinkArm(l1=0.7, l2=1.3, g=9.81)
ARMS = [pytest.param(BOOK, id="book-arm"), pytest.param(OTHER, id="other-arm")]
SEEDS = range(6)
REST = np.zeros(2)  # a first measurement, for `initial_state(q0, dq0)`

# Gains: the book's diagonal ones (Example 6.3.1) and full symmetric PD ones, which catch a transposed gain.
BOOK_GAINS = {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}
FULL_GAINS = {"Lam": np.array([[2.0, 0.5], [0.5, 1.0]]), "Kv": np.array([[10.0, -3.0], [-3.0, 4.0]]),
              "Gamma": np.array([[20.0, 5.0], [5.0, 3.0]])}
GAINS = [pytest.param(BOOK_GAINS, id="diagonal"), pytest.param(FULL_GAINS, id="full")]


def gain(value, n=2):
    return value * np.eye(n) if np.ndim(value) == 0 else np.asarray(value)


# --------------------------------------------------------------------------------------------------------------------
# Spec §1.3, written out


def spec_M(arm, q, m):
    m1, m2, l1, l2, c2 = m[0], m[1], arm.l1, arm.l2, np.cos(q[1])
    return np.array([[(m1 + m2) * l1**2 + m2 * l2**2 + 2 * m2 * l1 * l2 * c2, m2 * l2**2 + m2 * l1 * l2 * c2],
                     [m2 * l2**2 + m2 * l1 * l2 * c2, m2 * l2**2]])


def spec_Vm(arm, q, dq, m):
    return m[1] * arm.l1 * arm.l2 * np.sin(q[1]) * np.array([[-dq[1], -(dq[0] + dq[1])], [dq[0], 0.0]])


def spec_G(arm, q, m):
    c1, c12, g = np.cos(q[0]), np.cos(q[0] + q[1]), arm.g
    return np.array([(m[0] + m[1]) * g * arm.l1 * c1 + m[1] * g * arm.l2 * c12, m[1] * g * arm.l2 * c12])


def spec_Y(arm, q, dq, v, a):
    """Y11..Y22 of spec §1.3: Y(q, q̇, v, a) φ = M a + V_m v + G, φ = [m1, m2]."""
    l1, l2, g = arm.l1, arm.l2, arm.g
    c1, c2, s2, c12 = np.cos(q[0]), np.cos(q[1]), np.sin(q[1]), np.cos(q[0] + q[1])
    Y11 = l1**2 * a[0] + l1 * g * c1
    Y12 = ((l1**2 + l2**2 + 2 * l1 * l2 * c2) * a[0] + (l2**2 + l1 * l2 * c2) * a[1] - l1 * l2 * s2 * dq[1] * v[0]
           - l1 * l2 * s2 * (dq[0] + dq[1]) * v[1] + l1 * g * c1 + l2 * g * c12)
    Y21 = 0.0
    Y22 = (l2**2 + l1 * l2 * c2) * a[0] + l2**2 * a[1] + l1 * l2 * s2 * dq[0] * v[0] + l2 * g * c12
    return np.array([[Y11, Y12], [Y21, Y22]])


def spec_inverse_dynamics(arm, q, dq, ddq, m):
    return spec_M(arm, q, m) @ ddq + spec_Vm(arm, q, dq, m) @ dq + spec_G(arm, q, m)


def random_instant(rng, n=2, p=2):
    """(phi, q, dq, ref) at a random instant: true masses in [0.3, 3], states and desired motion in a few units."""
    phi = rng.uniform(0.3, 3.0, p)
    q, dq = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)
    ref = Reference(rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-3, 3, n))
    return phi, q, dq, ref


def slotine_li(arm, gains, phi_hat0):
    return InertiaRelated(arm, Lam=gains["Lam"], Kv=gains["Kv"], Gamma=gains["Gamma"], phi_hat0=phi_hat0)


# --------------------------------------------------------------------------------------------------------------------
# Perfect knowledge and zero error: τ is the inverse dynamics of the desired motion, and nothing adapts


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_exact_model_and_zero_error_gives_inverse_dynamics(arm, seed):
    phi, _, _, ref = random_instant(np.random.default_rng(seed))
    q, dq = ref.q_des.copy(), ref.dq_des.copy()
    tau_des = spec_inverse_dynamics(arm, ref.q_des, ref.dq_des, ref.ddq_des, phi)

    ctrl = slotine_li(arm, FULL_GAINS, phi)
    tau, dx = ctrl(0.3, phi, q, dq, ref)
    np.testing.assert_allclose(tau, tau_des, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(dx, np.zeros(2))

    ct = ComputedTorque(arm, Kp=[4.0, 5.0], Kv=4.0, phi_hat0=phi)
    tau, dx = ct(0.3, ct.initial_state(REST, REST), q, dq, ref)
    np.testing.assert_allclose(tau, tau_des, rtol=1e-12, atol=1e-12)
    assert dx.shape == (0,)


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_pd_gravity_at_a_set_point_gives_gravity(arm, seed):
    phi, q, _, _ = random_instant(np.random.default_rng(seed))
    ref = constant(2, q)(1.7)
    ctrl = PDGravity(arm, Kp=[125.0, 50.0], Kv=FULL_GAINS["Kv"], phi_hat0=phi)
    tau, dx = ctrl(1.7, ctrl.initial_state(REST, REST), q, np.zeros(2), ref)
    np.testing.assert_allclose(tau, spec_G(arm, q, phi), rtol=1e-12, atol=1e-12)
    assert dx.shape == (0,)
    # off the set point: τ = K_p e + K_v ė + Ĝ(q)   (6.3.5, with ė = −q̇ for a set point)
    q_now, dq_now = q + [0.1, -0.2], np.array([0.5, -1.0])
    e, de = q - q_now, -dq_now
    tau, _ = ctrl(1.7, ctrl.initial_state(REST, REST), q_now, dq_now, ref)
    np.testing.assert_allclose(tau, np.diag([125.0, 50.0]) @ e + FULL_GAINS["Kv"] @ de + spec_G(arm, q_now, phi),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_pd_is_zero_at_zero_error_and_linear_in_the_errors(seed):
    phi, q, dq, ref = random_instant(np.random.default_rng(seed))
    ctrl = PD(BOOK, Kp=[[5.0, 1.0], [1.0, 2.0]], Kv=3.0, phi_hat0=np.zeros(2))
    tau, dx = ctrl(0.0, ctrl.initial_state(REST, REST), ref.q_des, ref.dq_des, ref)
    np.testing.assert_array_equal(tau, np.zeros(2))
    assert dx.shape == (0,)
    tau, _ = ctrl(0.0, ctrl.initial_state(REST, REST), q, dq, ref)
    np.testing.assert_allclose(tau, np.array([[5.0, 1.0], [1.0, 2.0]]) @ (ref.q_des - q) + 3.0 * (ref.dq_des - dq),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_computed_torque_with_error(arm, seed):
    """τ = M̂(q)(q̈_d + K_v ė + K_p e) + V̂_m q̇ + Ĝ   (6.2.2), with fixed wrong estimates."""
    rng = np.random.default_rng(seed)
    _, q, dq, ref = random_instant(rng)
    phi_hat = np.array([0.85, 2.2])
    Kp, Kv = np.array([[4.0, 1.0], [1.0, 6.0]]), np.diag([4.0, 2.0])
    ct = ComputedTorque(arm, Kp=Kp, Kv=Kv, phi_hat0=phi_hat)
    e, de = ref.q_des - q, ref.dq_des - dq
    u = ref.ddq_des + Kv @ de + Kp @ e
    expected = spec_M(arm, q, phi_hat) @ u + spec_Vm(arm, q, dq, phi_hat) @ dq + spec_G(arm, q, phi_hat)
    tau, _ = ct(0.0, ct.initial_state(REST, REST), q, dq, ref)
    np.testing.assert_allclose(tau, expected, rtol=1e-12, atol=1e-10)


# --------------------------------------------------------------------------------------------------------------------
# Slotine–Li at a random instant, written out from Table 6.3.1


@pytest.mark.parametrize("gains", GAINS)
@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_slotine_li_torque_and_update_by_hand(arm, gains, seed):
    rng = np.random.default_rng(seed)
    _, q, dq, ref = random_instant(rng)
    phi_hat = rng.uniform(-1.0, 3.0, 2)
    Lam, Kv, Gamma = (gain(gains[k]) for k in ("Lam", "Kv", "Gamma"))
    e, de = ref.q_des - q, ref.dq_des - dq
    r = de + Lam @ e  # (6.3.8)
    Y = spec_Y(arm, q, dq, ref.dq_des + Lam @ e, ref.ddq_des + Lam @ de)  # (6.3.11)
    ctrl = slotine_li(arm, gains, phi_hat)
    tau, dx = ctrl(0.0, phi_hat, q, dq, ref)
    np.testing.assert_allclose(tau, Y @ phi_hat + Kv @ r, rtol=1e-12, atol=1e-10)  # (6.3.14)
    np.testing.assert_allclose(dx, Gamma @ Y.T @ r, rtol=1e-12, atol=1e-10)  # (6.3.16)
    np.testing.assert_allclose(ctrl.filtered_error(0.0, phi_hat, q, dq, ref), r, rtol=1e-14, atol=1e-14)


def test_slotine_li_update_written_per_joint():
    """Example 6.3.1 written per joint: dm̂1/dt = γ1 (Y11 r1 + Y21 r2), dm̂2/dt = γ2 (Y12 r1 + Y22 r2)."""
    q, dq = np.array([0.3, -0.8]), np.array([0.2, 1.1])
    ref = Reference(np.sin([1.0, 1.0]), np.cos([1.0, 1.0]), -np.sin([1.0, 1.0]))  # q_d = sin t at t = 1
    lam, gam = 2.5, 20.0
    e, de = ref.q_des - q, ref.dq_des - dq
    r = de + lam * e
    Y = spec_Y(BOOK, q, dq, ref.dq_des + lam * e, ref.ddq_des + lam * de)
    ctrl = slotine_li(BOOK, BOOK_GAINS, np.zeros(2))
    _, dx = ctrl(1.0, np.zeros(2), q, dq, ref)
    np.testing.assert_allclose(dx, [gam * (Y[0, 0] * r[0] + Y[1, 0] * r[1]), gam * (Y[0, 1] * r[0] + Y[1, 1] * r[1])],
                               rtol=1e-12)


@pytest.mark.parametrize("gains", GAINS)
@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_slotine_li_lyapunov_by_hand(arm, gains, seed):
    """V = ½ rᵀ M(q) r + ½ φ̃ᵀ Γ⁻¹ φ̃   (6.3.7), φ̃ = φ − φ̂."""
    rng = np.random.default_rng(seed)
    phi, q, dq, ref = random_instant(rng)
    phi_hat = rng.uniform(-1.0, 3.0, 2)
    Lam, Gamma = gain(gains["Lam"]), gain(gains["Gamma"])
    r = (ref.dq_des - dq) + Lam @ (ref.q_des - q)
    phi_err = phi - phi_hat
    expected = 0.5 * r @ spec_M(arm, q, phi) @ r + 0.5 * phi_err @ np.linalg.solve(Gamma, phi_err)
    V = slotine_li(arm, gains, phi_hat).lyapunov(0.0, phi_hat, q, dq, ref, phi)
    assert np.shape(V) == ()
    assert V == pytest.approx(expected, rel=1e-12)


def closed_loop_dVdt(ctrl, arm, phi, q, dq, x, ref, flip_update=False, h=1e-3):
    """dV/dt along the closed loop at one instant, by a fourth-order central difference in time.

    The state moves with q̇, q̈ = forward dynamics of the plant under the controller's τ, and dx (or −dx); the desired
    motion moves with q̇_d, q̈_d. V depends on (q, q̇, x, q_d, q̇_d) only, so first-order motion gives the exact
    derivative at s = 0.
    """
    tau, dx = ctrl(0.0, x, q, dq, ref)
    ddq = arm.forward_dynamics(q, dq, tau, phi)
    dx = -dx if flip_update else dx

    def V(s):
        ref_s = Reference(ref.q_des + s * ref.dq_des, ref.dq_des + s * ref.ddq_des, ref.ddq_des)
        return ctrl.lyapunov(s, x + s * dx, q + s * dq, dq + s * ddq, ref_s, phi)

    return (-V(2 * h) + 8 * V(h) - 8 * V(-h) + V(-2 * h)) / (12 * h), tau, dx


def closed_loop_instants():
    rng = np.random.default_rng(2024)
    for kind, arm in [("book-arm", BOOK), ("other-arm", OTHER), ("polar", PolarArm(friction_terms=True)),
                      ("one-link-stiff", OneLinkArm(stiffness=True))]:
        for seed in range(4):
            n, p = arm.n, arm.p
            phi = rng.uniform(0.3, 3.0, p)
            q = rng.uniform(-np.pi, np.pi, n)
            if isinstance(arm, PolarArm):
                q[1] = rng.uniform(0.3, 2.0)
            ref = Reference(q + rng.uniform(-0.5, 0.5, n), rng.uniform(-2, 2, n), rng.uniform(-3, 3, n))
            yield pytest.param(arm, phi, q, rng.uniform(-2, 2, n), rng.uniform(-1.0, 3.0, p), ref, id=f"{kind}-{seed}")


def gains_for(arm):
    n, p = arm.n, arm.p
    Lam = np.diag(np.linspace(2.5, 1.5, n)) + 0.3 * (np.ones((n, n)) - np.eye(n))
    return {"Lam": Lam, "Kv": np.diag(np.linspace(10.0, 4.0, n)), "Gamma": np.diag(np.linspace(20.0, 5.0, p))}


@pytest.mark.parametrize(("arm", "phi", "q", "dq", "phi_hat", "ref"), list(closed_loop_instants()))
def test_lyapunov_derivative_along_the_closed_loop(arm, phi, q, dq, phi_hat, ref):
    """(6.3.17)  dV/dt = −rᵀ K_v r at any instant, for any φ̂ ≠ φ; with the update's sign flipped it is not."""
    gains = gains_for(arm)
    ctrl = slotine_li(arm, gains, phi_hat)
    r = (ref.dq_des - dq) + gains["Lam"] @ (ref.q_des - q)
    expected = -r @ gains["Kv"] @ r
    dVdt, _, dx = closed_loop_dVdt(ctrl, arm, phi, q, dq, phi_hat, ref)
    assert dVdt == pytest.approx(expected, rel=1e-8, abs=1e-8)
    # the identity is sensitive to the update law: −Γ Yᵀ r adds 2 φ̃ᵀ Yᵀ r, generically far from zero
    flipped, _, _ = closed_loop_dVdt(ctrl, arm, phi, q, dq, phi_hat, ref, flip_update=True)
    gap = 2 * (phi - phi_hat) @ np.linalg.solve(gains["Gamma"], dx)
    assert abs(gap) > 1e-3
    assert flipped == pytest.approx(expected + gap, rel=1e-8, abs=1e-8)


# --------------------------------------------------------------------------------------------------------------------
# Batches: stacked inputs give stacked single calls

CONTROLLERS = {
    "slotine-li": lambda: slotine_li(OTHER, FULL_GAINS, np.array([0.5, 1.5])),
    "computed-torque": lambda: ComputedTorque(OTHER, Kp=[[4.0, 1.0], [1.0, 3.0]], Kv=[4.0, 2.0],
                                              phi_hat0=np.array([0.85, 2.2])),
    "pd-gravity": lambda: PDGravity(OTHER, Kp=[20.0, 10.0], Kv=5.0, phi_hat0=np.array([0.85, 2.2])),
    "pd": lambda: PD(OTHER, Kp=[20.0, 10.0], Kv=FULL_GAINS["Kv"], phi_hat0=np.zeros(2)),
}


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_batch_equals_stacked_single_calls(name):
    ctrl = CONTROLLERS[name]()
    rng, lead = np.random.default_rng(5), (3, 4)
    x0 = ctrl.initial_state(REST, REST)
    x = x0 + rng.uniform(-1, 1, lead + x0.shape)
    q, dq = rng.uniform(-3, 3, lead + (2,)), rng.uniform(-2, 2, lead + (2,))
    ref = Reference(*(rng.uniform(-2, 2, lead + (2,)) for _ in range(3)))
    t = rng.uniform(0, 10, lead)
    tau, dx = ctrl(t, x, q, dq, ref)
    assert tau.shape == lead + (2,)
    assert dx.shape == lead + x0.shape
    for idx in np.ndindex(*lead):
        tau_i, dx_i = ctrl(t[idx], x[idx], q[idx], dq[idx], Reference(*(a[idx] for a in ref)))
        np.testing.assert_allclose(tau[idx], tau_i, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(dx[idx], dx_i, rtol=1e-13, atol=1e-12)
    if ctrl.has("lyapunov"):
        phi = np.array([0.8, 2.3])
        V = ctrl.lyapunov(t, x, q, dq, ref, phi)
        assert V.shape == lead
        for idx in np.ndindex(*lead):
            assert V[idx] == pytest.approx(ctrl.lyapunov(t[idx], x[idx], q[idx], dq[idx],
                                                         Reference(*(a[idx] for a in ref)), phi), rel=1e-13)


# --------------------------------------------------------------------------------------------------------------------
# Gains and estimates are validated at construction, and the error names the field

GOOD = {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0, "Kp": 4.0, "phi_hat0": np.zeros(2)}
BAD_GAINS = [
    pytest.param(-1.0, id="negative"),
    pytest.param(0.0, id="zero"),
    pytest.param([[1.0, 2.0], [2.0, 1.0]], id="indefinite"),
    pytest.param([[1.0, 0.5], [0.0, 1.0]], id="non-symmetric"),
    pytest.param([1.0, -2.0], id="negative-diagonal"),
    pytest.param([1.0, 2.0, 3.0], id="wrong-length"),
    pytest.param(np.eye(3), id="wrong-shape"),
    pytest.param(np.ones((2, 2, 2)), id="3-d"),
    pytest.param(float("nan"), id="nan"),
    pytest.param([1.0, float("inf")], id="inf"),
    pytest.param("10", id="string"),
    pytest.param(True, id="bool"),
]
BAD_ESTIMATES = [
    pytest.param([1.0, 2.0, 3.0], id="too-long"),
    pytest.param([1.0], id="too-short"),
    pytest.param(1.0, id="scalar"),
    pytest.param([1.0, float("nan")], id="nan"),
    pytest.param(None, id="none"),
]
KINDS = {
    InertiaRelated: ("Lam", "Kv", "Gamma", "phi_hat0"),
    ComputedTorque: ("Kp", "Kv", "phi_hat0"),
    PDGravity: ("Kp", "Kv", "phi_hat0"),
    PD: ("Kp", "Kv", "phi_hat0"),
}


def build(cls, **override):
    kwargs = {name: override.get(name, GOOD[name]) for name in KINDS[cls]}
    return cls(BOOK, **kwargs)


@pytest.mark.parametrize("bad", BAD_GAINS)
@pytest.mark.parametrize(("cls", "field"), [(cls, f) for cls, fields in KINDS.items() for f in fields
                                            if f != "phi_hat0"], ids=lambda v: getattr(v, "__name__", v))
def test_bad_gain_is_rejected_naming_the_field(cls, field, bad):
    with pytest.raises(ConfigError, match=rf"^{re.escape('controller.' + field)}: ") as info:
        build(cls, **{field: bad})
    assert info.value.field == f"controller.{field}"


@pytest.mark.parametrize("bad", BAD_ESTIMATES)
@pytest.mark.parametrize("cls", list(KINDS), ids=lambda c: c.__name__)
def test_bad_estimate_is_rejected_naming_the_field(cls, bad):
    with pytest.raises(ConfigError, match=r"^controller\.phi_hat0: ") as info:
        build(cls, phi_hat0=bad)
    assert info.value.field == "controller.phi_hat0"


def test_gamma_is_sized_by_the_parameter_count():
    """Γ is p×p (4 with friction terms), Λ and K_v are n×n."""
    arm = TwoLinkArm(friction_terms=True)
    ok = InertiaRelated(arm, Lam=1.0, Kv=1.0, Gamma=[1.0, 2.0, 3.0, 4.0], phi_hat0=np.zeros(4))
    np.testing.assert_array_equal(ok.Gamma, np.diag([1.0, 2.0, 3.0, 4.0]))
    with pytest.raises(ConfigError, match=r"^controller\.Gamma: "):
        InertiaRelated(arm, Lam=1.0, Kv=1.0, Gamma=np.eye(2), phi_hat0=np.zeros(4))


def test_valid_gain_forms():
    ctrl = InertiaRelated(BOOK, Lam=2.5, Kv=[10.0, 5.0], Gamma=FULL_GAINS["Gamma"], phi_hat0=[0.0, 0.0])
    np.testing.assert_array_equal(ctrl.Lam, [[2.5, 0.0], [0.0, 2.5]])
    np.testing.assert_array_equal(ctrl.Kv, [[10.0, 0.0], [0.0, 5.0]])
    np.testing.assert_array_equal(ctrl.Gamma, FULL_GAINS["Gamma"])
    np.testing.assert_array_equal(ctrl.initial_state(REST, REST), [0.0, 0.0])
    # the initial state is a copy: the controller's constant cannot be changed through it
    x = ctrl.initial_state(REST, REST)
    x[0] = 7.0
    np.testing.assert_array_equal(ctrl.initial_state(REST, REST), [0.0, 0.0])
