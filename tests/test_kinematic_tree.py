"""The JAX-traceable chain model (robotadapt.robots.kinematic_tree) against independent references.

Oracles: Pinocchio's `computeJointTorqueRegressor`, `crba`, `computeCoriolisMatrix`, `computeGeneralizedGravity`, `rnea`
and `aba` on every arm of `pinocchio.EXAMPLES` (the URDF route; random states, random and non-physical φ, rotor
inertias as Pinocchio's `armature`), on a hand-built branched tree with unaligned and prismatic joints, and on DH arms
placed joint by joint in a `pinocchio.Model`; the sympy DH model (`symbolic.puma560`) for the PUMA 560 column by column.
Then the physical identities (P1–P3, Ṁ − 2V_m skew by finite differences), batch axes, `jax.jit`/`vmap` against numpy,
and bad input.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import pickle

import numpy as np
import pytest

from robotadapt.robots.kinematic_tree import KinematicTree
from robotadapt.validation import ConfigError

pin = pytest.importorskip("pinocchio")
from robotadapt.robots import dh  # noqa: E402
from robotadapt.robots.pinocchio import EXAMPLES, PinocchioArm  # noqa: E402

RTOL = 1e-10
STATES = 3


def close(actual: np.ndarray, expected: np.ndarray, rtol: float = RTOL) -> float:
    """Assert max |actual − expected| ≤ rtol · max |expected| (1 if that is 0); return the relative error."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    scale = max(float(np.abs(expected).max(initial=0.0)), 1.0 if not np.any(expected) else 0.0)
    err = float(np.abs(actual - expected).max(initial=0.0)) / scale
    assert err <= rtol, f"relative error {err:.2e} > {rtol:.0e}"
    return err


def configuration(model: object, q: np.ndarray) -> np.ndarray:
    """Plain joint angles → Pinocchio's configuration ((cos, sin) for continuous joints)."""
    out = []
    for j in range(1, model.njoints):
        x = q[model.idx_vs[j]]
        out += [math.cos(x), math.sin(x)] if model.joints[j].nq == 2 else [x]
    return np.array(out)


def random_phi(rng: np.random.Generator, tree: KinematicTree, physical: bool = False) -> np.ndarray:
    """Random φ: random first moments and inertia entries (non-physical: no positive definiteness, no triangle
    inequality), masses in [0.5, 2] (positive: Pinocchio's `Inertia` holds m, c = h/m, I_c, and its composite sums divide
    by the subtree's mass, which random signs can cancel), then the extra columns; `physical` keeps the tree's own
    inertials and draws only the extras (positive). The regressors are compared column by column, for any φ."""
    n = tree.n
    if physical:
        links = tree.default_phi[: 10 * n].reshape(n, 10)
    else:
        links = rng.normal(scale=0.5, size=(n, 10))
        links[:, 0] = rng.uniform(0.5, 2.0, n)
    extras = [rng.uniform(0.0, 0.5, n) for _ in tree.extras]
    return np.concatenate([links.ravel(), *extras])


def holding(model: object, tree: KinematicTree, phi: np.ndarray) -> tuple[object, object]:
    """A copy of the Pinocchio model with the link inertias and rotor inertias of φ, and its data."""
    model = model.copy()
    for j in range(1, model.njoints):
        model.inertias[j] = pin.Inertia.FromDynamicParameters(phi[10 * (j - 1) : 10 * j])
    model.armature = tree._extra(phi, "rotor_inertia") if tree.rotor_inertia is not None else np.zeros(tree.n)
    return model, model.createData()


def friction(tree: KinematicTree, dq: np.ndarray, phi: np.ndarray) -> np.ndarray:
    out = np.zeros_like(dq)
    if tree.viscous is not None:
        out = out + tree._extra(phi, "viscous") * dq
    if tree.coulomb is not None:
        out = out + tree._extra(phi, "coulomb") * np.sign(dq)
    return out


def check_against_pinocchio(tree: KinematicTree, model: object, rng: np.random.Generator,
                            physical: bool = False) -> float:
    """Every term of `tree` against Pinocchio on `model` (same kinematics, φ in Pinocchio's joint frames), STATES random
    states with a random φ each; returns the largest relative error."""
    n, worst = tree.n, 0.0
    for _ in range(STATES):
        q, dq, v, a = rng.normal(size=(4, n))
        phi = random_phi(rng, tree, physical)
        pm, pd = holding(model, tree, phi)
        cfg = configuration(pm, q)
        M = pin.crba(pm, pd, cfg).copy()
        M = np.triu(M) + np.triu(M, 1).T
        C = pin.computeCoriolisMatrix(pm, pd, cfg, dq).copy()
        G = pin.computeGeneralizedGravity(pm, pd, cfg).copy()
        F = friction(tree, dq, phi)
        def Yp(w: np.ndarray, acc: np.ndarray, pm=pm, pd=pd, cfg=cfg) -> np.ndarray:  # Y_p φ = M a + C(q, w) w + G
            return pin.computeJointTorqueRegressor(pm, pd, cfg, w, acc).copy()

        rigid = slice(0, 10 * n)
        errs = [
            close(tree.regressor(q, dq, dq, a)[:, rigid], Yp(dq, a)),
            # the mixed regressor by polarisation (robotadapt.robots.pinocchio), column by column
            close(tree.regressor(q, dq, v, a)[:, rigid],
                  4 / 3 * Yp(dq / 2 + 3 * v / 8, 3 * a / 4) - Yp(dq - 3 * v / 4, 0 * a) / 3),
            close(tree.momentum_regressor(q, dq)[:, rigid], Yp(0 * dq, dq) - Yp(0 * dq, 0 * dq)),
            close(tree.regressor(q, dq, v, a) @ phi, M @ a + C @ v + G + F),  # P3, the mixed regressor
            close(tree.mass_matrix(q, phi), M),
            close(tree.coriolis_matrix(q, dq, phi), C),
            close(tree.gravity(q, phi), G),
            close(tree.friction(dq, phi), F),
            close(tree.inverse_dynamics(q, dq, a, phi), pin.rnea(pm, pd, cfg, dq, a) + F),
            close(tree.momentum_regressor(q, dq) @ phi, M @ dq),  # (6.6.3)
            close(tree.remainder_regressor(q, dq) @ phi, -C.T @ dq + G + F),  # (6.6.4)
        ]
        if physical:  # ABA needs an invertible articulated inertia: the arm's own φ
            tau = rng.normal(size=n)
            errs.append(close(tree.forward_dynamics(q, dq, tau, phi), pin.aba(pm, pd, cfg, dq, tau - F), 1e-9))
        worst = max(worst, *errs)
    return worst


@functools.cache
def example(name: str) -> tuple[KinematicTree, object]:
    """(tree with every extra column group, Pinocchio model of the same URDF, grippers locked)."""
    return (KinematicTree.example(name, rotor_inertia=True, viscous=True, coulomb=True),
            PinocchioArm.example(name).pin_model)


# -- the URDF route: every example arm ----------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_every_example_arm_matches_pinocchio(name):
    """Random φ (non-physical inertia entries) and the arm's own φ with rotor inertias; the URDF's inertials are exactly
    `default_phi`."""
    tree, model = example(name)
    rng = np.random.default_rng(sum(map(ord, name)))
    check_against_pinocchio(tree, model, rng)
    check_against_pinocchio(tree, model, rng, physical=True)
    assert tree.n == model.nv and tree.param_names[: 10 * tree.n] == PinocchioArm(model).param_names
    np.testing.assert_array_equal(tree.default_phi[: 10 * tree.n], PinocchioArm(model).default_phi)


def test_panda_and_ur5_structure():
    panda, _ = example("panda")
    assert (panda.n, panda.p, panda.joints) == (7, 91, "RRRRRRR")
    assert "panda_finger_joint1" not in panda.joint_names and panda.name == "panda"
    assert panda.param_names[-7:] == tuple(f"fc{i}" for i in range(1, 8))
    ur5, _ = example("ur5")
    assert ur5.parents == (-1, 0, 1, 2, 3, 4) and ur5.q_limits.shape == (6, 2)


def test_a_branched_tree_with_unaligned_and_prismatic_joints():
    """The tree path (subtree sums by the 0/1 ancestry matrix): joints 2 and 4 both hang from joint 1. Joints are added
    depth first: Pinocchio's `crba` and `computeCoriolisMatrix` take each subtree's velocities to be contiguous."""
    rng = np.random.default_rng(3)
    tree, model = branched_tree(rng)
    assert tree.parents == (-1, 0, 1, 0, 3) and tree.joints == "RRPPR" and not tree._chain
    check_against_pinocchio(tree, model, rng)
    check_against_pinocchio(tree, model, rng, physical=True)


# -- the DH route -------------------------------------------------------------------------------------------------------

def test_puma560_from_its_dh_table_matches_the_sympy_model():
    """Same φ order and frames as SymbolicArm: every column of Y, Y_h, Y_g and M, V_m, G, F for random φ, on a batch."""
    from robotadapt.robots.symbolic import puma560

    sym = puma560(rotor_inertia=True, viscous=True, coulomb=True)
    tree = KinematicTree.from_symbolic(sym)
    assert tree.param_names == sym.param_names and tree.n == 6
    np.testing.assert_allclose(tree.default_phi, sym.default_phi, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(tree.q_limits, sym.q_limits)
    rng = np.random.default_rng(560)
    q, dq, v, a = rng.normal(size=(4, STATES, 6))
    phi = rng.normal(size=(STATES, tree.p))
    close(tree.regressor(q, dq, v, a), sym.regressor(q, dq, v, a))
    close(tree.momentum_regressor(q, dq), sym.momentum_regressor(q, dq))
    close(tree.remainder_regressor(q, dq), sym.remainder_regressor(q, dq))
    close(tree.mass_matrix(q, phi), sym.mass_matrix(q, phi))
    close(tree.coriolis_matrix(q, dq, phi), sym.coriolis_matrix(q, dq, phi))
    close(tree.gravity(q, phi), sym.gravity(q, phi))
    close(tree.friction(dq, phi), sym.friction(dq, phi))
    close(tree.inverse_dynamics(q, dq, a, phi), sym.inverse_dynamics(q, dq, a, phi))


def dh_pinocchio_model(tree: KinematicTree, joints: str, geo: dh.Geometry, mass, com, inertia) -> object:
    """The DH arm placed joint by joint in a pinocchio.Model (RZ/PZ joints, each link's inertia in its DH frame)."""
    model = pin.Model()
    model.gravity = pin.Motion(np.array(geo.gravity), np.zeros(3))
    parent, previous = 0, np.eye(4)
    for i, (pre, post) in enumerate(dh.joint_placements(geo)):
        X = previous @ pre
        joint = pin.JointModelRZ() if joints[i] == "R" else pin.JointModelPZ()
        parent = model.addJoint(parent, joint, pin.SE3(X[:3, :3], X[:3, 3]), f"j{i}")
        model.appendBodyToJoint(parent, pin.Inertia(mass[i], com[i], inertia[i]), pin.SE3(post[:3, :3], post[:3, 3]))
        previous = post
    return model


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_dh_tables_match_pinocchio_on_the_same_arm(convention):
    """Revolute and prismatic rows, offsets, a twist that is not a multiple of π/2, tilted gravity: M, V_m, G, τ and
    Y φ with the arm's own φ (its DH-frame parameters) against Pinocchio's joint-frame model of the same arm."""
    rng = np.random.default_rng(11)
    joints, n = "RPRR", 4
    mass = rng.uniform(0.5, 2.0, n)
    com = rng.uniform(-0.2, 0.2, (n, 3))
    inertia = []
    for _ in range(n):
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        d = rng.uniform(0.02, 0.1, 3)
        inertia.append(R @ np.diag([d[0] + d[1], d[1] + d[2], d[0] + d[2]]) @ R.T)
    rows = dict(a=[0.1, 0.0, 0.4, 0.2], alpha=[0.3, -math.pi / 2, math.pi, 0.7], d=[0.2, 0.3, 0.05, -0.1],
                theta=[0.1, 0.4, -0.2, 0.0])
    links = [dict(joint=joints[i], m=mass[i], com=com[i], inertia=inertia[i], **{k: v[i] for k, v in rows.items()})
             for i in range(n)]
    g = (0.5, -1.0, -9.7)
    tree = KinematicTree.from_dh(links, convention, g)
    geo = dh.Geometry(joints, *(tuple(rows[k]) for k in ("a", "alpha", "d", "theta")), convention == "modified", g)
    model = dh_pinocchio_model(tree, joints, geo, mass, com, np.array(inertia))
    data, phi = model.createData(), tree.default_phi
    for _ in range(STATES):
        q, dq, v, a = rng.normal(size=(4, n))
        M = pin.crba(model, data, q).copy()
        M = np.triu(M) + np.triu(M, 1).T
        C = pin.computeCoriolisMatrix(model, data, q, dq).copy()
        G = pin.computeGeneralizedGravity(model, data, q).copy()
        close(tree.mass_matrix(q, phi), M)
        close(tree.coriolis_matrix(q, dq, phi), C)
        close(tree.gravity(q, phi), G)
        close(tree.inverse_dynamics(q, dq, a, phi), pin.rnea(model, data, q, dq, a))
        close(tree.regressor(q, dq, v, a) @ phi, M @ a + C @ v + G)


# -- physical identities, batches, JAX ----------------------------------------------------------------------------------

@functools.cache
def puma() -> KinematicTree:
    from robotadapt.robots.symbolic import puma560

    return KinematicTree.from_symbolic(puma560(rotor_inertia=True, viscous=True, coulomb=True))


@pytest.mark.parametrize("name", ["panda", "puma560"])
def test_physical_identities(name):
    """P1: M symmetric positive definite (the arm's φ); P2: Ṁ − 2V_m skew (central differences of M along q̇);
    P3: Y φ = M a + V_m v + G + F with the model's own terms; inverse ∘ forward dynamics = identity."""
    tree = puma() if name == "puma560" else example(name)[0]
    rng = np.random.default_rng(2)
    phi = tree.default_phi + np.concatenate([np.zeros(10 * tree.n), rng.uniform(0.1, 0.5, tree.p - 10 * tree.n)])
    for _ in range(STATES):
        q, dq, v, a = rng.normal(size=(4, tree.n))
        M = tree.mass_matrix(q, phi)
        assert np.allclose(M, M.T, rtol=0, atol=1e-14 * np.abs(M).max()) and np.linalg.eigvalsh(M).min() > 0
        h = 1e-6
        Mdot = (tree.mass_matrix(q + h * dq, phi) - tree.mass_matrix(q - h * dq, phi)) / (2 * h)
        S = Mdot - 2 * tree.coriolis_matrix(q, dq, phi)
        assert np.abs(S + S.T).max() <= 1e-7 * np.abs(Mdot).max()
        V, G, F = tree.coriolis_matrix(q, dq, phi), tree.gravity(q, phi), tree.friction(dq, phi)
        close(tree.regressor(q, dq, v, a) @ phi, M @ a + V @ v + G + F)
        tau = tree.inverse_dynamics(q, dq, a, phi)
        close(tree.forward_dynamics(q, dq, tau, phi), a, 1e-9)


def branched_tree(rng: np.random.Generator) -> tuple[KinematicTree, object]:
    """Joints 2 and 4 both hang from joint 1 (unaligned and prismatic joints, rotor and viscous columns)."""
    model = pin.Model()
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    joints = [(0, pin.JointModelRY()), (1, pin.JointModelRevoluteUnaligned(axis)), (2, pin.JointModelPX()),
              (1, pin.JointModelPrismaticUnaligned(np.array([0.0, 0.6, 0.8]))), (4, pin.JointModelRUBZ())]
    for k, (parent, joint) in enumerate(joints):
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        j = model.addJoint(parent, joint, pin.SE3(R * np.sign(np.linalg.det(R)), rng.normal(scale=0.3, size=3)),
                           f"j{k}")
        model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    model.gravity = pin.Motion(np.array([0.3, -1.0, -9.7]), np.zeros(3))
    return KinematicTree.from_pinocchio(model, rotor_inertia=True, viscous=True), model


@pytest.mark.parametrize("name", ["panda", "puma560", "branched"])
def test_regressor_products_equal_the_regressor(name):
    """(Y φ, Yᵀ r) without forming Y (one pass contracted with φ; link blocks A_iᵀ W_i) equal Y φ and Yᵀ r of the
    regressor, every column group included (the Panda's Coulomb columns, the tree's rotor and viscous ones), on a batch
    and on one state."""
    rng = np.random.default_rng(5)
    tree = {"panda": lambda: example("panda")[0], "puma560": puma, "branched": lambda: branched_tree(rng)[0]}[name]()
    q, dq, v, a, r = rng.normal(size=(5, 4, tree.n))
    phi = rng.normal(size=tree.p)
    Y = tree.regressor(q, dq, v, a)
    Yphi, Ytr = tree.regressor_products(q, dq, v, a, phi, r)
    close(Yphi, Y @ phi)
    close(Ytr, np.einsum("bij,bi->bj", Y, r))
    one = tree.regressor_products(q[0], dq[0], v[0], a[0], phi, r[0])
    close(one[0], Yphi[0])
    close(one[1], Ytr[0])


def test_batch_axes_broadcast_and_match_single_states():
    tree, _ = example("panda")
    n, p = tree.n, tree.p
    rng = np.random.default_rng(4)
    q, dq = rng.normal(size=(2, 3, n)), rng.normal(size=(3, n))
    v, a = rng.normal(size=(2, 1, n)), rng.normal(size=n)
    phi = random_phi(rng, tree)[None] + 0.1 * rng.normal(size=(3, p))
    checks = [
        (tree.regressor(q, dq, v, a), (2, 3, n, p), lambda i, j: tree.regressor(q[i, j], dq[j], v[i, 0], a)),
        (tree.momentum_regressor(q, dq), (2, 3, n, p), lambda i, j: tree.momentum_regressor(q[i, j], dq[j])),
        (tree.remainder_regressor(q, dq), (2, 3, n, p), lambda i, j: tree.remainder_regressor(q[i, j], dq[j])),
        (tree.mass_matrix(q, phi), (2, 3, n, n), lambda i, j: tree.mass_matrix(q[i, j], phi[j])),
        (tree.coriolis_matrix(q, dq, phi), (2, 3, n, n), lambda i, j: tree.coriolis_matrix(q[i, j], dq[j], phi[j])),
        (tree.gravity(q, phi), (2, 3, n), lambda i, j: tree.gravity(q[i, j], phi[j])),
        (tree.friction(dq, phi), (3, n), None),
        (tree.inverse_dynamics(q, dq, a, phi), (2, 3, n), lambda i, j: tree.inverse_dynamics(q[i, j], dq[j], a, phi[j])),
        (tree.forward_dynamics(q, dq, a, tree.default_phi), (2, 3, n),
         lambda i, j: tree.forward_dynamics(q[i, j], dq[j], a, tree.default_phi)),
    ]
    for batched, shape, one in checks:
        assert batched.shape == shape
        for i in range(2 if one else 0):
            for j in range(3):
                np.testing.assert_allclose(batched[i, j], one(i, j), rtol=1e-13, atol=1e-13)


def _jax():
    """JAX with the project's disk cache (float64 comes from the `x64` fixture)."""
    pytest.importorskip("jax")
    from robotadapt.tracing import jax_module

    return jax_module()


def every_term(tree: KinematicTree, q, dq, v, a, phi) -> dict[str, object]:
    return {"Y": tree.regressor(q, dq, v, a), "Yh": tree.momentum_regressor(q, dq), "Yg": tree.remainder_regressor(q, dq),
            "M": tree.mass_matrix(q, phi), "V": tree.coriolis_matrix(q, dq, phi), "G": tree.gravity(q, phi),
            "F": tree.friction(dq, phi), "tau": tree.inverse_dynamics(q, dq, a, phi),
            "ddq": tree.forward_dynamics(q, dq, a, phi)}


@pytest.mark.parametrize("batch", [(), (10,)])
def test_jax_jit_equals_numpy(x64, batch):
    """The same code traced: one jit'ed program of every term, one state (multiply-and-sum products) and 10 states
    (10 × 7 links: matmul products), to 1e-12."""
    jax = _jax()
    tree, _ = example("panda")
    rng = np.random.default_rng(5)
    q, dq, v, a = rng.normal(size=(4, *batch, tree.n))
    phi = random_phi(rng, tree, physical=True)
    compiled = jax.jit(functools.partial(every_term, tree))(q, dq, v, a, phi)
    for key, value in every_term(tree, q, dq, v, a, phi).items():
        close(np.asarray(compiled[key]), value, 1e-12)


def test_jax_vmap_and_the_tree_path(x64):
    """vmap over states equals the numpy batch; the branched-tree path (0/1 ancestry products) traces too."""
    jax = _jax()
    tree, _ = example("ur5")
    rng = np.random.default_rng(6)
    q, dq, v, a = rng.normal(size=(4, 4, tree.n))
    close(np.asarray(jax.vmap(tree.regressor)(q, dq, v, a)), tree.regressor(q, dq, v, a), 1e-12)
    branched = dataclasses.replace(tree, parents=(-1, 0, 1, 1, 3, 3))
    assert not branched._chain
    phi = branched.default_phi

    def terms(q, dq, v, a, phi):
        return branched.regressor(q, dq, v, a), branched.mass_matrix(q, phi), branched.forward_dynamics(q, dq, a, phi)

    for traced, plain in zip(jax.jit(terms)(q, dq, v, a, phi), terms(q, dq, v, a, phi), strict=True):
        close(np.asarray(traced), plain, 1e-12)


def test_pickle_and_replace():
    tree, _ = example("ur5")
    q, dq, v, a = np.random.default_rng(7).normal(size=(4, tree.n))
    other = pickle.loads(pickle.dumps(tree))
    np.testing.assert_array_equal(other.regressor(q, dq, v, a), tree.regressor(q, dq, v, a))
    bare = dataclasses.replace(tree, rotor_inertia=None, viscous=None, coulomb=None)
    assert bare.p == 60
    np.testing.assert_array_equal(bare.regressor(q, dq, v, a), tree.regressor(q, dq, v, a)[:, :60])


# -- bad input ----------------------------------------------------------------------------------------------------------

URDF = """<robot name="r">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0 0 0.1"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="b"><inertial><origin xyz="0.1 0 0"/><mass value="0.5"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="first" type="{kind}"><parent link="base"/><child link="a"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
  <joint name="second" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/><dynamics damping="0.3" friction="0.2"/></joint>
</robot>
"""


def raises(fn, field: str, *words: str) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        fn()
    assert info.value.field == field, str(info.value)
    assert "\n" not in str(info.value) and all(w in str(info.value) for w in words), str(info.value)
    return info.value


@pytest.mark.parametrize("kind", ["floating", "planar"])
def test_a_floating_or_planar_joint_is_refused_and_locking_it_works(tmp_path, kind):
    path = tmp_path / "arm.urdf"
    path.write_text(URDF.format(kind=kind))
    raises(lambda: KinematicTree.from_urdf(path), "robot.urdf", "'first'", "robot.locked")
    tree = KinematicTree.from_urdf(path, locked=["first"], viscous=True, coulomb=True)
    assert tree.joint_names == ("second",) and tree.n == 1
    np.testing.assert_array_equal(tree.default_phi[10:], [0.3, 0.2])


def test_a_good_urdf_with_friction_columns(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(URDF.format(kind="revolute"))
    tree = KinematicTree.from_urdf(path, viscous=True, gravity=[0, 0, -1.62])
    assert tree.param_names[-2:] == ("fv1", "fv2") and tree.name == "arm"
    np.testing.assert_array_equal(tree.g, [0.0, 0.0, -1.62])
    model = pin.buildModelFromUrdf(str(path))
    model.gravity = pin.Motion(np.array([0.0, 0.0, -1.62]), np.zeros(3))
    check_against_pinocchio(tree, model, np.random.default_rng(8))


def test_bad_urdf_input(tmp_path):
    raises(lambda: KinematicTree.from_urdf(tmp_path / "missing.urdf"), "robot.urdf", "no file", "existing")
    (tmp_path / "notes.urdf").write_text("not xml <")
    raises(lambda: KinematicTree.from_urdf(tmp_path / "notes.urdf"), "robot.urdf", "not an XML file")
    (tmp_path / "other.urdf").write_text("<sdf/>")
    raises(lambda: KinematicTree.from_urdf(tmp_path / "other.urdf"), "robot.urdf", "not a URDF")
    raises(lambda: KinematicTree.from_urdf(3), "robot.urdf", "path")
    path = tmp_path / "arm.urdf"
    path.write_text(URDF.format(kind="revolute"))
    raises(lambda: KinematicTree.from_urdf(path, locked=["elbow"]), "robot.locked", "'elbow'", "first, second")
    raises(lambda: KinematicTree.from_urdf(path, locked="first"), "robot.locked", "list of joint names")
    raises(lambda: KinematicTree.from_urdf(path, viscous="yes"), "robot.viscous", "true or false")
    raises(lambda: KinematicTree.example("atlas"), "robot.name", "panda")


def test_bad_pinocchio_models_and_tables():
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "shoulder")
    model.addJoint(j, pin.JointModelSpherical(), pin.SE3.Identity(), "wrist")
    raises(lambda: KinematicTree.from_pinocchio(model), "robot.model", "'wrist' (Spherical)", "lock")
    raises(lambda: KinematicTree.from_pinocchio(pin.Model()), "robot.model", "no moving joint")
    raises(lambda: KinematicTree.from_dh({"m": 1.0}), "robot.links", "list of link tables")
    raises(lambda: KinematicTree.from_dh([{"joint": "S", "m": 1.0}]), "robot.links[0].joint", "'R'")
    raises(lambda: KinematicTree.from_dh([{"a": 0.3}]), "robot.links[0].m", "mass")
    raises(lambda: KinematicTree.from_dh([{"m": 1.0, "mass": 2.0}]), "robot.links[0].mass", "unknown key")
    raises(lambda: KinematicTree.from_dh([{"m": 1.0}], convention="craig"), "robot.convention", "modified")
    good = KinematicTree.from_dh([{"m": 1.0, "a": 0.5}, {"m": 1.0, "a": 0.5}])
    raises(lambda: dataclasses.replace(good, rotation=good.rotation * 2), "robot.rotation", "rotation matrix")
    raises(lambda: dataclasses.replace(good, axis=good.axis * 2), "robot.axis", "unit vector")
    raises(lambda: dataclasses.replace(good, parents=(0, 1)), "robot.parents", "earlier joint")
    raises(lambda: dataclasses.replace(good, joints="RX"), "robot.joints", "'R'")
    raises(lambda: dataclasses.replace(good, link_params=np.zeros((2, 9))), "robot.link_params", "shape")
    raises(lambda: dataclasses.replace(good, viscous=[-1.0, 0.0]), "robot.viscous", "positive")


@pytest.mark.parametrize("name, reference", [("panda-slotine-li", "pinocchio"), ("panda-composite", "pinocchio"),
                                             ("ur5-dcal", "pinocchio"), ("puma560-slotine-li", "sympy")])
def test_packaged_n_dof_scenarios_compile_and_equal_the_reference_model(name, reference):
    """The scenarios build the kinematic tree by default and run compiled; the run equals the one on the model it is
    checked against (Pinocchio's C++ or the sympy expressions) stepped by numpy, to 1e-9 relative."""
    from robotadapt.studies.scenarios import load

    tree = load(name, ["simulation.t_final=0.1", "simulation.backend='jax'"])
    assert isinstance(tree.setup.controller.model, KinematicTree) and tree.setup.controller.model.traceable
    ref = load(name, ["simulation.t_final=0.1", f"robot.model='{reference}'", "simulation.backend='numpy'"])
    assert not isinstance(ref.setup.controller.model, KinematicTree)
    a, b = ref.run(), tree.run()
    assert a.status == b.status == "ok"
    for field in ("q", "dq", "x", "tau"):
        scale = max(1.0, float(np.abs(getattr(a, field)).max()))
        np.testing.assert_allclose(getattr(b, field), getattr(a, field), rtol=0, atol=1e-9 * scale, err_msg=field)


FLOATING = """<robot name="f"><link name="base"/><link name="l1"><inertial><mass value="1"/>
<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="j1" type="floating"><parent link="base"/><child link="l1"/></joint></robot>"""


@pytest.mark.parametrize("override, field", [
    ("robot={kind='urdf', path='MISSING'}", "robot.path"),
    ("robot={kind='urdf', path='FLOATING'}", "robot.path"),
    ("robot.locked_joints=['nonesuch']", "robot.locked_joints"),
])
def test_bad_urdf_scenarios_are_one_line_and_exit_2(tmp_path, capsys, override, field):
    from robotadapt.cli import main

    (tmp_path / "floating.urdf").write_text(FLOATING)
    override = override.replace("MISSING", str(tmp_path / "nonesuch.urdf"))
    override = override.replace("FLOATING", str(tmp_path / "floating.urdf"))
    assert main(["run", "panda-slotine-li", "--set", override, "--no-plots", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"robotadapt: error: {field}:"), err
