"""Arms from DH tables (robotadapt.robots.symbolic): physical identities, agreement with independent models, the cache.

Independent references: the textbook two-link arm (spec §1.3, `TwoLinkArm`), Pinocchio's `crba`, `computeCoriolisMatrix`,
`computeGeneralizedGravity` and `rnea` on the same arm, forward kinematics written out here from the DH definitions (for
the potential energy U, whose gradient is G, and to check the Pinocchio model's placements), and finite differences of M
for the Christoffel symbols.
"""

from __future__ import annotations

import copy
import functools
import itertools
import math
import pickle
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robotadapt.robots import TwoLinkArm
from robotadapt.robots import dh as dh_module
from robotadapt.robots.base import RobotModel
from robotadapt.robots.catalog import planar
from robotadapt.robots.symbolic import SymbolicArm, from_dh_table, planar_arm, puma560
from robotadapt.studies.scenarios import load
from robotadapt.validation import ConfigError

SETTINGS = settings(max_examples=25, deadline=None)
ARMS = ["puma560", "puma560-full", "modified-rpr", "standard-rrp", "planar-rods"]


def _random_links(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masses, centres of mass and physically consistent inertia tensors (R diag Rᵀ, triangle inequality) per link."""
    mass = rng.uniform(0.5, 3.0, n)
    com = rng.uniform(-0.2, 0.2, (n, 3))
    inertia = []
    for _ in range(n):
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        d = rng.uniform(0.02, 0.1, 3)
        inertia.append(R @ np.diag([d[0] + d[1], d[1] + d[2], d[0] + d[2]]) @ R.T)
    return mass, com, np.array(inertia)


@functools.cache
def arm(name: str) -> SymbolicArm:
    rng = np.random.default_rng(7)
    if name == "puma560":
        return puma560()
    if name == "puma560-full":
        return puma560(rotor_inertia=True, viscous=True, coulomb=True)
    if name == "planar-rods":
        return planar_arm(3, lengths=[0.5, 0.4, 0.3], masses=[2.0, 1.5, 1.0], rods=True, viscous=0.3, coulomb=0.2)
    m, c, inertia = _random_links(rng, 3)
    if name == "modified-rpr":  # Craig's convention, a prismatic joint, offsets, a twist that is not a multiple of π/2
        return SymbolicArm("RPR", [0.0, 0.1, 0.4], [0.0, -math.pi / 2, 0.3], [0.2, 0.3, 0.05], [0.1, 0.4, -0.2], m, c,
                           inertia, "modified", (0.5, -1.0, -9.7), rotor_inertia=[0.05, 0.1, 0.02])
    return SymbolicArm("RRP", [0.4, 0.3, 0.0], [0.0, math.pi, 0.0], [0.3, 0.0, 0.1], [0.0, 0.0, 0.0], m, c, inertia,
                       "standard", (0.0, 0.0, -9.81), viscous=[0.2, 0.3, 0.4])


def states(model: RobotModel) -> st.SearchStrategy:
    """(q, q̇, v, a): angles in [−π, π], prismatic extensions in [0, 0.5] m, rates in [−2, 2]."""
    n = model.n
    vec = st.lists(st.floats(-2.0, 2.0), min_size=4 * n, max_size=4 * n).map(lambda x: np.array(x).reshape(4, n))
    scale = np.array([math.pi if j == "R" else 0.25 for j in model.joints])
    shift = np.array([0.0 if j == "R" else 0.25 for j in model.joints])
    return vec.map(lambda x: (shift + scale * x[0] / 2, x[1], x[2], x[3]))


def terms(model: SymbolicArm, q, dq, phi):
    return (model.mass_matrix(q, phi), model.coriolis_matrix(q, dq, phi), model.gravity(q, phi),
            model.friction(dq, phi))


def close(actual, expected, rel: float, scale: float) -> None:
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rel * (1.0 + scale))


# ---------------------------------------------------------------------------------------------------------------------
# Forward kinematics written out from the DH definitions (independent of the library's transforms)


def dh_frames(model: SymbolicArm, q: np.ndarray) -> list[np.ndarray]:
    """World poses (4×4) of the link frames: standard Rz(θ) Tz(d) Tx(a) Rx(α), modified Rx(α) Tx(a) Rz(θ) Tz(d)."""
    def rot(axis: int, t: float) -> np.ndarray:
        T = np.eye(4)
        i, k = [(1, 2), (2, 0), (0, 1)][axis]
        T[i, i] = T[k, k] = math.cos(t)
        T[i, k], T[k, i] = -math.sin(t), math.sin(t)
        return T

    def trans(axis: int, s: float) -> np.ndarray:
        T = np.eye(4)
        T[axis, 3] = s
        return T

    T, out = np.eye(4), []
    for j, kind in enumerate(model.joints):
        theta = model.theta[j] + (q[j] if kind == "R" else 0.0)
        d = model.d[j] + (q[j] if kind == "P" else 0.0)
        if model.convention == "standard":
            T = T @ rot(2, theta) @ trans(2, d) @ trans(0, model.a[j]) @ rot(0, model.alpha[j])
        else:
            T = T @ rot(0, model.alpha[j]) @ trans(0, model.a[j]) @ rot(2, theta) @ trans(2, d)
        out.append(T)
    return out


def potential(model: SymbolicArm, q: np.ndarray) -> float:
    """U(q) = −Σ m_i gᵀ p_ci, centres of mass placed by :func:`dh_frames`, with the model's own link data."""
    return -sum(m * model.g @ (T[:3, :3] @ c + T[:3, 3])
                for m, c, T in zip(model.mass, model.com, dh_frames(model, q), strict=True))


# ---------------------------------------------------------------------------------------------------------------------
# Physical identities, each on every arm


@pytest.mark.parametrize("name", ARMS)
@SETTINGS
@given(data=st.data())
def test_regressor_is_the_two_slot_identity(name, data):
    """(P3)  Y(q, q̇, v, a) φ = M a + V_m(q, q̇) v + G + F(q̇), for the published φ and for a random one."""
    model = arm(name)
    q, dq, v, a = data.draw(states(model))
    Y = model.regressor(q, dq, v, a)
    assert Y.shape == (model.n, model.p)
    for phi in (model.default_phi, np.random.default_rng(data.draw(st.integers(0, 99))).normal(size=model.p)):
        M, V, G, F = terms(model, q, dq, phi)
        expected = M @ a + V @ v + G + F
        close(Y @ phi, expected, 1e-12, np.abs(expected).max())


@pytest.mark.parametrize("name", ARMS)
@SETTINGS
@given(data=st.data())
def test_coriolis_is_the_christoffel_form_and_mdot_minus_2v_is_skew(name, data):
    """(P2)  V_m,kj = Σ_i c_ijk q̇_i with c_ijk from central differences of M, and Ṁ − 2V_m skew-symmetric."""
    model = arm(name)
    q, dq, _, _ = data.draw(states(model))
    phi, n, h = model.default_phi, model.n, 1e-6
    eye = np.eye(n)
    dM = np.array([(model.mass_matrix(q + h * eye[i], phi) - model.mass_matrix(q - h * eye[i], phi)) / (2 * h)
                   for i in range(n)])  # dM[i, k, j] = ∂M_kj/∂q_i
    c = np.zeros((n, n, n))
    for i, j, k in itertools.product(range(n), repeat=3):
        c[i, j, k] = 0.5 * (dM[i, k, j] + dM[j, k, i] - dM[k, i, j])
    V = model.coriolis_matrix(q, dq, phi)
    scale = np.abs(dM).max() * np.abs(dq).max()
    close(V, np.einsum("ijk,i->kj", c, dq), 1e-7, scale)
    S = np.einsum("ikj,i->kj", dM, dq) - 2 * V
    close(S + S.T, np.zeros((n, n)), 1e-7, scale)


@pytest.mark.parametrize("name", ARMS)
@SETTINGS
@given(data=st.data())
def test_mass_matrix_is_symmetric_positive_definite(name, data):
    """(P1)  M = Mᵀ > 0 for the published parameters (the PUMA's m1 = 0 included) and random consistent links."""
    model = arm(name)
    q, _, _, _ = data.draw(states(model))
    m, c, inertia = _random_links(np.random.default_rng(data.draw(st.integers(0, 99))), model.n)
    other = SymbolicArm(model.joints, model.a, model.alpha, model.d, model.theta, m, c, inertia, model.convention,
                        model.g)
    for M in (model.mass_matrix(q, model.default_phi), other.mass_matrix(q, other.default_phi)):
        assert np.array_equal(M, M.T)
        assert np.linalg.eigvalsh(M).min() > 0


@pytest.mark.parametrize("name", ARMS)
@SETTINGS
@given(data=st.data())
def test_gravity_is_the_gradient_of_the_potential_energy(name, data):
    """G = ∂U/∂q, U = −Σ m_i gᵀ p_ci from forward kinematics written here (central differences, h = 1e-6)."""
    model = arm(name)
    q, _, _, _ = data.draw(states(model))
    h, eye = 1e-6, np.eye(model.n)
    grad = np.array([(potential(model, q + h * e) - potential(model, q - h * e)) / (2 * h) for e in eye])
    close(model.gravity(q, model.default_phi), grad, 1e-7, np.abs(grad).max())


@pytest.mark.parametrize("name", ARMS)
@SETTINGS
@given(data=st.data())
def test_momentum_and_remainder_regressors(name, data):
    """Y_h φ = M q̇ (6.6.3); Y_g φ = −V_mᵀ q̇ + G + F (6.6.4), exact, and equal to the base class's finite differences."""
    model = arm(name)
    q, dq, _, _ = data.draw(states(model))
    phi = model.default_phi
    M, V, G, F = terms(model, q, dq, phi)
    close(model.momentum_regressor(q, dq) @ phi, M @ dq, 1e-12, np.abs(M @ dq).max())
    Yg = model.remainder_regressor(q, dq)
    close(Yg @ phi, -V.T @ dq + G + F, 1e-12, np.abs(G).max() + np.abs(V).max() * np.abs(dq).max())
    close(Yg, RobotModel.remainder_regressor(model, q, dq), 1e-7, np.abs(Yg).max())


# ---------------------------------------------------------------------------------------------------------------------
# Agreement with independent models


@SETTINGS
@given(q=st.lists(st.floats(-math.pi, math.pi), min_size=2, max_size=2).map(np.array),
       rates=st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6).map(lambda x: np.array(x).reshape(3, 2)),
       m=st.lists(st.floats(0.1, 5.0), min_size=2, max_size=2).map(np.array),
       lengths=st.sampled_from([(1.0, 1.0), (0.3, 1.7)]))  # a few geometries: each new one is derived and cached
def test_planar_two_link_point_masses_is_the_textbook_arm(q, rates, m, lengths):
    """planar_arm(2) with point masses = TwoLinkArm (spec §1.3) to 1e-12: its regressor columns of m1, m2 are the
    textbook Y, and every term agrees with φ = [m1, 0, …, m2, 0, …]."""
    dq, v, a = rates
    book = TwoLinkArm(l1=lengths[0], l2=lengths[1], g=9.8)
    model = planar_arm(2, lengths=lengths, masses=m, g=9.8)
    phi = np.zeros(20)
    phi[[0, 10]] = m
    np.testing.assert_array_equal(model.default_phi, phi)
    scale = 1.0 + np.abs(book.regressor(q, dq, v, a)).max()
    close(model.regressor(q, dq, v, a)[:, [0, 10]], book.regressor(q, dq, v, a), 1e-12, scale)
    close(model.remainder_regressor(q, dq)[:, [0, 10]], book.remainder_regressor(q, dq), 1e-12, scale)
    for mine, theirs in zip(terms(model, q, dq, phi), (book.mass_matrix(q, m), book.coriolis_matrix(q, dq, m),
                                                       book.gravity(q, m), book.friction(dq, m)), strict=True):
        close(mine, theirs, 1e-12, scale)


@pytest.mark.parametrize("name", ["puma560", "puma560-full", "modified-rpr", "standard-rrp"])
def test_symbolic_model_agrees_with_pinocchio(name):
    """M (crba), V_m v (computeCoriolisMatrix), G (computeGeneralizedGravity) and Y φ (rnea-style M a + V_m v + G, plus
    F) agree with Pinocchio on the same arm to 1e-9 relative on random states; rotor inertia is Pinocchio's armature."""
    pin = pytest.importorskip("pinocchio")
    model = arm(name)
    pm = model.pinocchio_model()
    data = pm.createData()
    rng = np.random.default_rng(1)
    for _ in range(20):
        q, dq, v, a = rng.uniform(-1.0, 1.0, (4, model.n)) * [[2.0], [2.0], [2.0], [5.0]]
        phi = model.default_phi
        M, V, G, F = terms(model, q, dq, phi)
        M_pin = pin.crba(pm, data, q).copy()
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        V_pin = pin.computeCoriolisMatrix(pm, data, q, dq).copy()
        G_pin = pin.computeGeneralizedGravity(pm, data, q).copy()
        for mine, theirs in ((M, M_pin), (V @ v, V_pin @ v), (G, G_pin),
                             (model.regressor(q, dq, v, a) @ phi, M_pin @ a + V_pin @ v + G_pin + F)):
            np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-9 * np.abs(theirs).max())
        tau = pin.rnea(pm, data, q, dq, a).copy() + F
        np.testing.assert_allclose(model.inverse_dynamics(q, dq, a, phi), tau, rtol=0, atol=1e-9 * np.abs(tau).max())


@pytest.mark.parametrize("name", ["puma560", "modified-rpr"])
def test_two_independent_mixed_regressors_agree(name):
    """The symbolic Y(q, q̇, v, a) (polarised Newton–Euler, DH-frame parameters) and PinocchioArm's (polarised
    `computeJointTorqueRegressor`, joint-frame parameters) give the same torque for the same arm: Y φ = Y_pin φ_pin."""
    pytest.importorskip("pinocchio")
    from robotadapt.robots.pinocchio import PinocchioArm

    model = arm(name)
    other = PinocchioArm(model.pinocchio_model())
    rng = np.random.default_rng(8)
    for _ in range(10):
        q, dq, v, a = rng.uniform(-2.0, 2.0, (4, model.n))
        rigid = model.regressor(q, dq, v, a)[:, : 10 * model.n] @ model.default_phi[: 10 * model.n]
        theirs = other.regressor(q, dq, v, a) @ other.default_phi
        np.testing.assert_allclose(rigid, theirs, rtol=0, atol=1e-9 * np.abs(theirs).max())


@pytest.mark.parametrize("name", ["puma560", "modified-rpr", "standard-rrp"])
def test_pinocchio_model_places_the_dh_frames(name):
    """The Pinocchio model's joint frames composed with each link's DH offset land on the DH frames written here."""
    pin = pytest.importorskip("pinocchio")
    model = arm(name)
    pm = model.pinocchio_model()
    data = pm.createData()
    q = np.random.default_rng(2).uniform(-1.0, 1.0, model.n)
    pin.forwardKinematics(pm, data, q)
    posts = [post for _, post in dh_module.joint_placements(model.geometry)]
    for j, T in enumerate(dh_frames(model, q)):
        np.testing.assert_allclose(data.oMi[j + 1].homogeneous @ posts[j], T, atol=1e-12)


def test_puma560_regressor_has_36_independent_columns():
    """The 60 standard parameters of the PUMA 560 give 36 base parameters (Gautier & Khalil 1990); a planar chain of
    n links gives 3n. Rank of the regressor stacked over random states."""
    rng = np.random.default_rng(3)
    for model, rank in ((puma560(), 36), (arm("planar-rods"), 9 + 3 + 3)):  # + viscous and Coulomb columns
        Y = model.regressor(*rng.uniform(-math.pi, math.pi, (4, 200, model.n))).reshape(-1, model.p)
        s = np.linalg.svd(Y, compute_uv=False)
        assert int(np.sum(s > 1e-10 * s[0])) == rank


# ---------------------------------------------------------------------------------------------------------------------
# Parameters, the batch contract, the cache


def test_parameter_names_and_published_values():
    full = arm("puma560-full")
    assert full.param_names[:11] == ("m1", "mx1", "my1", "mz1", "Ixx1", "Ixy1", "Iyy1", "Ixz1", "Iyz1", "Izz1", "m2")
    assert full.param_names[60:] == tuple(f"{k}{i}" for k in ("Ia", "fv", "fc") for i in range(1, 7))
    phi = dict(zip(full.param_names, full.default_phi, strict=True))
    assert phi["m2"] == 17.4 and phi["mx2"] == pytest.approx(17.4 * -0.3638)
    assert phi["Izz2"] == pytest.approx(0.539 + 17.4 * (0.3638**2 + 0.006**2))  # parallel axes: I_c + m(c_x² + c_y²)
    assert phi["Ia1"] == pytest.approx(200e-6 * 62.6111**2)  # J_m G²
    assert phi["fc1"] == pytest.approx(62.6111 * (0.395 + 0.435) / 2)
    rods = planar_arm(2, lengths=[0.5, 2.0], masses=[2.0, 3.0], rods=True)
    phi = dict(zip(rods.param_names, rods.default_phi, strict=True))
    assert phi["mx2"] == pytest.approx(-3.0)  # m c_x, the centre of the rod 1 m behind its distal frame
    assert phi["Izz2"] == pytest.approx(3.0 * 2.0**2 / 3)  # a rod about its end: m l²/3
    np.testing.assert_allclose(puma560().q_limits[1], np.radians([-45, 225]))


def test_batch_contract():
    """Outputs carry the broadcast leading axes of the inputs; each entry is the one-state result (the math path and the
    numpy path of the same generated code), whatever the mix of shapes."""
    model = arm("puma560-full")
    n, rng = model.n, np.random.default_rng(4)
    q, dq, v, a = rng.normal(size=(4, 2, 3, n))
    phi = model.default_phi * rng.uniform(0.5, 1.5, (3, model.p))
    assert model.regressor(q, dq[0, 0], v, a[:, :1]).shape == (2, 3, n, model.p)
    checks = [
        (model.regressor(q, dq, v, a), lambda i, j: model.regressor(q[i, j], dq[i, j], v[i, j], a[i, j])),
        (model.mass_matrix(q, phi), lambda i, j: model.mass_matrix(q[i, j], phi[j])),
        (model.coriolis_matrix(q, dq, phi), lambda i, j: model.coriolis_matrix(q[i, j], dq[i, j], phi[j])),
        (model.gravity(q, phi), lambda i, j: model.gravity(q[i, j], phi[j])),
        (model.friction(dq, phi), lambda i, j: model.friction(dq[i, j], phi[j])),
        (model.momentum_regressor(q, dq), lambda i, j: model.momentum_regressor(q[i, j], dq[i, j])),
        (model.remainder_regressor(q, dq), lambda i, j: model.remainder_regressor(q[i, j], dq[i, j])),
    ]
    for batched, one in checks:
        assert batched.shape[:2] == (2, 3)
        for i, j in itertools.product(range(2), range(3)):
            np.testing.assert_allclose(batched[i, j], one(i, j), rtol=1e-13, atol=1e-13)


def test_other_array_namespaces(x64):
    """The same generated code runs on jax.numpy arrays (stacking, no assignment) and agrees with numpy."""
    jax = pytest.importorskip("jax")
    model = arm("modified-rpr")
    q, dq, v, a = np.random.default_rng(5).normal(size=(4, 2, model.n))
    J = [jax.numpy.asarray(x) for x in (q, dq, v, a)]
    np.testing.assert_allclose(np.asarray(model.regressor(*J)), model.regressor(q, dq, v, a), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(np.asarray(model.mass_matrix(J[0], model.default_phi)),
                               model.mass_matrix(q, model.default_phi), rtol=1e-13, atol=1e-13)


def test_the_disk_cache_is_exact_and_faster(tmp_path, monkeypatch):
    """A miss derives and writes the module under $ROBOTADAPT_CACHE; a new process (the in-memory cache cleared) loads it
    unchanged, faster, and computes bit-identical results."""
    monkeypatch.setenv("ROBOTADAPT_CACHE", str(tmp_path))
    dh_module.compiled.cache_clear()
    try:
        t0 = time.perf_counter()
        first = planar_arm(3, lengths=[0.31, 0.27, 0.23], rods=True)
        miss = time.perf_counter() - t0
        files = list((tmp_path / "dh").glob("*/arm_*.py"))
        assert [f.name for f in files] == [first._code.path.name]
        text = files[0].read_text()
        dh_module.compiled.cache_clear()
        t0 = time.perf_counter()
        second = planar_arm(3, lengths=[0.31, 0.27, 0.23], masses=[1.0, 2.0, 3.0], rods=True)  # other masses: same file
        hit = time.perf_counter() - t0
    finally:
        dh_module.compiled.cache_clear()
    assert files[0].read_text() == text
    assert hit < miss / 5, (hit, miss)
    q, dq, v, a = np.random.default_rng(6).normal(size=(4, 3))
    assert np.array_equal(first.regressor(q, dq, v, a), second.regressor(q, dq, v, a))


def test_pickle_and_deepcopy_rebuild_the_compiled_code():
    """A model crosses process boundaries (multiprocessing, Dask) and deep copies: its code is reloaded, not pickled."""
    model = arm("puma560-full")
    q, dq, v, a = np.random.default_rng(9).normal(size=(4, 6))
    for other in (pickle.loads(pickle.dumps(model)), copy.deepcopy(model)):
        assert other.param_names == model.param_names
        np.testing.assert_array_equal(other.default_phi, model.default_phi)
        np.testing.assert_array_equal(other.regressor(q, dq, v, a), model.regressor(q, dq, v, a))


def test_an_unwritable_cache_still_builds_the_arm(tmp_path, monkeypatch):
    """A cache directory that cannot be created (here: below a file) costs a derivation, not a failure."""
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("ROBOTADAPT_CACHE", str(tmp_path / "file" / "cache"))
    dh_module.compiled.cache_clear()
    try:
        model = planar_arm(2, lengths=[0.43, 0.21])
    finally:
        dh_module.compiled.cache_clear()
    q = np.array([0.3, -0.4])
    book = TwoLinkArm(l1=0.43, l2=0.21, g=9.8)
    np.testing.assert_allclose(model.gravity(q, model.default_phi), book.gravity(q, np.ones(2)), rtol=1e-12)
    assert not model._code.path.exists()


def test_a_cache_miss_without_sympy_is_a_clear_error(tmp_path, monkeypatch):
    """Without the [symbolic] extra an arm already in the disk cache still loads; a new table names the extra."""
    import importlib.util

    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "sympy" else find_spec(name, *a))
    monkeypatch.setenv("ROBOTADAPT_CACHE", str(tmp_path))
    dh_module.compiled.cache_clear()
    try:
        with pytest.raises(ConfigError, match=r"^robot\.kind: deriving an arm from its DH table needs sympy"):
            planar(2, lengths=[0.43, 0.21], model="sympy")  # found at construction, before any work
    finally:
        dh_module.compiled.cache_clear()


# ---------------------------------------------------------------------------------------------------------------------
# Input checking and the TOML-friendly constructor


def test_from_dh_table_builds_the_same_arm():
    """The PUMA from a list of link tables (as [[robot.links]] in TOML) is the PUMA."""
    puma = puma560(rotor_inertia=True)
    links = [{"a": float(puma.a[i]), "alpha": float(puma.alpha[i]), "d": float(puma.d[i]), "m": float(puma.mass[i]),
              "com": puma.com[i].tolist(), "inertia": np.diag(puma.inertia[i]).tolist(),
              "rotor_inertia": float(puma.rotor_inertia[i]), "q_limits": puma.q_limits[i].tolist()}
             for i in range(6)]
    model = from_dh_table(links)
    np.testing.assert_array_equal(model.default_phi, puma.default_phi)
    assert model._code is puma._code
    q = np.linspace(-1, 1, 6)
    np.testing.assert_array_equal(model.mass_matrix(q, puma.default_phi), puma.mass_matrix(q, puma.default_phi))


@pytest.mark.parametrize(("build", "field"), [
    (lambda: from_dh_table([{"a": 1.0}]), "robot.links[0].m"),
    (lambda: from_dh_table([{"m": 1.0, "mass": 2.0}]), "robot.links[0].mass"),
    (lambda: from_dh_table([{"m": 1.0, "joint": "S"}]), "robot.links[0].joint"),
    (lambda: from_dh_table([{"m": -1.0}]), "robot.links[0].m"),
    (lambda: from_dh_table([{"m": 1.0, "inertia": [[1, 2, 0], [2, 1, 0], [0, 0, 1]]}]), "robot.links[0].inertia"),
    (lambda: from_dh_table([{"m": 1.0, "q_limits": [0, 1]}, {"m": 1.0}]), "robot.links"),
    (lambda: from_dh_table({"m": 1.0}), "robot.links"),
    (lambda: from_dh_table([{"m": 1.0}], convention="craig"), "robot.convention"),
    (lambda: from_dh_table([{"m": 1.0}], g=[0, 0]), "robot.g"),
    (lambda: planar_arm(0), "robot.n_links"),
    (lambda: planar_arm(2.5), "robot.n_links"),
    (lambda: planar_arm(2, lengths=[1.0, -1.0]), "robot.lengths"),
    (lambda: planar_arm(2, masses=[1.0, math.nan]), "robot.masses"),
    (lambda: planar_arm(2, viscous=[-1.0, 0.0]), "robot.viscous"),
    (lambda: planar_arm(2, rods=1), "robot.rods"),
    (lambda: puma560(rotor_inertia=3), "robot.rotor_inertia"),
])
def test_bad_input_names_the_field(build, field):
    with pytest.raises(ConfigError) as err:
        build()
    assert err.value.field == field


# ---------------------------------------------------------------------------------------------------------------------
# The packaged PUMA 560 scenario


def _puma_scenario(t_final: float):
    scenario = load("puma560-slotine-li", [f"simulation.t_final={t_final}"])
    model = scenario.setup.plant.model
    phi = scenario.setup.plant.phi
    return scenario, model, phi


def test_puma560_scenario_stays_inside_the_joint_limits_and_starts_30_percent_off():
    scenario, model, phi = _puma_scenario(10.0)
    np.testing.assert_array_equal(phi, model.default_phi)
    np.testing.assert_allclose(scenario.setup.controller.phi_hat0, 0.7 * phi, rtol=1e-5, atol=1e-9)
    q_des = scenario.setup.trajectory(np.linspace(0.0, 40.0, 4001)).q_des
    assert np.all(q_des > model.q_limits[:, 0]) and np.all(q_des < model.q_limits[:, 1])


def test_puma560_scenario_first_second_of_convergence():
    """Fast version of the convergence test: in 1 s the 0.05 rad initial error falls below 2e-3 on every joint, and the
    Lyapunov function (6.3.7) never increases."""
    scenario, _, _ = _puma_scenario(1.0)
    res = scenario.run()
    assert res.status == "ok"
    assert np.all(np.abs(res.e[0]) == pytest.approx(0.05))
    assert np.all(np.abs(res.e[-1]) < 2e-3)
    assert np.max(np.diff(res.V)) <= 1e-9 * res.V[0]


@pytest.mark.slow
def test_puma560_scenario_converges():
    """Slotine–Li on the PUMA 560 with every estimate 30 % low: after 10 s the error is below 1e-3 rad on every joint
    (issue 6), and V (6.3.7) never increases."""
    scenario, _, _ = _puma_scenario(10.0)
    res = scenario.run()
    assert res.status == "ok"
    assert np.all(np.abs(res.e[-1]) < 1e-3), res.e[-1]
    assert np.max(np.abs(res.e[res.t > 9.0])) < 1e-3
    assert np.max(np.diff(res.V)) <= 1e-9 * res.V[0]
