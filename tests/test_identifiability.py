"""Base parameters (robots/identifiability.py): counts known from the theory, Y = Y_b K on fresh states, readable names
that reproduce K, and a model in base parameters that any controller can adapt.

Known counts: the two-link arm's two masses are identifiable; a planar chain of n revolute joints has 3n base parameters
with gravity in its plane (Izz, mx, my per link, grouped) and 3n − 2 without (the first link's mx, my never act); a
serial chain of n revolute joints in general position whose first axis is vertical has 7(n − 1) + 1 (Gautier & Khalil
1990: 7 per link, Izz alone for the first; special geometry can only lower it), which the Panda (7R, 43) and the UR5
(6R, 36) reach; the PUMA 560 has 36.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from robotadapt.robots import TwoLinkArm
from robotadapt.robots.identifiability import BaseParameterModel, base_parameters
from robotadapt.validation import ConfigError

pin = pytest.importorskip("pinocchio")
from robotadapt.robots.pinocchio import PinocchioArm  # noqa: E402


def chain(n: int, gravity, general: bool, seed: int = 0) -> PinocchioArm:
    """n revolute joints with random inertias: planar (axes z, links 0.5 m along x) or in general position."""
    rng = np.random.default_rng(seed)
    model = pin.Model()
    model.gravity = pin.Motion(np.array(gravity, dtype=float), np.zeros(3))
    parent = 0
    for j in range(n):
        rotation = pin.exp3(rng.normal(size=3)) if general and j else np.eye(3)
        offset = rng.normal(size=3) if general and j else np.array([0.5 * (j > 0), 0.0, 0.0])
        parent = model.addJoint(parent, pin.JointModelRZ(), pin.SE3(rotation, offset), f"joint{j + 1}")
        model.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
    return PinocchioArm(model)


def fresh_states(model, count: int = 20, seed: int = 99):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-np.pi, np.pi, (count, model.n))
    return (q,) + tuple(rng.normal(size=(3, count, model.n)))


def assert_factorizes(basis, seed: int = 99):
    """Y = Y_b K on states the analysis never saw (Y less its friction part Y(q, q̇, 0, 0) − Y(q, 0, 0, 0) when the
    analysis left friction out)."""
    q, dq, v, a = fresh_states(basis.model, seed=seed)
    Y = basis.model.regressor(q, dq, v, a)
    if not basis.friction:
        Y = Y - basis.model.regressor(q, dq, 0 * v, 0 * a) + basis.model.regressor(q, 0 * dq, 0 * v, 0 * a)
    Yb = Y[..., list(basis.independent)]
    assert np.abs(Y - Yb @ basis.K).max() <= 1e-9 * np.abs(Y).max()


def test_two_link_arm_masses_are_both_identifiable():
    basis = base_parameters(TwoLinkArm())
    assert basis.count == 2 and basis.names == ("m1", "m2")
    np.testing.assert_array_equal(basis.K, np.eye(2))
    rigid = base_parameters(TwoLinkArm(friction_terms=True), friction=False)
    assert rigid.names == ("m1", "m2")
    np.testing.assert_array_equal(rigid.K[:, 2:], 0.0)  # the friction parameters are left out
    assert base_parameters(TwoLinkArm(friction_terms=True)).count == 4


@pytest.mark.parametrize("n", [2, 3, 4])
def test_planar_chain_counts(n):
    in_plane = base_parameters(chain(n, [0.0, -9.81, 0.0], general=False))
    assert in_plane.count == 3 * n
    assert base_parameters(chain(n, [0.0, 0.0, 0.0], general=False)).count == 3 * n - 2
    assert base_parameters(chain(n, [0.0, 0.0, -9.81], general=False)).count == 3 * n - 2  # gravity along the axes
    assert_factorizes(in_plane)


def test_planar_chain_groups_like_the_textbook():
    """Each link's Izz and mx absorb the masses beyond it (links 0.5 m long): Izz1 + 0.25·(m2 + m3), mx1 + 0.5·(m2 + m3)."""
    names = base_parameters(chain(3, [0.0, -9.81, 0.0], general=False)).names
    assert names == ("mx1 + 0.5·m2 + 0.5·m3", "my1", "Izz1 + 0.25·m2 + 0.25·m3", "mx2 + 0.5·m3", "my2",
                     "Izz2 + 0.25·m3", "mx3", "my3", "Izz3")


@pytest.mark.parametrize("n", [3, 5])
def test_general_serial_chain_count(n):
    basis = base_parameters(chain(n, [0.0, 0.0, -9.81], general=True, seed=n))
    assert basis.count == 7 * (n - 1) + 1
    assert basis.margin[0] > 1e-3 > 1e-12 > basis.margin[1]
    assert_factorizes(basis)


def test_panda_and_ur5():
    panda = PinocchioArm.example("panda", viscous=True, coulomb=True)
    full, rigid = base_parameters(panda), base_parameters(panda, friction=False)
    assert (full.count, rigid.count) == (43 + 14, 43)
    assert full.margin[0] > 0.1 and full.margin[1] < 1e-12 and full.residual < 1e-12
    assert_factorizes(full)
    assert_factorizes(rigid)
    np.testing.assert_array_equal(rigid.K[:, 70:], 0.0)
    ur5 = base_parameters(PinocchioArm.example("ur5"))
    assert ur5.count == 36
    assert_factorizes(ur5)


def test_count_does_not_depend_on_the_draw():
    arm = PinocchioArm.example("ur5")
    for seed, samples in [(1, 20), (2, 60)]:
        basis = base_parameters(arm, rng=np.random.default_rng(seed), samples=samples)
        assert basis.count == 36 and basis.residual < 1e-12


def parse(name: str, names: tuple[str, ...]) -> np.ndarray:
    """The row of K that a readable name states."""
    row = np.zeros(len(names))
    for sign, coef, param in re.findall(r"(^|[+−] )(?:([0-9.e+-]+)·)?(\w+)", name):
        row[names.index(param)] = (-1.0 if sign.startswith("−") else 1.0) * (float(coef) if coef else 1.0)
    return row


def test_names_state_the_combinations():
    arm = PinocchioArm.example("panda")
    basis = base_parameters(arm)
    assert basis.names[:2] == ("Izz1 + Iyy2", "mx2")  # joint 1 is vertical: its link shows only Izz1, with Iyy2
    for name, row, own in zip(basis.names, basis.K, basis.independent, strict=True):
        assert name.split(" ")[0] == arm.param_names[own]
        np.testing.assert_allclose(parse(name, arm.param_names), row, rtol=1e-3, atol=1e-12)


def test_model_in_base_parameters_has_the_same_dynamics():
    arm = PinocchioArm.example("panda", viscous=True)
    basis = base_parameters(arm)
    model = BaseParameterModel(basis)
    rng = np.random.default_rng(4)
    phi = arm.default_phi * rng.uniform(0.5, 1.5, arm.p)
    phi_b = basis.base(phi)
    np.testing.assert_allclose(basis.base(basis.standard(phi_b)), phi_b, rtol=1e-14)
    assert model.n == 7 and model.p == 50 and model.param_names == basis.names
    np.testing.assert_allclose(model.default_phi, basis.K @ arm.default_phi)
    q, dq, v, a = fresh_states(arm, 4)
    for ours, theirs in [(model.regressor(q, dq, v, a) @ phi_b, arm.regressor(q, dq, v, a) @ phi),
                         (model.mass_matrix(q, phi_b), arm.mass_matrix(q, phi)),
                         (model.coriolis_matrix(q, dq, phi_b), arm.coriolis_matrix(q, dq, phi)),
                         (model.gravity(q, phi_b), arm.gravity(q, phi)),
                         (model.friction(dq, phi_b), arm.friction(dq, phi)),
                         (model.momentum_regressor(q, dq) @ phi_b, arm.momentum_regressor(q, dq) @ phi),
                         (model.remainder_regressor(q, dq) @ phi_b, arm.remainder_regressor(q, dq) @ phi),
                         (model.forward_dynamics(q, dq, v, phi_b), arm.forward_dynamics(q, dq, v, phi))]:
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9 * np.abs(theirs).max())


def test_slotine_li_in_base_parameters_at_one_instant():
    """With φ̂_b = K φ and zero tracking error the torque is the inverse dynamics of the desired motion and the update
    vanishes (Table 6.3.1)."""
    from robotadapt.controllers import InertiaRelated
    from robotadapt.trajectories import Reference

    arm = PinocchioArm.example("ur5")
    model = BaseParameterModel(base_parameters(arm))
    ctrl = InertiaRelated(model, Lam=5.0, Kv=10.0, Gamma=1.0, phi_hat0=model.default_phi)
    q, dq, _, a = fresh_states(arm, 1)
    tau, dx = ctrl(0.0, model.default_phi, q[0], dq[0], Reference(q[0], dq[0], a[0]))
    np.testing.assert_allclose(tau, arm.inverse_dynamics(q[0], dq[0], a[0], arm.default_phi), rtol=1e-10)
    np.testing.assert_array_equal(dx, 0.0)


def test_puma560_has_36_base_parameters():
    symbolic = pytest.importorskip("robotadapt.robots.symbolic")
    assert base_parameters(symbolic.puma560(), friction=False).count == 36


@pytest.mark.parametrize(("kwargs", "field"), [({"samples": 2}, "samples"), ({"samples": 10.5}, "samples"),
                                               ({"tol": 0.0}, "tol"), ({"friction": "no"}, "friction")])
def test_bad_arguments_name_the_field(kwargs, field):
    with pytest.raises(ConfigError) as info:
        base_parameters(PinocchioArm.example("ur5"), **kwargs)
    assert info.value.field == field
