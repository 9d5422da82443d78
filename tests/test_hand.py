"""Task-space kinematics (robotadapt.robots.hand; `hand`, `kinematic_basis`, `kinematic_regressor` on every model)
against oracles that share no code with it:

- Pinocchio's frame algorithms (`forwardKinematics`, `updateFramePlacements`, `computeFrameJacobian`,
  `getFrameJacobianTimeVariation`, `getFrameClassicalAcceleration`, LOCAL_WORLD_ALIGNED) on a frame added at the tool
  offset: the Panda and the UR5 (URDF), DH arms placed joint by joint (revolute and prismatic rows, both conventions),
  a branched tree with unaligned and prismatic joints whose hand hangs on a branch;
- the book's closed forms (two-link, one-link and polar arms), written out here;
- JAX's forward-mode derivative along q̇ (J̇, Ḃ, ṗ = J_v q̇, Ṙ = [J_ω q̇]× R);
- the model rebuilt with one kinematic parameter changed (the basis columns are the derivatives in θ_k, exactly:
  p is linear in them);
- scipy's rotation vectors (orientation error).

Tolerances: 1e-12 relative to max(1, |expected|) everywhere (the computations agree to ~1e-15).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robotadapt.robots import OneLinkArm, PolarArm, RobotModel, TaskKinematics, TwoLinkArm, orientation_error
from robotadapt.robots.kinematic_tree import KinematicTree
from robotadapt.robots.symbolic import planar_arm, puma560
from robotadapt.validation import ConfigError

pin = pytest.importorskip("pinocchio")
from robotadapt.robots import dh  # noqa: E402
from robotadapt.robots.pinocchio import PinocchioArm  # noqa: E402

TOL = 1e-12
TOOL = np.array([0.07, -0.04, 0.12])
LWA = pin.LOCAL_WORLD_ALIGNED


def close(actual, expected, tol: float = TOL) -> None:
    """max |actual − expected| ≤ tol · max(1, max |expected|), shapes equal."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    err = float(np.abs(actual - expected).max(initial=0.0))
    assert err <= tol * max(1.0, float(np.abs(expected).max(initial=0.0))), f"error {err:.2e}"


def matvec(A, x):
    return np.einsum("...ij,...j->...i", A, x)


# -- the arms -------------------------------------------------------------------------------------------------------

DH_ROWS = {"joints": "RPRR", "a": [0.1, 0.0, 0.4, 0.2], "alpha": [0.3, -1.2, math.pi, 0.7],
           "d": [0.2, 0.3, 0.05, -0.1], "theta": [0.1, 0.4, -0.2, 0.0]}


def dh_arm(convention: str) -> tuple[KinematicTree, object, np.ndarray]:
    """A DH arm with a prismatic row and twists off multiples of π/2: (tree, the same arm placed joint by joint in a
    pinocchio.Model, the last DH frame in the last Pinocchio joint's frame)."""
    joints, n = DH_ROWS["joints"], 4
    links = [{"joint": joints[i], "m": 1.0, **{k: DH_ROWS[k][i] for k in ("a", "alpha", "d", "theta")}}
             for i in range(n)]
    tree = KinematicTree.from_dh(links, convention)
    geo = dh.Geometry(joints, *(tuple(DH_ROWS[k]) for k in ("a", "alpha", "d", "theta")), convention == "modified",
                      (0.0, 0.0, -9.81))
    model, parent, previous = pin.Model(), 0, np.eye(4)
    for i, (pre, post) in enumerate(dh.joint_placements(geo)):
        X = previous @ pre
        joint = pin.JointModelRZ() if joints[i] == "R" else pin.JointModelPZ()
        parent = model.addJoint(parent, joint, pin.SE3(X[:3, :3], X[:3, 3]), f"j{i}")
        model.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
        previous = post
    return tree, model, previous


def branched() -> tuple[KinematicTree, object]:
    """Joints 2 and 4 hang from joint 1; the hand is on joint 5, after the unaligned prismatic joint 4 (joints 2 and 3
    are off its path)."""
    rng = np.random.default_rng(3)
    model = pin.Model()
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    joints = [(0, pin.JointModelRY()), (1, pin.JointModelRevoluteUnaligned(axis)), (2, pin.JointModelPX()),
              (1, pin.JointModelPrismaticUnaligned(np.array([0.0, 0.6, 0.8]))), (4, pin.JointModelRZ())]
    for k, (parent, joint) in enumerate(joints):
        R = Rotation.random(random_state=k).as_matrix()
        j = model.addJoint(parent, joint, pin.SE3(R, rng.normal(scale=0.3, size=3)), f"j{k}")
        model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    return KinematicTree.from_pinocchio(model), model


def planar3() -> KinematicTree:
    return KinematicTree.from_symbolic(planar_arm(3, [0.5, 0.7, 0.9], derive=False))


def puma() -> KinematicTree:
    return KinematicTree.from_symbolic(puma560(derive=False))


ARMS = {  # name → (model, tool)
    "two_link": lambda: (TwoLinkArm(l1=0.7, l2=1.3), TOOL),
    "one_link": lambda: (OneLinkArm(), TOOL),
    "polar": lambda: (PolarArm(), TOOL),
    "planar3": lambda: (planar3(), None),
    "puma_tool": lambda: (puma(), TOOL),
    "dh_modified": lambda: (dh_arm("modified")[0], TOOL),
    "branched": lambda: (branched()[0], TOOL),
    "panda_tool": lambda: (KinematicTree.example("panda"), TOOL),
}


def frame_reference(model, joint: int, placement: np.ndarray, q: np.ndarray, dq: np.ndarray) -> dict[str, np.ndarray]:
    """Pinocchio's frame at `placement` (4×4) in joint `joint`'s frame: p, R, J, J̇ and the classical acceleration
    at q̈ = 0, LOCAL_WORLD_ALIGNED."""
    model = model.copy()
    frame = model.addFrame(pin.Frame("hand", joint, pin.SE3(placement[:3, :3], placement[:3, 3]),
                                     pin.FrameType.OP_FRAME))
    data = model.createData()
    pin.forwardKinematics(model, data, q, dq, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)
    out = {"p": data.oMf[frame].translation.copy(), "R": data.oMf[frame].rotation.copy()}
    acc = pin.getFrameClassicalAcceleration(model, data, frame, LWA)
    out["acc"] = np.concatenate([acc.linear, acc.angular])
    out["J"] = pin.computeFrameJacobian(model, data, q, frame, LWA).copy()
    pin.computeJointJacobiansTimeVariation(model, data, q, dq)
    out["dJ"] = pin.getFrameJacobianTimeVariation(model, data, frame, LWA).copy()
    return out


def offset(tool: np.ndarray | None) -> np.ndarray:
    X = np.eye(4)
    X[:3, 3] = 0.0 if tool is None else tool
    return X


def check_against_pinocchio(model_tree: RobotModel, model, joint: int, last: np.ndarray, tool, seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(3):
        q, dq = rng.uniform(-math.pi, math.pi, model.nv), rng.normal(size=model.nv)
        ref = frame_reference(model, joint, last @ offset(tool), q, dq)
        hand = model_tree.hand(q, dq, tool)
        for key in ("p", "R", "J", "dJ"):
            close(getattr(hand, key), ref[key])
        close(matvec(hand.dJ, dq), ref["acc"])  # classical acceleration at q̈ = 0: J̇ q̇


# -- Pinocchio --------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("tool", [None, TOOL], ids=["flange", "tool"])
@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_urdf_arms_match_pinocchio_frames(name, tool):
    """p, R, J, J̇ and J̇ q̇ (= the classical acceleration at q̈ = 0) of the last link's frame, with and without a
    tool offset, at random states; PinocchioArm.hand (Pinocchio itself, looped over a batch) equals the tree's."""
    tree, arm = KinematicTree.example(name), PinocchioArm.example(name)
    assert arm.pin_model.nq == arm.pin_model.nv == tree.n
    check_against_pinocchio(tree, arm.pin_model, tree.n, np.eye(4), tool, seed=1)
    q, dq = np.random.default_rng(2).normal(size=(2, 4, tree.n))
    for got, expected in zip(arm.hand(q, dq, tool), tree.hand(q, dq, tool), strict=True):
        close(got, expected)


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_dh_arms_match_pinocchio_frames(convention):
    """A DH arm with a prismatic row (tree from the table) against the arm placed joint by joint in Pinocchio: the
    hand is the last DH frame (the last joint's frame times its post-placement), offset by the tool."""
    tree, model, last = dh_arm(convention)
    check_against_pinocchio(tree, model, tree.n, last, TOOL, seed=3)


def test_a_branched_tree_matches_pinocchio_frames():
    """The hand on a branch after an unaligned prismatic joint; the off-path joints' columns are zero."""
    tree, model = branched()
    check_against_pinocchio(tree, model, tree.n, np.eye(4), TOOL, seed=4)
    hand = tree.hand(np.ones(5), np.ones(5), TOOL)
    assert np.all(hand.J[:, 1:3] == 0) and np.all(hand.dJ[:, 1:3] == 0) and np.all(np.abs(hand.J[:, [0, 3, 4]]).max(0) > 0)


# -- the book's arms: closed forms --------------------------------------------------------------------------------------

def test_two_link_closed_forms():
    """x = l1 c1 + l2 c12, y = l1 s1 + l2 s12 (a tool offset (tx, ty, tz) in link 2's frame adds tx along link 2 and
    ty across it), J and J̇ written out; the basis columns (c1, s1), (c12, s12) and their Jacobians."""
    l1, l2 = 0.7, 1.3
    arm = TwoLinkArm(l1=l1, l2=l2)
    rng = np.random.default_rng(5)
    for tool in (None, TOOL):
        tx, ty, tz = (0.0, 0.0, 0.0) if tool is None else TOOL
        for _ in range(3):
            (q1, q2), (w1, w2) = rng.normal(size=(2, 2))
            c1, s1, c12, s12 = math.cos(q1), math.sin(q1), math.cos(q1 + q2), math.sin(q1 + q2)
            a, b = l2 + tx, ty  # the hand in link 2's frame, seen from joint 2
            col2 = [-a * s12 - b * c12, a * c12 - b * s12, 0.0]
            dcol2 = [-(w1 + w2) * (a * c12 - b * s12), -(w1 + w2) * (a * s12 + b * c12), 0.0]
            J = np.array([[col2[0] - l1 * s1, col2[0]], [col2[1] + l1 * c1, col2[1]], [0, 0], [0, 0], [0, 0], [1, 1]])
            dJ = np.array([[dcol2[0] - w1 * l1 * c1, dcol2[0]], [dcol2[1] - w1 * l1 * s1, dcol2[1]],
                           [0, 0], [0, 0], [0, 0], [0, 0]])
            hand = arm.hand(np.array([q1, q2]), np.array([w1, w2]), tool)
            close(hand.p, [l1 * c1 + a * c12 - b * s12, l1 * s1 + a * s12 + b * c12, tz])
            close(hand.R, [[c12, -s12, 0], [s12, c12, 0], [0, 0, 1]])
            close(hand.J, J)
            close(hand.dJ, dJ)
        basis = arm.kinematic_basis(np.array([q1, q2]), np.array([w1, w2]))
        close(basis.h, [[0, 0, 0], [c1, s1, 0], [c12, s12, 0]])
        close(basis.B[1], [[-s1, 0], [c1, 0], [0, 0]])
        close(basis.B[2], [[-s12, -s12], [c12, c12], [0, 0]])
        close(basis.dB[1], [[-w1 * c1, 0], [-w1 * s1, 0], [0, 0]])
        only_l2 = arm.kinematic_basis(np.array([q1, q2]), np.array([w1, w2]), unknown=("l2",))
        close(only_l2.h, [[l1 * c1, l1 * s1, 0], [c12, s12, 0]])
        close(only_l2.B[0], [[-l1 * s1, 0], [l1 * c1, 0], [0, 0]])
    assert arm.kinematic_names(TOOL) == ("l1", "l2", "tool.x", "tool.y", "tool.z")
    close(arm.kinematic_values(TOOL), [l1, l2, *TOOL])


def test_one_link_and_polar_closed_forms():
    """One link: p = l (cos q, sin q), l = OneLinkArm.length. Polar: p = r (cos θ, sin θ), J_v = [r e_θ, e_r],
    J̇_v = [ṙ e_θ − r θ̇ e_r, θ̇ e_θ], J_ω = [e_z, 0]; the radial travel is the basis's known part."""
    q, w = 0.4, -1.3
    c, s = math.cos(q), math.sin(q)
    hand = OneLinkArm().hand(np.array([q]), np.array([w]))
    close(hand.p, [c, s, 0])
    close(hand.J, [[-s], [c], [0], [0], [0], [1]])
    close(hand.dJ, [[-w * c], [-w * s], [0], [0], [0], [0]])
    assert OneLinkArm().kinematic_names() == ("l",) and OneLinkArm.length == 1.0
    r, dr = 0.8, 0.5
    e_r, e_t = np.array([c, s, 0]), np.array([-s, c, 0])
    polar = PolarArm()
    hand = polar.hand(np.array([q, r]), np.array([w, dr]))
    close(hand.p, r * e_r)
    close(hand.R, [[c, -s, 0], [s, c, 0], [0, 0, 1]])
    close(hand.J, np.concatenate([np.stack([r * e_t, e_r], axis=-1), [[0, 0], [0, 0], [1, 0]]]))
    close(hand.dJ, np.concatenate([np.stack([dr * e_t - r * w * e_r, w * e_t], axis=-1), np.zeros((3, 2))]))
    basis = polar.kinematic_basis(np.array([q, r]), np.array([w, dr]))
    assert polar.kinematic_names() == () and basis.h.shape == (1, 3)
    close(basis.h[0], r * e_r)
    close(basis.B[0], hand.J[:3])


def test_two_link_equals_the_planar_tree():
    """The book's arm and the DH planar arm of the same lengths: the same hand, the same basis (l_i = joint i's a)."""
    arm, tree = TwoLinkArm(l1=0.7, l2=1.3), KinematicTree.from_symbolic(planar_arm(2, [0.7, 1.3], derive=False))
    q, dq = np.random.default_rng(6).normal(size=(2, 3, 2))
    for got, expected in zip(arm.hand(q, dq, TOOL), tree.hand(q, dq, TOOL), strict=True):
        close(got, expected)
    assert tree.kinematic_names() == ("joint1.link.x", "joint2.link.x")
    for got, expected in zip(arm.kinematic_basis(q, dq, TOOL), tree.kinematic_basis(q, dq, TOOL), strict=True):
        close(got, expected)


# -- time derivatives (JAX forward mode) ----------------------------------------------------------------------------

def _jax():
    pytest.importorskip("jax")
    from robotadapt.tracing import jax_module

    return jax_module()


def skew(w):
    z = np.zeros_like(w[..., 0])
    return np.stack([np.stack([z, -w[..., 2], w[..., 1]], -1), np.stack([w[..., 2], z, -w[..., 0]], -1),
                     np.stack([-w[..., 1], w[..., 0], z], -1)], -2)


@pytest.mark.parametrize("name", sorted(ARMS))
def test_rates_are_the_time_derivatives(x64, name):
    """d/dt along q̇ (jax.jvp): ṗ = J_v q̇, Ṙ = [J_ω q̇]× R, J̇ = dJ, Ḃ = dB, at random states."""
    jax = _jax()
    model, tool = ARMS[name]()
    rng = np.random.default_rng(7)
    for _ in range(2):
        q, dq = rng.uniform(-math.pi, math.pi, model.n), rng.normal(size=model.n)

        def parts(q, dq=dq):
            hand, basis = model.hand(q, dq, tool), model.kinematic_basis(q, dq, tool)
            return hand.p, hand.R, hand.J, basis.B

        (p, R, J, B), (dp, dR, dJ, dB) = (tuple(np.asarray(x) for x in y) for y in jax.jvp(parts, (q,), (dq,)))
        hand, basis = model.hand(q, dq, tool), model.kinematic_basis(q, dq, tool)
        close(dp, matvec(hand.J[:3], dq))
        close(dR, skew(matvec(hand.J[3:], dq)) @ hand.R)
        close(dJ, hand.dJ)
        close(dB, basis.dB)


# -- the kinematic basis ----------------------------------------------------------------------------------------------

def rebuilt(model: KinematicTree, name: str, delta: float) -> tuple[KinematicTree, float]:
    """The tree with the placement component `name` changed by `delta`, and its value."""
    joint, *link, axis = name.split(".")
    key = "link_translation" if link else "translation"
    table = getattr(model, key).copy()
    k, c = model.joint_names.index(joint), "xyz".index(axis)
    value = table[k, c]
    table[k, c] += delta
    return dataclasses.replace(model, **{key: table}), value


TREES = ["puma_tool", "dh_modified", "branched", "panda_tool"]


@pytest.mark.parametrize("name", [*TREES, "two_link"])
def test_basis_columns_are_the_parameter_derivatives(name):
    """Each column (h_j, B_j, Ḃ_j) equals the change of (p, J_v, J̇_v) when the model is rebuilt with θ_j + δ (exact:
    p is linear in θ_k), and kinematic_values holds the value the name points at."""
    model, tool = ARMS[name]()
    q, dq = np.random.default_rng(8).normal(size=(2, model.n))
    hand, basis = model.hand(q, dq, tool), model.kinematic_basis(q, dq, tool)
    names, values, delta = model.kinematic_names(tool), model.kinematic_values(tool), 0.25
    assert len(names) == len(values) == basis.h.shape[0] - 1 >= 4
    for j, parameter in enumerate(names):
        if parameter.startswith("tool."):
            other, changed, value = model, TOOL + delta * np.eye(3)["xyz".index(parameter[-1])], TOOL["xyz".index(
                parameter[-1])]
        elif name == "two_link":
            other, changed, value = dataclasses.replace(model, **{parameter: values[j] + delta}), tool, values[j]
        else:
            (other, value), changed = rebuilt(model, parameter, delta), tool
        assert values[j] == value
        moved = other.hand(q, dq, changed)
        close((moved.p - hand.p) / delta, basis.h[j + 1])
        close((moved.J[:3] - hand.J[:3]) / delta, basis.B[j + 1])
        close((moved.dJ[:3] - hand.dJ[:3]) / delta, basis.dB[j + 1])


@pytest.mark.parametrize("name", ["two_link", "planar3", "puma_tool", "panda_tool"])
def test_revolute_arms_are_their_parameters_alone(name):
    """With every parameter unknown, a revolute arm's known part is zero; the basis gives p and J_v at θ_k."""
    model, tool = ARMS[name]()
    q, dq = np.random.default_rng(9).normal(size=(2, 4, model.n))
    basis, hand = model.kinematic_basis(q, dq, tool), model.hand(q, dq, tool)
    theta = model.kinematic_values(tool)
    for part in basis:
        close(part[:, 0], np.zeros_like(part[:, 0]), 1e-15)
    close(np.einsum("j,...jx->...x", theta, basis.h[:, 1:]), hand.p)
    close(np.einsum("j,...jxn->...xn", theta, basis.B[:, 1:]), hand.J[:, :3])


def test_unknown_subset_folds_the_rest_in():
    """unknown = a subset, in the order given: index 0 = the full index 0 plus the known parameters' columns × their
    values; unknown names and repeats are errors."""
    model, tool = ARMS["dh_modified"]()
    q, dq = np.random.default_rng(10).normal(size=(2, 3, model.n))
    names, values = model.kinematic_names(tool), model.kinematic_values(tool)
    full = model.kinematic_basis(q, dq, tool)
    unknown = ("tool.z", names[0], names[2])
    part = model.kinematic_basis(q, dq, tool, unknown)
    index = [names.index(u) for u in unknown]
    rest = [j for j in range(len(names)) if j not in index]
    for got, all_ in zip(part, full, strict=True):
        assert got.shape[1] == 1 + len(unknown)
        close(got[:, 1:], all_[:, [1 + j for j in index]])
        expected = all_[:, 0] + np.einsum("j,aj...->a...", values[rest], all_[:, [1 + j for j in rest]])
        close(got[:, 0], expected)
    for bad in (("tool.w",), (names[0], names[0]), ("tool.x",)):
        with pytest.raises(ConfigError, match="unknown"):
            model.kinematic_basis(q, dq, None if bad == ("tool.x",) else tool, bad)


@pytest.mark.parametrize("name", ["polar", "dh_modified", "panda_tool"])
def test_the_kinematic_regressor(name):
    """Y_k θ_k + known = J_v q̇ = ṗ, Y_k[:, j] = B_j q̇ (batch (2, 3)); with no unknown, Y_k has no column."""
    model, tool = ARMS[name]()
    q, dq = np.random.default_rng(11).normal(size=(2, 2, 3, model.n))
    Y, known = model.kinematic_regressor(q, dq, tool)
    basis, hand = model.kinematic_basis(q, dq, tool), model.hand(q, dq, tool)
    assert Y.shape == (2, 3, 3, len(model.kinematic_names(tool))) and known.shape == (2, 3, 3)
    close(matvec(Y, model.kinematic_values(tool)) + known, matvec(hand.J[..., :3, :], dq))
    close(Y[..., 0], matvec(basis.B[..., 1, :, :], dq))
    close(known, matvec(basis.B[..., 0, :, :], dq))
    Y, known = model.kinematic_regressor(q, dq, tool, unknown=())
    assert Y.shape == (2, 3, 3, 0)
    close(known, matvec(hand.J[..., :3, :], dq))


def test_dh_parameter_names():
    """Standard DH: revolute "jointi.link.x" = a_i, "jointi.link.z" = d_i (the PUMA 560's d1, a2, a3, d3, d4);
    modified, prismatic joint 2: "joint2.x" = a_1, "joint2.y" = −d_2 sin α_1, "joint2.z" = d_2 cos α_1."""
    arm = puma()
    assert arm.kinematic_names() == ("joint1.link.z", "joint2.link.x", "joint3.link.x", "joint3.link.z",
                                     "joint4.link.z")
    close(arm.kinematic_values(), [0.672, 0.4318, 0.0203, 0.15005, 0.4318])
    tree = dh_arm("modified")[0]
    names, values = tree.kinematic_names(), dict(zip(tree.kinematic_names(), tree.kinematic_values(), strict=True))
    a, alpha, d = DH_ROWS["a"], DH_ROWS["alpha"], DH_ROWS["d"]
    assert names == ("joint1.x", "joint1.link.z", "joint2.y", "joint2.z", "joint3.x", "joint3.link.z", "joint4.x",
                     "joint4.link.z")
    close([values["joint2.y"], values["joint2.z"], values["joint3.x"], values["joint4.link.z"]],
          [-d[1] * math.sin(alpha[1]), d[1] * math.cos(alpha[1]), a[2], d[3]])


def test_task_axes():
    """(0, 1) for arms that move in the x–y plane (a joint sliding in the plane included), (0, 1, 2) otherwise (a
    SCARA's vertical slide)."""
    model = pin.Model()
    for k, joint in enumerate([pin.JointModelRZ(), pin.JointModelPX(), pin.JointModelRZ()]):
        j = model.addJoint(k, joint, pin.SE3(Rotation.from_euler("z", k).as_matrix(), np.array([0.3, 0.1, 0.2])), f"j{k}")
        model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    scara = KinematicTree.from_dh([{"a": 0.4, "m": 1.0}, {"a": 0.3, "m": 1.0}, {"joint": "P", "m": 1.0}])
    planar = {"two_link": TwoLinkArm(), "one_link": OneLinkArm(), "polar": PolarArm(), "planar3": planar3(),
              "sliding": KinematicTree.from_pinocchio(model)}
    spatial = {"puma": puma(), "panda": KinematicTree.example("panda"), "dh": dh_arm("standard")[0],
               "branched": branched()[0], "scara": scara}
    assert {k: m.task_axes for k, m in planar.items()} == dict.fromkeys(planar, (0, 1))
    assert {k: m.task_axes for k, m in spatial.items()} == dict.fromkeys(spatial, (0, 1, 2))


def test_a_model_without_a_hand_is_refused_by_the_task_laws():
    """A model of the user's own without task-space kinematics is refused by a task-space law in one line naming the
    robot; every packaged arm but the Pinocchio model is a TaskKinematics, which gives the hand alone (no reach bound)."""
    from robotadapt.controllers.task_space import TaskSlotineLi
    from robotadapt.robots.workspace import reach

    class Bare(RobotModel):
        n, param_names = 1, ("m",)
        mass_matrix = coriolis_matrix = gravity = friction = regressor = None  # the dynamics play no part here

    with pytest.raises(ConfigError, match="Bare has no hand frame for a task-space law"):
        TaskSlotineLi(Bare(), Lam=1.0, Kv=1.0, Gamma=1.0, phi_hat0=[1.0])
    assert all(isinstance(arm, TaskKinematics) for arm in (TwoLinkArm(), PolarArm(), KinematicTree.example("ur5")))
    ur5 = PinocchioArm.example("ur5")
    assert not isinstance(ur5, TaskKinematics) and reach(ur5) is None and ur5.task_axes == (0, 1, 2)


# -- JAX and batches --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["two_link", "polar", "branched", "panda_tool", "symbolic"])
def test_jit_equals_numpy_with_batch_axes(x64, name):
    """hand and kinematic_basis traced by jax.jit with the model as an argument (its leaves traced; the SymbolicArm
    carries its kinematic tree), on q of shape (5, n), equal numpy's; a single state keeps no batch axis."""
    jax = _jax()
    model, tool = (planar_arm(3), TOOL) if name == "symbolic" else ARMS[name]()
    q, dq = np.random.default_rng(12).normal(size=(2, 5, model.n))
    unknown = model.kinematic_names(tool)[-2:]
    assert unknown == ("tool.y", "tool.z") and len(model.kinematic_values(tool)) == len(model.kinematic_names(tool))

    def both(model, q, dq, tool):
        return model.hand(q, dq, tool), model.kinematic_basis(q, dq, tool, unknown)

    traced, plain = jax.jit(both)(model, q, dq, tool), both(model, q, dq, tool)
    for got, expected in zip(jax.tree_util.tree_leaves(traced), jax.tree_util.tree_leaves(plain), strict=True):
        close(np.asarray(got), expected)
    hand, basis = plain
    n, k = model.n, len(unknown)
    assert (hand.p.shape, hand.R.shape, hand.J.shape, hand.dJ.shape) == ((5, 3), (5, 3, 3), (5, 6, n), (5, 6, n))
    assert (basis.h.shape, basis.B.shape, basis.dB.shape) == ((5, k + 1, 3), (5, k + 1, 3, n), (5, k + 1, 3, n))
    one = model.hand(q[3], dq[3], tool)
    assert one.J.shape == (6, n)
    close(one.dJ, hand.dJ[3])
    grid = model.kinematic_basis(q[:2, None], dq[:3], tool, unknown)  # leading axes (2, 1) and (3,) broadcast
    assert all(part.shape[:2] == (2, 3) for part in (*grid, *model.hand(q[:2, None], dq[:3], tool)))
    for got, expected in zip(grid, model.kinematic_basis(q[1], dq[2], tool, unknown), strict=True):
        close(got[1, 2], expected)


# -- orientation error --------------------------------------------------------------------------------------------------

def test_orientation_error():
    """log(R_d Rᵀ): zero at R = R_d; the rotation vector e of R_d = exp([e]×) R at every angle (scipy's), small ones
    (down to 1e-12 rad) and near π included; odd."""
    rng = np.random.default_rng(13)
    R = Rotation.random(600, random_state=14).as_matrix()
    axes = rng.normal(size=(600, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0.0, math.pi, 200), math.pi - 10.0 ** rng.uniform(-8, -1, 200),
                             10.0 ** rng.uniform(-12, -1, 200)])
    e = axes * angles[:, None]
    R_d = Rotation.from_rotvec(e).as_matrix() @ R
    close(orientation_error(R, R), np.zeros((600, 3)), 0.0)
    got = orientation_error(R_d, R)
    close(got, e)
    close(got, Rotation.from_matrix(R_d @ np.swapaxes(R, -1, -2)).as_rotvec())
    close(orientation_error(R, R_d), -got)
    small = orientation_error(Rotation.from_rotvec(e[400:]).as_matrix(), np.eye(3))  # relative to the angle
    close(small / angles[400:, None], axes[400:])
    about = np.concatenate([np.eye(3), [[0.6, 0.8, 0.0], [0.0, 1e-9, -1.0]]])  # axes with zero components, near π
    for angle in (2.0, 3.0, math.pi - 1e-7):
        close(orientation_error(Rotation.from_rotvec(angle * about).as_matrix(), np.eye(3)), angle * about)


def test_orientation_error_traces(x64):
    jax = _jax()
    R = Rotation.random(4, random_state=15).as_matrix()
    R_d = Rotation.from_rotvec([[0.1, 0, 0], [0, 2.0, 0], [0, 0, 3.1], [1e-9, 0, 0]]).as_matrix() @ R
    close(np.asarray(jax.jit(orientation_error)(R_d, R)), orientation_error(R_d, R))
