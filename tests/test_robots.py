"""Physical identities of the robot models (spec §1), as property tests over random states and positive parameters.

Every expected value here is computed independently of the library: the spec's closed forms (§1.3–§1.5) written out by
hand, potential energies differentiated numerically, or Christoffel symbols built from finite differences of M.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robotadapt.robots import OneLinkArm, PolarArm, TwoLinkArm

SETTINGS = settings(max_examples=50, deadline=None)

KINDS = ["one-link", "one-link-stiff", "two-link", "two-link-friction", "polar", "polar-friction"]

angles = st.floats(-np.pi, np.pi, allow_nan=False)
rates = st.floats(-3.0, 3.0, allow_nan=False)
positive = st.floats(0.1, 5.0, allow_nan=False)
lengths = st.floats(0.2, 2.0, allow_nan=False)
gravities = st.floats(0.0, 20.0, allow_nan=False)
# The polar arm's prismatic coordinate: |r| in [0.2, 3], away from the singularity r = 0.
radii = st.tuples(st.floats(0.2, 3.0, allow_nan=False), st.sampled_from([-1.0, 1.0])).map(lambda rs: rs[0] * rs[1])


def arm_strategy(kind: str) -> st.SearchStrategy:
    if kind == "one-link":
        return st.just(OneLinkArm())
    if kind == "one-link-stiff":
        return st.just(OneLinkArm(stiffness=True))
    if kind.startswith("two-link"):
        return st.builds(TwoLinkArm, l1=lengths, l2=lengths, g=gravities,
                         friction_terms=st.just(kind.endswith("friction")))
    return st.builds(PolarArm, g=gravities, friction_terms=st.just(kind.endswith("friction")))


def vec(strategy: st.SearchStrategy, n: int) -> st.SearchStrategy:
    return st.lists(strategy, min_size=n, max_size=n).map(np.array)


@st.composite
def cases(draw: st.DrawFn, kind: str) -> tuple:
    """(arm, phi, q, dq, v, a) with independent v and a."""
    arm = draw(arm_strategy(kind))
    n = arm.n
    q = np.array([draw(angles), draw(radii)]) if isinstance(arm, PolarArm) else draw(vec(angles, n))
    return arm, draw(vec(positive, arm.p)), q, draw(vec(rates, n)), draw(vec(rates, n)), draw(vec(rates, n))


# --------------------------------------------------------------------------------------------------------------------
# The spec's closed forms, written out by hand (one instant, plain floats)


def spec_terms(arm, q, dq, phi):
    """(M, V_m, G, F) of spec §1.3 (two-link), §1.4 (one-link, + k q) and §1.5 (polar), from the formulas in the spec."""
    if isinstance(arm, OneLinkArm):
        m, b = phi[0], phi[1]
        k = phi[2] if arm.stiffness else 0.0
        return np.array([[m]]), np.array([[0.0]]), np.array([k * q[0]]), np.array([b * dq[0]])
    if isinstance(arm, TwoLinkArm):
        m1, m2 = phi[0], phi[1]
        l1, l2, g = arm.l1, arm.l2, arm.g
        c1, c2, s2, c12 = np.cos(q[0]), np.cos(q[1]), np.sin(q[1]), np.cos(q[0] + q[1])
        M = np.array([[(m1 + m2) * l1**2 + m2 * l2**2 + 2 * m2 * l1 * l2 * c2, m2 * l2**2 + m2 * l1 * l2 * c2],
                      [m2 * l2**2 + m2 * l1 * l2 * c2, m2 * l2**2]])
        V = m2 * l1 * l2 * s2 * np.array([[-dq[1], -(dq[0] + dq[1])], [dq[0], 0.0]])
        G = np.array([(m1 + m2) * g * l1 * c1 + m2 * g * l2 * c12, m2 * g * l2 * c12])
        F = phi[2:4] * dq if arm.friction_terms else np.zeros(2)
        return M, V, G, F
    m, g = phi[0], arm.g
    th, r, dth, dr = q[0], q[1], dq[0], dq[1]
    M = np.diag([m * r**2, m])
    V = m * np.array([[r * dr, r * dth], [-r * dth, 0.0]])
    G = np.array([m * g * r * np.cos(th), m * g * np.sin(th)])
    F = phi[1:3] * dq if arm.friction_terms else np.zeros(2)
    return M, V, G, F


def potential(arm, q, phi) -> float:
    """Potential energy U(q): gravity for the two-link and polar arms, the joint spring ½ k q² for the one-link arm."""
    if isinstance(arm, OneLinkArm):
        return 0.5 * phi[2] * q[0] ** 2 if arm.stiffness else 0.0
    if isinstance(arm, TwoLinkArm):
        m1, m2 = phi[0], phi[1]
        s1, s12 = np.sin(q[0]), np.sin(q[0] + q[1])
        return m1 * arm.g * arm.l1 * s1 + m2 * arm.g * (arm.l1 * s1 + arm.l2 * s12)
    return phi[0] * arm.g * q[1] * np.sin(q[0])


def model_terms(arm, q, dq, phi):
    return arm.mass_matrix(q, phi), arm.coriolis_matrix(q, dq, phi), arm.gravity(q, phi), arm.friction(dq, phi)


def mdot_fd(arm, q, dq, phi, h=1e-6):
    """Ṁ = dM(q(t))/dt along q̇, by central differences."""
    return (arm.mass_matrix(q + h * dq, phi) - arm.mass_matrix(q - h * dq, phi)) / (2 * h)


def skew_defect(Mdot, V) -> float:
    """max |S + Sᵀ| for S = Ṁ − 2V: zero exactly when Ṁ − 2V is skew-symmetric."""
    S = Mdot - 2 * V
    return float(np.abs(S + S.T).max())


def skew_tolerance(Mdot, V) -> float:
    """With h = 1e-6 the central-difference error (O(h²) truncation, O(eps/h) round-off) is far below 1e-6 of the
    terms' size."""
    return 1e-6 * (1.0 + np.abs(Mdot).max() + np.abs(V).max())


def close(actual, expected, rel=1e-10, scale=1.0):
    """Assert equality to `rel` of the problem's scale (not of each entry, which may be a cancellation)."""
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rel * (1.0 + scale))


# --------------------------------------------------------------------------------------------------------------------
# Property tests, one per identity, each over all six arm configurations


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_terms_are_the_spec_closed_forms(kind, data):
    arm, phi, q, dq, _, _ = data.draw(cases(kind))
    for got, want in zip(model_terms(arm, q, dq, phi), spec_terms(arm, q, dq, phi), strict=True):
        assert got.shape == want.shape
        close(got, want, scale=np.abs(want).max())


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_regressor_is_linear_in_phi_with_two_slots(kind, data):
    """(P3)  Y(q, q̇, v, a) φ = M a + V_m v + G + F, with v and a independent of q̇."""
    arm, phi, q, dq, v, a = data.draw(cases(kind))
    M, V, G, F = model_terms(arm, q, dq, phi)
    Y = arm.regressor(q, dq, v, a)
    assert Y.shape == (arm.n, arm.p)
    scale = np.abs(M).max() * np.abs(a).max() + np.abs(V).max() * np.abs(v).max() + np.abs(G).max() + np.abs(F).max()
    close(Y @ phi, M @ a + V @ v + G + F, scale=scale)
    # and against the spec's terms directly, so that a shared error in M/V/G/F and Y cannot hide
    Ms, Vs, Gs, Fs = spec_terms(arm, q, dq, phi)
    close(Y @ phi, Ms @ a + Vs @ v + Gs + Fs, scale=scale)


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_mdot_minus_2v_is_skew_symmetric(kind, data):
    """(P2)  Ṁ − 2V_m is skew-symmetric, Ṁ by central differences along q̇."""
    arm, phi, q, dq, _, _ = data.draw(cases(kind))
    Mdot = mdot_fd(arm, q, dq, phi)
    V = arm.coriolis_matrix(q, dq, phi)
    assert skew_defect(Mdot, V) <= skew_tolerance(Mdot, V)
    # equivalently Ṁ = V_m + V_mᵀ
    close(Mdot, V + V.T, rel=1e-6, scale=np.abs(Mdot).max() + np.abs(V).max())


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_coriolis_matrix_is_the_christoffel_form(kind, data):
    """V_m,kj = Σ_i c_ijk q̇_i, c_ijk = ½(∂M_kj/∂q_i + ∂M_ki/∂q_j − ∂M_ij/∂q_k) (spec §1.2 P2), ∂M by differences."""
    arm, phi, q, dq, _, _ = data.draw(cases(kind))
    n, h = arm.n, 1e-6
    eye = np.eye(n)
    dM = np.array([(arm.mass_matrix(q + h * eye[i], phi) - arm.mass_matrix(q - h * eye[i], phi)) / (2 * h)
                   for i in range(n)])  # dM[i, k, j] = ∂M_kj/∂q_i
    c = np.zeros((n, n, n))
    for i, j, k in itertools.product(range(n), repeat=3):
        c[i, j, k] = 0.5 * (dM[i, k, j] + dM[j, k, i] - dM[k, i, j])
    V_christoffel = np.einsum("ijk,i->kj", c, dq)
    V = arm.coriolis_matrix(q, dq, phi)
    close(V, V_christoffel, rel=1e-6, scale=np.abs(dM).max() * np.abs(dq).max())


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_mass_matrix_is_symmetric_positive_definite(kind, data):
    """(P1)  M = Mᵀ > 0."""
    arm, phi, q, _, _, _ = data.draw(cases(kind))
    M = arm.mass_matrix(q, phi)
    assert M.shape == (arm.n, arm.n)
    np.testing.assert_allclose(M, M.T, rtol=1e-14, atol=0)
    assert np.linalg.eigvalsh(M).min() > 0


@SETTINGS
@given(arm=arm_strategy("two-link"), m=vec(positive, 2), q=vec(angles, 2))
def test_two_link_determinant(arm, m, q):
    """det M = m2 l1² l2² (m1 + m2 s2²) (spec §1.3)."""
    det = m[1] * arm.l1**2 * arm.l2**2 * (m[0] + m[1] * np.sin(q[1]) ** 2)
    M = arm.mass_matrix(q, m)
    np.testing.assert_allclose(np.linalg.det(M), det, rtol=1e-8, atol=1e-12 * np.abs(M).max() ** 2)


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_gravity_is_the_gradient_of_the_potential(kind, data):
    """G = ∂U/∂q, by central differences of the hand-written potential energy."""
    arm, phi, q, _, _, _ = data.draw(cases(kind))
    h = 1e-6
    grad = np.array([(potential(arm, q + h * e, phi) - potential(arm, q - h * e, phi)) / (2 * h)
                     for e in np.eye(arm.n)])
    G = arm.gravity(q, phi)
    assert G.shape == (arm.n,)
    close(G, grad, rel=1e-6, scale=np.abs(grad).max())


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_momentum_and_remainder_regressors(kind, data):
    """Y_h φ = M q̇ (6.6.3);  Y_g φ = −V_mᵀ q̇ + G + F (6.6.4)."""
    arm, phi, q, dq, _, _ = data.draw(cases(kind))
    M, V, G, F = spec_terms(arm, q, dq, phi)
    Yh, Yg = arm.momentum_regressor(q, dq), arm.remainder_regressor(q, dq)
    assert Yh.shape == Yg.shape == (arm.n, arm.p)
    close(Yh @ phi, M @ dq, scale=np.abs(M).max() * np.abs(dq).max())
    close(Yg @ phi, -V.T @ dq + G + F, scale=np.abs(V).max() * np.abs(dq).max() + np.abs(G).max() + np.abs(F).max())
    # the filtering identity: d/dt(Y_h φ) + Y_g φ = τ for τ = M q̈ + V_m q̇ + G + F (6.6.3–6.6.4), with Ṁ = V_m + V_mᵀ
    ddq = np.linspace(-1.0, 1.0, arm.n)
    Mdot = mdot_fd(arm, q, dq, phi)
    tau = arm.inverse_dynamics(q, dq, ddq, phi)
    close(M @ ddq + Mdot @ dq + Yg @ phi, tau, rel=1e-6,
          scale=np.abs(tau).max() + np.abs(Mdot).max() * np.abs(dq).max() + np.abs(M).max())


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(data=st.data())
def test_forward_dynamics_inverts_inverse_dynamics(kind, data):
    arm, phi, q, dq, ddq, tau = data.draw(cases(kind))
    M, V, G, F = spec_terms(arm, q, dq, phi)
    tau_of_ddq = arm.inverse_dynamics(q, dq, ddq, phi)
    close(tau_of_ddq, M @ ddq + V @ dq + G + F, scale=np.abs(tau_of_ddq).max())
    # M q̈ + bias = τ is the well-conditioned residual; q̈ itself is recovered up to cond(M)
    ddq_of_tau = arm.forward_dynamics(q, dq, tau, phi)
    scale = np.abs(tau).max() + np.abs(V).max() * np.abs(dq).max() + np.abs(G).max() + np.abs(F).max()
    close(M @ ddq_of_tau + V @ dq + G + F, tau, scale=scale)
    roundtrip = arm.forward_dynamics(q, dq, tau_of_ddq, phi)
    close(roundtrip, ddq, rel=1e-8 * np.linalg.cond(M), scale=np.abs(ddq).max() + scale / np.linalg.eigvalsh(M).min())


# --------------------------------------------------------------------------------------------------------------------
# Closed-form spot checks with the book's numbers (Example 6.3.1: m1 = 0.8, m2 = 2.3, l1 = l2 = 1, g = 9.8)

BOOK_PHI = np.array([0.8, 2.3])


@pytest.mark.parametrize(
    ("q2", "expected"),
    [
        # M11 = (m1+m2) + m2 + 2 m2 = 3.1 + 2.3 + 4.6;  M12 = m2 + m2 = 4.6;  M22 = m2
        (0.0, [[10.0, 4.6], [4.6, 2.3]]),
        # c2 = 0:  M11 = 3.1 + 2.3;  M12 = M22 = m2
        (np.pi / 2, [[5.4, 2.3], [2.3, 2.3]]),
    ],
)
def test_two_link_mass_matrix_book_numbers(q2, expected):
    M = TwoLinkArm().mass_matrix(np.array([0.3, q2]), BOOK_PHI)
    np.testing.assert_allclose(M, expected, rtol=1e-12, atol=1e-12)


def test_two_link_gravity_and_coriolis_book_numbers():
    arm = TwoLinkArm()
    # q = 0: G = [(m1+m2) g + m2 g, m2 g] = [5.4·9.8, 2.3·9.8]
    np.testing.assert_allclose(arm.gravity(np.zeros(2), BOOK_PHI), [52.92, 22.54], rtol=1e-12)
    # arm straight up (q1 = π/2, q2 = 0): no gravity torque
    np.testing.assert_allclose(arm.gravity(np.array([np.pi / 2, 0.0]), BOOK_PHI), [0.0, 0.0], atol=1e-12)
    # q2 = π/2, q̇ = (1, 2): m2 l1 l2 s2 = 2.3, V_m = 2.3 [[-2, -3], [1, 0]],
    # V_m q̇ = [-m2 s2 (2 q̇1 q̇2 + q̇2²), m2 s2 q̇1²] = [-18.4, 2.3]
    q, dq = np.array([0.1, np.pi / 2]), np.array([1.0, 2.0])
    V = arm.coriolis_matrix(q, dq, BOOK_PHI)
    np.testing.assert_allclose(V, [[-4.6, -6.9], [2.3, 0.0]], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(V @ dq, [-18.4, 2.3], rtol=1e-12)


def test_polar_and_one_link_book_numbers():
    polar = PolarArm()
    # m = 1.5, r = 2: M = diag(m r², m) = diag(6, 1.5); θ = 0: G = [m g r, 0] = [29.4, 0]
    q, phi = np.array([0.0, 2.0]), np.array([1.5])
    np.testing.assert_allclose(polar.mass_matrix(q, phi), [[6.0, 0.0], [0.0, 1.5]], rtol=1e-12)
    np.testing.assert_allclose(polar.gravity(q, phi), [29.4, 0.0], rtol=1e-12, atol=1e-12)
    # Example 6.5.2: m = b = 1, τ = m q̈ + b q̇
    one = OneLinkArm()
    np.testing.assert_allclose(one.inverse_dynamics(np.array([0.4]), np.array([2.0]), np.array([-3.0]),
                                                    np.array([1.0, 1.0])), [-1.0])


def test_a_wrong_coriolis_factorisation_fails_the_skew_check():
    """The non-Christoffel V' = m2 l1 l2 s2 [[-2 q̇2, -q̇2], [q̇1, 0]] has V' q̇ = V_m q̇, so the regressor identity
    at v = q̇ cannot tell them apart, but Ṁ − 2V' is not skew-symmetric: the check above can fail."""
    arm, phi = TwoLinkArm(l1=0.9, l2=1.2), np.array([0.8, 2.3])
    q, dq = np.array([0.4, 1.1]), np.array([0.7, -1.3])
    h = phi[1] * arm.l1 * arm.l2 * np.sin(q[1])
    V_wrong = h * np.array([[-2 * dq[1], -dq[1]], [dq[0], 0.0]])
    V = arm.coriolis_matrix(q, dq, phi)
    np.testing.assert_allclose(V_wrong @ dq, V @ dq, rtol=1e-12)
    Mdot = mdot_fd(arm, q, dq, phi)
    assert skew_defect(Mdot, V) <= skew_tolerance(Mdot, V)
    assert skew_defect(Mdot, V_wrong) > 1e3 * skew_tolerance(Mdot, V_wrong)


# --------------------------------------------------------------------------------------------------------------------
# Batches: leading axes broadcast, outputs carry exactly the broadcast leading axes and equal stacked single calls

ARMS = {
    "one-link": OneLinkArm(),
    "one-link-stiff": OneLinkArm(stiffness=True),
    "two-link": TwoLinkArm(),
    "two-link-friction": TwoLinkArm(l1=0.7, l2=1.3, g=9.81, friction_terms=True),
    "polar": PolarArm(),
    "polar-friction": PolarArm(friction_terms=True),
}
METHODS = {
    "mass_matrix": ("q", "phi"),
    "coriolis_matrix": ("q", "dq", "phi"),
    "gravity": ("q", "phi"),
    "friction": ("dq", "phi"),
    "regressor": ("q", "dq", "v", "a"),
    "remainder_regressor": ("q", "dq"),
    "momentum_regressor": ("q", "dq"),
    "inverse_dynamics": ("q", "dq", "ddq", "phi"),
    "forward_dynamics": ("q", "dq", "tau", "phi"),
}
LEAD = (3, 4)


def random_args(arm, lead, rng):
    n, p = arm.n, arm.p
    q = rng.uniform(-np.pi, np.pi, lead + (n,))
    if isinstance(arm, PolarArm):
        q[..., 1] = rng.choice([-1.0, 1.0], lead) * rng.uniform(0.2, 3.0, lead)
    vec_ = {name: rng.uniform(-3, 3, lead + (n,)) for name in ("dq", "v", "a", "ddq", "tau")}
    return {"q": q, "phi": rng.uniform(0.1, 5.0, lead + (p,)), **vec_}


def single_call(arm, method, args, idx):
    """Call `method` with every batched argument indexed at `idx` (unbatched arguments passed as they are)."""
    return getattr(arm, method)(*[a[idx] if a.ndim > 1 else a for a in args])


def _batch_cases(batched_args):
    for kind, method in itertools.product(ARMS, METHODS):
        for batched in batched_args(METHODS[method]):
            yield pytest.param(kind, method, batched, id=f"{kind}-{method}-{'+'.join(batched)}")


@pytest.mark.parametrize(("kind", "method", "batched"), list(_batch_cases(
    lambda names: [tuple(a for a in names if a != "phi"), names] if "phi" in names else [names])))
def test_batch_equals_stacked_single_calls(kind, method, batched):
    """All state arguments with leading axes (3, 4); phi either `(p,)` or `(3, 4, p)`."""
    arm, rng = ARMS[kind], np.random.default_rng(3)
    full = random_args(arm, LEAD, rng)
    args = [full[name] if name in batched else full[name][0, 0] for name in METHODS[method]]
    out = getattr(arm, method)(*args)
    one = single_call(arm, method, args, (0, 0))
    assert out.shape == LEAD + one.shape
    for idx in np.ndindex(*LEAD):
        np.testing.assert_allclose(out[idx], single_call(arm, method, args, idx), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize(("kind", "method", "batched"), list(_batch_cases(lambda names: [(a,) for a in names])))
def test_one_batched_argument_sets_the_leading_axes(kind, method, batched):
    """Only one argument carries leading axes (3, 4): the output still carries exactly those axes."""
    arm, rng = ARMS[kind], np.random.default_rng(7)
    full = random_args(arm, LEAD, rng)
    args = [full[name] if name in batched else full[name][0, 0] for name in METHODS[method]]
    out = getattr(arm, method)(*args)
    one = single_call(arm, method, args, (0, 0))
    assert out.shape == LEAD + one.shape
    for idx in np.ndindex(*LEAD):
        np.testing.assert_allclose(out[idx], single_call(arm, method, args, idx), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("kind", list(ARMS))
def test_leading_axes_broadcast_against_each_other(kind):
    """q of shape (4, n) with phi of shape (3, 1, p) gives (3, 4, ...), as numpy broadcasting would."""
    arm, rng = ARMS[kind], np.random.default_rng(11)
    full = random_args(arm, (3, 4), rng)
    q, dq, ddq, phi = full["q"][0], full["dq"][0], full["ddq"][0], full["phi"][:, :1]
    M = arm.mass_matrix(q, phi)
    tau = arm.inverse_dynamics(q, dq, ddq, phi)
    assert M.shape == (3, 4, arm.n, arm.n)
    assert tau.shape == (3, 4, arm.n)
    for i, j in np.ndindex(3, 4):
        np.testing.assert_allclose(M[i, j], arm.mass_matrix(q[j], phi[i, 0]), rtol=1e-13)
        np.testing.assert_allclose(tau[i, j], arm.inverse_dynamics(q[j], dq[j], ddq[j], phi[i, 0]), rtol=1e-12,
                                   atol=1e-12)


@pytest.mark.parametrize("kind", ["two-link", "polar", "one-link"])
def test_generic_remainder_regressor_matches_the_closed_form(kind):
    """The base class's finite-difference Y_g (for n-DOF models) agrees with each arm's closed form."""
    from robotadapt.robots.base import RobotModel

    arm, rng = ARMS[kind], np.random.default_rng(11)
    args = random_args(arm, (6,), rng)
    q, dq = args["q"], 3 * args["dq"]
    np.testing.assert_allclose(RobotModel.remainder_regressor(arm, q, dq), arm.remainder_regressor(q, dq),
                               rtol=1e-7, atol=1e-7)
