"""Friction a real joint has (docs/arms.md#friction-columns): besides viscous f_v q̇ and Coulomb f_c sgn q̇, a smooth
Coulomb term f_s tanh(q̇/v_s) at a fixed velocity scale v_s and a constant offset τ_off, each an optional group of one
column per joint.

Independent checks: F written out here, f_v q̇ + f_c sgn q̇ + f_s tanh(q̇/v_s) + τ_off with the coefficients read from φ
by their names, against every term of the models (Y, Y_h, Y_g, Yφ and Yᵀr without Y, F, τ, q̈); the Panda's rigid-body
part from Pinocchio's own algorithms, which know no friction; the MuJoCo plant's acceleration with the offset; the
scenario keys through the scenario builder; the consistent parts by name; and a noise-free identification that sees the
new columns and recovers a negative offset.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robotadapt.robots.catalog import dh_arm, example_arm, planar
from robotadapt.robots.consistency import consistency_metrics, parts, unformed
from robotadapt.robots.identifiability import base_parameters
from robotadapt.robots.kinematic_tree import KinematicTree
from robotadapt.studies.scenarios.build import robot
from robotadapt.validation import ConfigError

VS = [0.05, 0.2]  # v_s per joint of the two-link arms: neither 1 (q̇·v_s and q̇/v_s differ) nor equal


def two_link(model: str = "tree"):
    """A planar 2-link arm of rods with every friction group, a negative offset on joint 1."""
    return planar(2, lengths=[0.7, 0.5], masses=[1.5, 0.8], rods=True, viscous=[0.3, 0.1], coulomb=[0.4, 0.2],
                  smooth_coulomb=[0.5, 0.25], offset=[-0.3, 0.15], smooth_coulomb_velocity=VS, model=model)


DH_LINKS = [  # a vertical prismatic joint, then two revolute ones; groups given by some links only (others 0)
    {"joint": "P", "alpha": -np.pi / 2, "m": 2.0, "com": [0.0, 0.05, 0.0], "inertia": [0.02, 0.03, 0.02],
     "offset": -1.5, "smooth_coulomb": 0.8},
    {"a": 0.4, "m": 1.2, "com": [-0.2, 0.0, 0.01], "inertia": [0.001, 0.02, 0.02], "viscous": 0.2, "offset": 0.4},
    {"a": 0.3, "alpha": np.pi / 2, "m": 0.6, "com": [-0.1, 0.02, 0.0], "inertia": [0.001, 0.01, 0.01],
     "coulomb": 0.3, "smooth_coulomb": 0.1},
]


def dh_chain():
    return dh_arm(DH_LINKS, smooth_coulomb_velocity=[0.1, 0.03, 0.3])


def panda(model: str = "tree"):
    return example_arm("panda", viscous=True, coulomb=True, smooth_coulomb=True, offset=True,
                       smooth_coulomb_velocity=0.08, rotor_inertia=model == "tree", model=model)


ARMS = {"two-link": two_link, "two-link-sympy": lambda: two_link("sympy"), "dh-prismatic": dh_chain,
        "panda": panda, "panda-pinocchio": lambda: panda("pinocchio")}


def coefficients(model, phi: np.ndarray, prefix: str) -> np.ndarray:
    """φ's entries named prefix1 … prefixn (zeros when the model has no such group)."""
    index = {name: k for k, name in enumerate(model.param_names)}
    return np.array([phi[..., index[f"{prefix}{i + 1}"]] if f"{prefix}{i + 1}" in index else 0.0
                     for i in range(model.n)])


def velocity_scale(model) -> np.ndarray:
    return np.broadcast_to(np.asarray(model.smooth_coulomb_velocity, dtype=float), (model.n,))


def by_hand(model, dq: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """F = f_v q̇ + f_c sgn q̇ + f_s tanh(q̇/v_s) + τ_off, written out."""
    fv, fc, fs, off = (coefficients(model, phi, p) for p in ("fv", "fc", "fs", "off"))
    return fv * dq + fc * np.sign(dq) + fs * np.tanh(dq / velocity_scale(model)) + off


def states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """q, q̇, v, a for 7 states: q̇ of order 1, of order v_s (where tanh is not yet sgn) and exactly zero (rest)."""
    q, v, a = rng.uniform(-1.5, 1.5, (3, 7, n))
    dq = np.concatenate([rng.normal(size=(3, n)), 0.1 * rng.normal(size=(3, n)), np.zeros((1, n))])
    return q, dq, v, a


def close(x, y, tol: float = 1e-10) -> None:
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    assert x.shape == y.shape
    assert np.max(np.abs(x - y)) <= tol * max(1.0, float(np.max(np.abs(y))))


@pytest.mark.parametrize("name", sorted(ARMS))
def test_every_term_holds_the_new_friction_with_the_hand_written_f(name):
    """Y φ = M a + V_m v + G + F (P3) with F by hand; Y's friction columns, F, τ, Y_h φ = M q̇ (no friction, the offset
    included), Y_g φ = −V_mᵀ q̇ + G + F, q̈ of the forward dynamics, on states moving fast, slowly (|q̇| ~ v_s) and at
    rest (where only the offset acts)."""
    model = ARMS[name]()
    n, p = model.n, model.p
    assert model.param_names[-4 * n:] == tuple(f"{g}{i + 1}" for g in ("fv", "fc", "fs", "off") for i in range(n))
    rng = np.random.default_rng(6)
    q, dq, v, a = states(rng, n)
    phi = rng.normal(size=p)
    M, V, G = model.mass_matrix(q, phi), model.coriolis_matrix(q, dq, phi), model.gravity(q, phi)
    F = by_hand(model, dq, phi)
    Y = model.regressor(q, dq, v, a)
    close(Y @ phi, np.einsum("sij,sj->si", M, a) + np.einsum("sij,sj->si", V, v) + G + F)
    close(model.friction(dq, phi), F)
    close(model.inverse_dynamics(q, dq, a, phi), np.einsum("sij,sj->si", M, a) + np.einsum("sij,sj->si", V, dq) + G + F)
    close(model.momentum_regressor(q, dq) @ phi, np.einsum("sij,sj->si", M, dq))
    close(model.remainder_regressor(q, dq) @ phi, -np.einsum("sji,sj->si", V, dq) + G + F, 1e-8)
    index = {k: j for j, k in enumerate(model.param_names)}
    for i in range(n):  # the columns themselves: one per joint and group, on that joint's row only
        rows = np.arange(n) != i
        for prefix, column in (("fs", np.tanh(dq[:, i] / velocity_scale(model)[i])), ("off", np.ones(7))):
            close(Y[:, i, index[f"{prefix}{i + 1}"]], column, 1e-14)
            close(Y[:, rows, index[f"{prefix}{i + 1}"]], np.zeros((7, n - 1)), 0.0)
    if isinstance(model, KinematicTree):
        r = rng.normal(size=(7, n))
        Yphi, Ytr = model.regressor_products(q, dq, v, a, phi, r)
        close(Yphi, Y @ phi)
        close(Ytr, np.einsum("sij,si->sj", Y, r))
    physical = np.asarray(model.default_phi, dtype=float).copy()
    for prefix, scale in (("fs", 0.7), ("off", -0.4)):
        for i in range(n):
            physical[index[f"{prefix}{i + 1}"]] = scale * (i + 1)
    tau = rng.normal(size=(7, n))
    ddq = model.forward_dynamics(q, dq, tau, physical)
    M0 = model.mass_matrix(q, physical)
    bias = np.einsum("sij,sj->si", model.coriolis_matrix(q, dq, physical), dq) + model.gravity(q, physical)
    close(np.einsum("sij,sj->si", M0, ddq) + bias + by_hand(model, dq, physical), tau, 1e-9)


def test_the_panda_against_pinocchios_algorithms_plus_the_hand_written_friction():
    """Pinocchio's crba, Coriolis matrix, gravity and rnea hold the rigid-body part (and the rotor inertia as
    `armature`); the friction, which Pinocchio does not model, is the hand-written F."""
    pin = pytest.importorskip("pinocchio")
    tree, reference = panda(), panda("pinocchio")
    pm0 = reference.pin_model
    rng = np.random.default_rng(7)
    q, dq, v, a = states(rng, tree.n)
    for k in range(len(q)):
        phi = rng.normal(size=tree.p)
        phi[: 70 : 10] = rng.uniform(0.5, 2.0, 7)
        pm = pm0.copy()
        for j in range(1, pm.njoints):
            pm.inertias[j] = pin.Inertia.FromDynamicParameters(phi[10 * (j - 1) : 10 * j])
        pm.armature = coefficients(tree, phi, "Ia")
        pd = pm.createData()
        M = pin.crba(pm, pd, q[k]).copy()
        M = np.triu(M) + np.triu(M, 1).T
        C = pin.computeCoriolisMatrix(pm, pd, q[k], dq[k]).copy()
        G = pin.computeGeneralizedGravity(pm, pd, q[k]).copy()
        F = by_hand(tree, dq[k], phi)
        close(tree.regressor(q[k], dq[k], v[k], a[k]) @ phi, M @ a[k] + C @ v[k] + G + F)
        close(tree.inverse_dynamics(q[k], dq[k], a[k], phi), pin.rnea(pm, pd, q[k], dq[k], a[k]) + F)
        no_rotor = np.delete(phi, [tree.param_names.index(f"Ia{i + 1}") for i in range(7)])
        close(reference.regressor(q[k], dq[k], v[k], a[k]) @ no_rotor,
              M @ a[k] + C @ v[k] + G + F - coefficients(tree, phi, "Ia") * a[k])
        close(reference.momentum_regressor(q[k], dq[k]) @ no_rotor, M @ dq[k] - coefficients(tree, phi, "Ia") * dq[k])
        close(reference.friction(dq[k], no_rotor), F)


def test_the_compiled_model_traces_the_smooth_coulomb_and_offset_columns(x64):
    """The same code under jax.jit: Y and F equal numpy's to 1e-12."""
    pytest.importorskip("jax")
    from robotadapt.tracing import jax_module

    jax = jax_module()
    model = two_link()
    q, dq, v, a = states(np.random.default_rng(8), 2)
    phi = np.random.default_rng(9).normal(size=model.p)
    Y, F = jax.jit(lambda *x: (model.regressor(*x[:4]), model.friction(x[1], x[4])))(q, dq, v, a, phi)
    close(np.asarray(Y), model.regressor(q, dq, v, a), 1e-12)
    close(np.asarray(F), by_hand(model, dq, phi), 1e-12)


# -- scenario keys --------------------------------------------------------------------------------------------------


def test_scenario_keys_turn_the_groups_on_and_name_them():
    """`smooth_coulomb`, `offset` (switches on URDF arms and the PUMA, values on `planar` and per DH link) and
    `smooth_coulomb_velocity` (one or per joint); defaults zero, the PUMA's offset its published Coulomb asymmetry."""
    arm = robot({"kind": "planar", "n_links": 2, "smooth_coulomb": 0.2, "offset": [-0.1, 0.3],
                 "smooth_coulomb_velocity": 0.05})
    assert arm.param_names[-4:] == ("fs1", "fs2", "off1", "off2")
    close(arm.default_phi[-4:], [0.2, 0.2, -0.1, 0.3], 0.0)
    close(arm.smooth_coulomb_velocity, [0.05, 0.05], 0.0)
    names = [f"{g}{i}" for g in ("fc", "fs", "off") for i in range(1, 8)]
    for model in ("tree", "pinocchio"):
        urdf = robot({"kind": "example_robot", "name": "panda", "coulomb": True, "smooth_coulomb": True, "offset": True,
                      "smooth_coulomb_velocity": [0.1] * 6 + [0.3], "model": model})
        assert list(urdf.param_names[70:]) == names, model
        close(urdf.default_phi[77:], np.zeros(14), 0.0)
        close(urdf.smooth_coulomb_velocity, [0.1] * 6 + [0.3], 0.0)
    dh = robot({"kind": "dh", "links": DH_LINKS, "smooth_coulomb_velocity": 0.2})
    assert dh.param_names[30:] == tuple(f"{g}{i}" for g in ("fv", "fc", "fs", "off") for i in (1, 2, 3))
    close(dh.default_phi[36:], [0.8, 0.0, 0.1, -1.5, 0.4, 0.0], 0.0)
    puma = robot({"kind": "puma560", "coulomb": True, "offset": True})
    assert puma.param_names[60:] == tuple(f"{g}{i}" for g in ("fc", "off") for i in range(1, 7))
    gear, tc = np.array([-62.6111, 107.815, -53.7063, 76.0364, 71.923, 76.686]), np.array([
        [0.395, -0.435], [0.126, -0.071], [0.132, -0.105], [11.2e-3, -16.9e-3], [9.26e-3, -14.5e-3], [3.96e-3, -10.5e-3]])
    fc, off = puma.default_phi[60:66], puma.default_phi[66:]
    close(fc, np.abs(gear) * (tc[:, 0] - tc[:, 1]) / 2, 1e-15)
    close(fc + off, np.abs(gear) * tc[:, 0], 1e-14)  # moving forward: T_c+
    close(-fc + off, np.abs(gear) * tc[:, 1], 1e-14)  # moving back: T_c−
    assert robot({"kind": "puma560", "smooth_coulomb": True}).param_names[60:] == tuple(f"fs{i}" for i in range(1, 7))


@pytest.mark.parametrize(("section", "field"), [
    ({"kind": "example_robot", "name": "panda", "smooth_coulomb": "yes"}, "robot.smooth_coulomb"),
    ({"kind": "example_robot", "name": "panda", "offset": 1, "model": "pinocchio"}, "robot.offset"),
    ({"kind": "puma560", "offset": "true"}, "robot.offset"),
    ({"kind": "planar", "n_links": 2, "smooth_coulomb": [-0.1, 0.2]}, "robot.smooth_coulomb"),
    ({"kind": "planar", "n_links": 2, "smooth_coulomb": 0.1, "smooth_coulomb_velocity": 0.0},
     "robot.smooth_coulomb_velocity"),
    ({"kind": "example_robot", "name": "ur5", "smooth_coulomb_velocity": [0.1, 0.2]}, "robot.smooth_coulomb_velocity"),
    ({"kind": "dh", "links": [{"m": 1.0, "smooth_coulomb": -1.0}]}, "robot.links[0].smooth_coulomb"),
    ({"kind": "dh", "links": [{"m": 1.0, "offset": "x"}]}, "robot.links[0].offset"),
])
def test_bad_friction_keys_are_one_clear_error(section, field):
    with pytest.raises(ConfigError) as info:
        robot(section)
    assert info.value.field == field


def test_a_negative_offset_is_accepted_where_a_negative_coefficient_is_not():
    """An offset has either sign; f_v, f_c, f_s do not."""
    tree = two_link()
    assert tree.offset[0] < 0
    with pytest.raises(ConfigError, match="robot.smooth_coulomb"):
        dataclasses.replace(tree, smooth_coulomb=[-0.1, 0.0])
    dataclasses.replace(tree, offset=[-5.0, -1.0])


def test_a_scenario_with_the_keys_reaches_the_plant_and_the_controller():
    """`--set robot.smooth_coulomb=true robot.offset=true` on the Panda scenario: the controller's model and the plant's
    truth both have the 14 columns, the truth's zero (the URDF has no such numbers)."""
    from robotadapt.studies.scenarios import load

    setup = load("panda-slotine-li", ["robot.smooth_coulomb=true", "robot.offset=true",
                                      "robot.smooth_coulomb_velocity=0.05"]).setup
    names = tuple(f"{g}{i}" for g in ("fs", "off") for i in range(1, 8))
    assert setup.controller.model.param_names[70:] == names == setup.plant.model.param_names[70:]
    close(setup.plant.phi[70:], np.zeros(14), 0.0)
    close(setup.controller.model.smooth_coulomb_velocity, np.full(7, 0.05), 0.0)


# -- base parameters, physical consistency, identification -----------------------------------------------------------


def test_every_friction_column_is_a_base_parameter_and_friction_false_drops_them_all():
    """Each group adds n base parameters named after themselves (the offset too: constant, but no rigid-body column has a
    constant part — on the DH arm's vertical prismatic joint the masses with a constant gravity torque also have
    inertia); friction=False leaves every group out, the offset's constant column included."""
    for model, rigid in ((two_link(), planar(2, lengths=[0.7, 0.5], masses=[1.5, 0.8], rods=True)),
                         (dh_chain(), dh_arm([{k: v for k, v in link.items() if k not in (
                             "offset", "smooth_coulomb", "viscous", "coulomb")} for link in DH_LINKS]))):
        n = model.n
        full, without = base_parameters(model), base_parameters(model, friction=False)
        assert full.count == base_parameters(rigid).count + 4 * n == without.count + 4 * n
        friction = [k for k, name in enumerate(model.param_names) if name.rstrip("0123456789") in ("fv", "fc", "fs",
                                                                                                      "off")]
        assert set(friction) <= set(full.independent)
        assert {model.param_names[k] for k in friction} <= set(full.names)
        np.testing.assert_array_equal(without.K[:, friction], 0.0)
        assert full.margin[0] > 1e-3  # kept columns well away from the tolerance


def test_consistency_bounds_fs_like_fc_and_leaves_the_offset_free():
    names = two_link().param_names
    scalars = {part.name for part in parts(names) if len(part.entries) == 1}
    assert {"fv1", "fc2", "fs1", "fs2"} <= scalars
    assert not any(name.startswith("off") for name in scalars)
    assert unformed(names) == ["off1", "off2"]
    phi = two_link().default_phi  # off1 = −0.3
    t = np.array([0.0, 1.0])
    assert consistency_metrics(t, np.stack([phi, phi]), names)["physically_consistent"]
    bad = phi.copy()
    bad[names.index("fs2")] = -0.01
    metrics = consistency_metrics(t, np.stack([phi, bad]), names)
    assert not metrics["physically_consistent"] and metrics["left_consistent_set_part"] == "fs2"


def test_identification_sees_the_new_columns_and_recovers_a_negative_offset():
    """A noise-free log of the two-link arm (τ = Y φ along an exciting Fourier trajectory with slow reversals): W has
    the fs and off columns; least squares and the consistent estimate (offset unbounded, f_s ≥ ε) recover φ's."""
    pytest.importorskip("cvxpy")
    from robotadapt.analysis.identification import Preprocessing, identify
    from robotadapt.analysis.joint_data import JointData
    from robotadapt.trajectories import fourier

    model = planar(2, lengths=[0.7, 0.5], masses=[1.5, 0.8], rods=True, viscous=[0.3, 0.1],
                   smooth_coulomb=[0.5, 0.25], offset=[-0.3, 0.15], smooth_coulomb_velocity=VS)
    truth = model.default_phi
    t = np.arange(0.0, 12.0, 2e-3)
    ref = fourier(2, 6.0, [[0.6, -0.3, 0.2], [0.5, 0.25, -0.2]], [[0.1, 0.3, -0.1], [-0.4, 0.1, 0.2]], [0.3, -0.2])(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ truth
    res = identify(model, JointData(t, ref.q_des, ref.dq_des, tau, "friction"), Preprocessing(cutoff=None))
    for name in ("fs1", "fs2", "off1", "off2"):
        assert name in res.basis.names
    index = [model.param_names.index(name) for name in ("fs1", "fs2", "off1", "off2")]
    base_index = [res.basis.names.index(name) for name in ("fs1", "fs2", "off1", "off2")]
    for estimate in ("ols", "wls", "consistent"):
        close(res.base[estimate][base_index], truth[index], 1e-4)
    consistent = res.standard["consistent"]
    assert consistent[model.param_names.index("off1")] == pytest.approx(-0.3, abs=1e-4)
    assert consistent[model.param_names.index("fs2")] > 0


# -- MuJoCo -------------------------------------------------------------------------------------------------------------


def test_mujoco_applies_the_offset_and_refuses_a_smooth_coulomb_term():
    """MuJoCo's Euler step from rest: (q̇₁ − q̇₀)/dt is MuJoCo's q̈, which equals the model's with the offset (and differs
    from it without); a truth with f_s ≠ 0 is refused naming plant.phi, one with f_s = 0 is built."""
    from robotadapt.plant.mujoco import MujocoPlant, load_mujoco

    try:
        load_mujoco()
    except ConfigError:  # pragma: no cover - `make test` installs the extra
        pytest.skip("the mujoco extra is not installed")
    model = planar(2, lengths=[0.7, 0.5], masses=[1.5, 0.8], rods=True, smooth_coulomb=0.0, offset=[-0.3, 0.15])
    phi = model.default_phi
    q, u, dt = np.array([0.4, -0.7]), np.array([1.0, -0.5]), 1e-3
    expected = model.forward_dynamics(q, 0 * q, u, phi)
    for actuation in ("motor", "qfrc_applied"):
        plant = MujocoPlant(model, phi, integrator="Euler", actuation=actuation)
        s = plant.advance(0.0, np.concatenate([q, 0 * q]), u, 1, dt)
        close((s[2:] - 0.0) / dt, expected, 1e-8)
    assert np.max(np.abs(expected - model.forward_dynamics(q, 0 * q, u, np.concatenate([phi[:-2], [0.0, 0.0]])))) > 0.1
    assert plant.describe()["mujoco"]["offset"] == [-0.3, 0.15]
    smooth = phi.copy()
    smooth[model.param_names.index("fs2")] = 0.2
    with pytest.raises(ConfigError, match=r"^plant\.phi: MuJoCo has no smooth \(tanh\) Coulomb friction.*fs2 = 0\.2"):
        MujocoPlant(model, smooth)
