"""URDF arms through Pinocchio (robots/pinocchio.py): every term against Pinocchio's own algorithms on the URDF's
parameters, the mixed-regressor identity, skew symmetry, the batch contract, other parameter vectors, a planar URDF
against the textbook two-link arm, and the Panda / UR5 scenarios.

Expected values come from Pinocchio's `crba`, `computeCoriolisMatrix`, `computeGeneralizedGravity`, `rnea` and `aba`
(with the model's own inertias, or a copy whose inertias were changed), never from the code under test.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robotadapt.robots import TwoLinkArm
from robotadapt.robots.base import RobotModel
from robotadapt.validation import ConfigError

pin = pytest.importorskip("pinocchio")
from robotadapt.robots.pinocchio import EXAMPLES, PinocchioArm  # noqa: E402

SETTINGS = settings(max_examples=25, deadline=None)
RTOL = 1e-9


@pytest.fixture(scope="module", params=["panda", "ur5"])
def arm(request):
    return PinocchioArm.example(request.param)


def states(n: int, seed: int, lead: tuple[int, ...] = ()) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    return tuple(rng.uniform(-np.pi, np.pi, lead + (n,)) if k == 0 else rng.normal(size=lead + (n,)) for k in range(4))


def reference(model, q, dq, v, a):
    """(M, V_m, G, mixed τ, rnea τ) from Pinocchio with the model's own inertias."""
    data = model.createData()
    M = pin.crba(model, data, q).copy()
    M = np.triu(M) + np.triu(M, 1).T
    V = pin.computeCoriolisMatrix(model, data, q, dq).copy()
    G = pin.computeGeneralizedGravity(model, data, q).copy()
    return M, V, G, M @ a + V @ v + G, pin.rnea(model, data, q, dq, a).copy()


def close(actual, expected, rtol=RTOL):
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rtol * max(1.0, np.abs(expected).max()))


seeds = st.integers(0, 2**32 - 1)


@SETTINGS
@given(seed=seeds)
def test_terms_equal_pinocchios_algorithms(arm, seed):
    q, dq, v, a = states(arm.n, seed)
    phi = arm.default_phi
    M, V, G, tau_mixed, tau_rnea = reference(arm.pin_model, q, dq, v, a)
    close(arm.mass_matrix(q, phi), M)
    close(arm.coriolis_matrix(q, dq, phi) @ v, V @ v)
    close(arm.coriolis_matrix(q, dq, phi), V)
    close(arm.gravity(q, phi), G)
    close(arm.regressor(q, dq, v, a) @ phi, tau_mixed)  # the mixed (Slotine–Li) identity, P3
    close(arm.regressor(q, dq, dq, a) @ phi, tau_rnea)
    close(arm.inverse_dynamics(q, dq, a, phi), tau_rnea)
    close(arm.momentum_regressor(q, dq) @ phi, M @ dq)
    close(arm.forward_dynamics(q, dq, tau_rnea, phi), a, 1e-8)


@SETTINGS
@given(seed=seeds)
def test_friction_columns_and_remainder_regressor(seed):
    arm = PinocchioArm.example("ur5", viscous=True, coulomb=True)
    rng = np.random.default_rng(seed)
    q, dq, v, a = states(arm.n, seed)
    fv, fc = rng.uniform(0.1, 2.0, (2, arm.n))
    phi = np.concatenate([arm.default_phi[:60], fv, fc])
    M, V, G, tau_mixed, tau_rnea = reference(arm.pin_model, q, dq, v, a)
    F = fv * dq + fc * np.sign(dq)
    close(arm.friction(dq, phi), F)
    close(arm.regressor(q, dq, v, a) @ phi, tau_mixed + F)
    close(arm.remainder_regressor(q, dq) @ phi, -V.T @ dq + G + F, 1e-7)  # (6.6.4), by differences in the base class
    close(arm.forward_dynamics(q, dq, tau_rnea + F, phi), a, 1e-8)


@SETTINGS
@given(seed=seeds)
def test_mdot_minus_2v_is_skew_symmetric(arm, seed):
    q, dq, _, _ = states(arm.n, seed)
    phi, h = arm.default_phi, 1e-6
    Mdot = (arm.mass_matrix(q + h * dq, phi) - arm.mass_matrix(q - h * dq, phi)) / (2 * h)
    N = Mdot - 2 * arm.coriolis_matrix(q, dq, phi)
    assert np.abs(N + N.T).max() < 1e-7 * max(1.0, np.abs(Mdot).max())
    assert np.abs(Mdot - arm.coriolis_matrix(q, dq, phi) - arm.coriolis_matrix(q, dq, phi).T).max() < 1e-7


def test_batch_contract_over_states_and_parameters(arm):
    n, p = arm.n, arm.p
    q, dq, v, a = states(n, 3, (3, 1))
    dq = np.broadcast_to(dq, (3, 4, n)) + np.arange(4)[:, None]  # (3, 4, n) against q (3, 1, n)
    phi = arm.default_phi * np.array([1.0, 2.0])[:, None, None, None]  # (2, 1, 1, p)
    assert arm.regressor(q, dq, v, a).shape == (3, 4, n, p)
    assert arm.mass_matrix(q, phi).shape == (2, 3, 1, n, n)
    assert arm.coriolis_matrix(q, dq, phi).shape == (2, 3, 4, n, n)
    assert arm.gravity(q, phi).shape == (2, 3, 1, n)
    assert arm.friction(dq, arm.default_phi).shape == (3, 4, n)
    assert arm.momentum_regressor(q, dq).shape == (3, 4, n, p)
    assert arm.forward_dynamics(q, dq, v, arm.default_phi).shape == (3, 4, n)
    Y = arm.regressor(q, dq, v, a)
    for i, j in [(0, 0), (2, 3)]:
        np.testing.assert_array_equal(Y[i, j], arm.regressor(q[i, 0], dq[i, j], v[i, 0], a[i, 0]))
        close(arm.mass_matrix(q, phi)[1, i, 0], 2 * arm.mass_matrix(q[i, 0], arm.default_phi))


def modified(model, link: int, mass_factor: float):
    """A copy of `model` whose link `link` has its mass scaled, centre of mass and inertia about it kept."""
    other = model.copy()
    inertia = other.inertias[link]
    other.inertias[link] = pin.Inertia(mass_factor * inertia.mass, inertia.lever, inertia.inertia)
    return other


def test_other_parameters_give_the_modified_robots_dynamics():
    arm = PinocchioArm.example("panda")
    other = modified(modified(arm.pin_model, 3, 2.0), 7, 1.5)  # a heavier elbow and a payload on the flange
    phi = np.concatenate([other.inertias[j].toDynamicParameters() for j in range(1, other.njoints)])
    assert not np.allclose(phi, arm.default_phi)
    for seed in range(5):
        q, dq, v, a = states(arm.n, seed)
        M, V, G, tau_mixed, tau_rnea = reference(other, q, dq, v, a)
        close(arm.mass_matrix(q, phi), M)
        close(arm.coriolis_matrix(q, dq, phi), V)
        close(arm.gravity(q, phi), G)
        close(arm.regressor(q, dq, v, a) @ phi, tau_mixed)
        close(arm.forward_dynamics(q, dq, tau_rnea, phi), pin.aba(other, other.createData(), q, dq, tau_rnea), 1e-8)


def test_terms_are_linear_in_phi_also_where_pinocchio_has_no_inertia():
    """A controller's φ̂ starts at zero (no pin.Inertia has a zero mass): M, V_m, G vanish, and M is linear in φ."""
    arm = PinocchioArm.example("ur5")
    q, dq, _, _ = states(arm.n, 7)
    zero = np.zeros(arm.p)
    assert np.abs(arm.mass_matrix(q, zero)).max() == 0.0
    assert np.abs(arm.coriolis_matrix(q, dq, zero)).max() == 0.0
    assert np.abs(arm.gravity(q, zero)).max() == 0.0
    rng = np.random.default_rng(0)
    phi1, phi2 = rng.normal(size=(2, arm.p))
    close(arm.mass_matrix(q, phi1 + 3 * phi2), arm.mass_matrix(q, phi1) + 3 * arm.mass_matrix(q, phi2))
    close(arm.forward_dynamics(q, dq, dq, -arm.default_phi), RobotModel.forward_dynamics(arm, q, dq, dq,
                                                                                           -arm.default_phi))


PLANAR_URDF = """<?xml version="1.0"?>
<robot name="planar_two_link">
  <link name="base"/>
  <link name="link1"><inertial><origin xyz="{l1} 0 0"/><mass value="{m1}"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <link name="link2"><inertial><origin xyz="{l2} 0 0"/><mass value="{m2}"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <joint name="shoulder" type="continuous"><parent link="base"/><child link="link1"/><axis xyz="0 -1 0"/></joint>
  <joint name="elbow" type="revolute"><parent link="link1"/><child link="link2"/><origin xyz="{l1} 0 0"/>
    <axis xyz="0 -1 0"/><limit lower="-3.2" upper="3.2" effort="100" velocity="10"/></joint>
</robot>
"""


def test_planar_urdf_equals_the_textbook_two_link_arm(tmp_path):
    """Point masses at the link ends, rotation about −y so that angles rise from the horizontal against gravity −z:
    the book's arm (spec §1.3), with the continuous shoulder going through Pinocchio's (cos, sin) configuration."""
    l1, l2, m1, m2 = 0.7, 1.3, 0.8, 2.3
    path = tmp_path / "planar.urdf"
    path.write_text(PLANAR_URDF.format(l1=l1, l2=l2, m1=m1, m2=m2))
    arm = PinocchioArm.from_urdf(path, gravity=[0.0, 0.0, -9.8])
    book = TwoLinkArm(l1=l1, l2=l2, g=9.8)
    assert arm.n == 2 and arm.pin_model.nq == 3 and arm.joint_names == ("shoulder", "elbow")
    point = [[m, m * l, 0, 0, 0, 0, m * l**2, 0, 0, m * l**2] for m, l in ((m1, l1), (m2, l2))]
    phi = np.concatenate(point)
    close(arm.default_phi, phi, 1e-12)
    masses = np.array([m1, m2])
    for seed in range(10):
        q, dq, v, a = states(2, seed)
        close(arm.mass_matrix(q, phi), book.mass_matrix(q, masses), 1e-12)
        close(arm.coriolis_matrix(q, dq, phi), book.coriolis_matrix(q, dq, masses), 1e-12)
        close(arm.gravity(q, phi), book.gravity(q, masses), 1e-12)
        close(arm.regressor(q, dq, v, a) @ phi, book.regressor(q, dq, v, a) @ masses, 1e-12)
    lower, upper = arm.position_limits
    np.testing.assert_array_equal(lower, [-np.inf, -3.2])
    np.testing.assert_array_equal(upper, [np.inf, 3.2])


def test_gravity_vector_of_a_mounted_arm():
    q, _, _, _ = states(6, 1)
    up = PinocchioArm.example("ur5")
    ceiling = PinocchioArm.example("ur5", gravity=[0.0, 0.0, 9.81])
    space = PinocchioArm.example("ur5", gravity=[0.0, 0.0, 0.0])
    close(ceiling.gravity(q, up.default_phi), -up.gravity(q, up.default_phi))
    assert np.abs(space.gravity(q, up.default_phi)).max() == 0.0


def test_parameters_names_and_defaults():
    arm = PinocchioArm.example("panda", viscous=True, coulomb=True)
    assert arm.n == 7 and arm.p == 84 and arm.name == "panda"
    assert arm.param_names[:10] == ("m1", "mx1", "my1", "mz1", "Ixx1", "Ixy1", "Iyy1", "Ixz1", "Iyz1", "Izz1")
    assert arm.param_names[70:72] == ("fv1", "fv2") and arm.param_names[-1] == "fc7"
    np.testing.assert_allclose(arm.default_phi[70:77], 0.003)  # the URDF's <dynamics damping="0.003"/>
    np.testing.assert_allclose(arm.default_phi[0], 4.970684)  # panda_link1's mass in the URDF
    assert arm.default_phi[60] > 0.5  # link 7 holds the locked hand and fingers


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_every_example_robot_loads_and_satisfies_the_regressor_identity(name):
    arm = PinocchioArm.example(name)
    q, dq, _, a = states(arm.n, 5)
    data = arm.pin_model.createData()
    config = pin.integrate(arm.pin_model, pin.neutral(arm.pin_model), q)  # (cos, sin) for continuous joints
    close(arm.regressor(q, dq, dq, a) @ arm.default_phi, pin.rnea(arm.pin_model, data, config, dq, a))


def test_pickled_model_computes_the_same():
    arm = PinocchioArm.example("panda")
    q, dq, v, a = states(7, 2)
    arm.forward_dynamics(q, dq, v, arm.default_phi)  # fills the per-instance caches
    copy = pickle.loads(pickle.dumps(arm))
    np.testing.assert_array_equal(copy.regressor(q, dq, v, a), arm.regressor(q, dq, v, a))
    np.testing.assert_array_equal(copy.forward_dynamics(q, dq, v, arm.default_phi),
                                  arm.forward_dynamics(q, dq, v, arm.default_phi))


@pytest.mark.parametrize(("call", "field"), [
    (lambda tmp: PinocchioArm.from_urdf(tmp / "missing.urdf"), "robot.path"),
    (lambda tmp: PinocchioArm.example("pr2d2"), "robot.name"),
    (lambda tmp: PinocchioArm.example("panda", locked_joints=["panda_joint8"]), "robot.locked_joints"),
    (lambda tmp: PinocchioArm.example("panda", locked_joints="panda_joint7"), "robot.locked_joints"),
    (lambda tmp: PinocchioArm.example("panda", viscous=1), "robot.viscous"),
    (lambda tmp: PinocchioArm.example("panda", gravity=[0, 9.81]), "robot.gravity"),
    (lambda tmp: PinocchioArm(pin.buildModelFromUrdf(str(_write(tmp, "planar")))), "robot.locked_joints"),
    (lambda tmp: PinocchioArm.from_urdf(_text(tmp, "robot:\n  name: yaml")), "robot.path"),
    (lambda tmp: PinocchioArm.from_urdf(_text(tmp, "<sdf version='1.6'/>")), "robot.path"),
    (lambda tmp: PinocchioArm.from_urdf(_text(tmp, "<robot name='r'><link name='base'/></robot>")), "robot.path"),
    (lambda tmp: PinocchioArm.from_urdf(3.0), "robot.path"),
])
def test_bad_input_names_the_field(tmp_path, call, field):
    with pytest.raises(ConfigError) as info:
        call(tmp_path)
    assert info.value.field == field


def _text(tmp, text: str):
    path = tmp / "file.urdf"
    path.write_text(text)
    return path


def _write(tmp, joint_type: str):
    path = tmp / "odd.urdf"
    text = PLANAR_URDF.format(l1=1, l2=1, m1=1, m2=1).replace('type="continuous"', f'type="{joint_type}"')
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------------------------------------------------
# Scenarios


def test_panda_slotine_li_converges_fast_version():
    from robotadapt.studies.scenarios import load

    res = load("panda-slotine-li", ["simulation.t_final=5"]).run()
    assert res.ok
    assert np.all(np.abs(res.e[-1]) < 1e-3)
    assert np.max(np.abs(res.e[res.t > 1.0])) < 1e-3
    assert np.max(np.diff(res.V)) <= 1e-9 * res.V[0]  # (6.3.17): V never increases


@pytest.mark.slow
def test_panda_slotine_li_converges():
    from robotadapt.studies.scenarios import load

    res = load("panda-slotine-li").run()
    assert res.ok and res.t[-1] == pytest.approx(20.0)
    assert np.all(np.abs(res.e[-1]) < 1e-3)
    late, early = np.abs(res.e[res.t > 15.0]).max(), np.abs(res.e[res.t < 5.0]).max()
    assert late < 0.2 * early


@pytest.mark.parametrize("name", ["panda-composite", "ur5-dcal"])
def test_other_arm_scenarios_run(name):
    from robotadapt.studies.scenarios import load

    res = load(name, ["simulation.t_final=0.5"]).run()
    assert res.ok
    assert np.max(np.abs(res.e)) < 1e-2
    assert np.max(np.diff(res.V)) <= 1e-9 * res.V[0]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["panda-composite", "ur5-dcal"])
def test_other_arm_scenarios_converge(name):
    from robotadapt.studies.scenarios import load

    res = load(name).run()
    assert res.ok
    assert np.all(np.abs(res.e[-1]) < 1e-3)
