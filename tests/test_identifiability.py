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


# --- issue 16, item 4: a run's metrics and summary in base parameters -------------------------------------------------

PLANAR3 = ["robot={kind='planar', n_links=3}", "plant={q0=[0.0, 0.0, 0.0], dq0=[0.0, 0.0, 0.0]}",
           "controller.phi_hat0={scale=0.7}", "simulation.t_final=0.2", "simulation.backend='numpy'"]


def independent_rank(model, count: int = 40, seed: int = 7) -> int:
    """The rank of Y stacked over random states, by numpy alone (not base_parameters)."""
    q, dq, v, a = fresh_states(model, count, seed)
    Y = model.regressor(q, dq, v, a).reshape(-1, model.p)
    return int(np.linalg.matrix_rank(Y / np.linalg.norm(Y, axis=0).clip(1e-300), tol=1e-8 * np.sqrt(Y.shape[0])))


def test_three_link_planar_run_metrics_and_summary_speak_of_base_parameters():
    from robotadapt.analysis.metrics import metrics
    from robotadapt.cli.common import summary
    from robotadapt.studies.scenarios import load

    scenario = load("example-6.3.1", PLANAR3)
    model = scenario.setup.controller.model
    res = scenario.run()
    m = metrics(res, model)
    for key in ("final_abs_error", "rms_error", "max_abs_torque", "final_phi_hat", "status", "final_phi_error"):
        assert key in m
    rank = independent_rank(model)
    assert model.p == 30 and rank == 9
    assert m["base_parameters"] == rank and len(m["base_param_names"]) == rank
    assert m["unidentifiable_directions"] == model.p - rank == 21
    basis = base_parameters(model)
    err = basis.K @ (res.phi - res.phi_hat[-1])
    assert m["final_base_phi_error"] == pytest.approx(np.linalg.norm(err), rel=1e-12)
    assert m["final_base_phi_error_relative"] == pytest.approx(np.linalg.norm(err) / np.linalg.norm(basis.K @ res.phi))
    line = summary("planar3", m)
    assert "21 of 30 directions unidentifiable" in line and "‖K(φ − φ̂)‖/‖Kφ‖" in line and "9 base parameters" in line
    plain = metrics(res)  # without the model: the standard keys alone, unchanged
    assert "unidentifiable_directions" not in plain and plain["final_phi_error"] == m["final_phi_error"]


def test_the_book_arms_get_no_base_keys_and_are_not_sampled():
    from robotadapt.analysis.metrics import base_of, metrics
    from robotadapt.studies.scenarios import load

    scenario = load("example-6.3.1", ["simulation.t_final=0.05"])
    model = scenario.setup.controller.model
    assert base_of(model) is None  # p = n = 2: skipped without sampling
    m = metrics(scenario.run(), model)
    assert "unidentifiable_directions" not in m and "base_parameters" not in m


def test_base_parameters_are_computed_once_per_model(monkeypatch):
    from robotadapt.analysis import metrics as metrics_module
    from robotadapt.robots import identifiability

    model = chain(3, [0.0, 0.0, -9.81], general=False, seed=3)
    calls = []
    real = identifiability.base_parameters
    monkeypatch.setattr(identifiability, "base_parameters", lambda m, *a, **k: calls.append(m) or real(m, *a, **k))
    first = metrics_module.base_of(model)
    assert first is not None and metrics_module.base_of(model) is first and len(calls) == 1


def test_robotadapt_run_reports_base_parameters(tmp_path, capsys):
    """`robotadapt run` on a 3-link planar arm: metrics.json and the summary line speak of the 9 base parameters and the
    21 directions the dynamics cannot see (counted here by an independent rank)."""
    import json

    from robotadapt.cli import main
    from robotadapt.studies.scenarios import load

    args = [a for o in PLANAR3 for a in ("--set", o)]
    assert main(["run", "example-6.3.1", *args, "--no-plots", "--out", str(tmp_path)]) == 0
    model = load("example-6.3.1", PLANAR3).setup.controller.model
    rank = independent_rank(model)
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["base_parameters"] == rank and m["unidentifiable_directions"] == model.p - rank
    assert f"{model.p - rank} of {model.p} directions unidentifiable" in capsys.readouterr().out
