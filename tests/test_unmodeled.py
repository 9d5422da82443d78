"""Dynamics the controller's model lacks (`robotadapt.plant.unmodeled`, `robotadapt.plant.actuators.DCMotor`, a different
plant model): the payload's parameter change against an independent parallel-axis computation, a payload step and the
re-adapting estimate, elastic joints (energy, equilibrium, stiff vs soft), DC motors (stall current, back-EMF damping,
voltage limit, rotor inertia) and friction the model lacks."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.arrays import matvec
from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.plant.actuators import DCMotor
from robotadapt.plant.unmodeled import ElasticJoint, Payload
from robotadapt.robots import OneLinkArm, PolarArm, TwoLinkArm
from robotadapt.robots.symbolic import SymbolicArm
from robotadapt.sim import RK4, simulate
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid
from robotadapt.validation import ConfigError

ARM = TwoLinkArm()
PHI = np.array([0.8, 2.3])


# -- payload -----------------------------------------------------------------------------------------------------------

def test_a_payload_adds_to_the_point_mass_of_the_last_link():
    np.testing.assert_array_equal(Payload(1.5).change(ARM), [0.0, 1.5])
    np.testing.assert_array_equal(Payload(1.5).change(TwoLinkArm(friction_terms=True)), [0.0, 1.5, 0.0, 0.0])
    np.testing.assert_array_equal(Payload(0.5).change(PolarArm()), [0.5])
    np.testing.assert_array_equal(Payload(0.5).change(OneLinkArm()), [0.5, 0.0])
    with pytest.raises(ConfigError) as info:
        Payload(1.0, offset=[0.1, 0.0, 0.0]).change(ARM)
    assert info.value.field == "plant.payload_offset"


def _arm(last_mass: float, last_com: list[float]) -> SymbolicArm:
    """A 2-link planar DH arm whose last link is a point mass `last_mass` at `last_com` (its own frame)."""
    return SymbolicArm("RR", [1.0, 0.8], 0.0, 0.0, 0.0, [1.0, last_mass], [[-0.5, 0.0, 0.0], last_com],
                       np.zeros((2, 3, 3)), g=(0.0, -9.8, 0.0))


def test_a_payload_at_an_offset_moves_the_last_links_standard_parameters_by_the_parallel_axis_theorem():
    """Δφ of a point mass m at p equals the difference of the standard parameters (computed by `default_phi` from a
    centre of mass and an inertia about it) of the arm with and without that mass on its last link."""
    p = [0.3, -0.2, 0.1]
    empty, loaded = _arm(0.0, [0.0, 0.0, 0.0]), _arm(2.0, p)
    np.testing.assert_allclose(Payload(2.0, offset=p).change(empty), loaded.default_phi - empty.default_phi,
                               rtol=0, atol=1e-15)


def test_a_payload_from_the_start_is_a_plant_with_the_loaded_parameters_bit_for_bit():
    ctrl = InertiaRelated(ARM, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    loaded = simulate(Plant(ARM, PHI, payload=Payload(1.0)), ctrl, sinusoid(2), t_final=0.3)
    plain = simulate(Plant(ARM, PHI + [0.0, 1.0]), ctrl, sinusoid(2), t_final=0.3)
    for name in ("q", "dq", "x", "tau", "V"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(plain, name))
    np.testing.assert_array_equal(loaded.phi, [0.8, 3.3])


def test_a_payload_step_changes_the_truth_at_its_time_and_the_estimate_re_adapts():
    """payload-change, cut to 10 s: φ̂ has converged to (0.8, 2.3) before the 1 kg payload at t = 5 s and to
    (0.8, 3.3) five seconds after; the truth's history steps at 5 s; V (6.3.7), evaluated with the truth of each
    instant, jumps at the step by ½ Δm2²/γ = 1/40 (the estimate is suddenly 1 kg off; r ≈ 0 there) and otherwise never
    increases beyond round-off."""
    res = load("payload-change", ["simulation.t_final=10"]).run()
    assert res.ok
    before = np.searchsorted(res.t, 5.0) - 1
    np.testing.assert_allclose(res.phi_hat[before], [0.8, 2.3], atol=1e-3)
    np.testing.assert_allclose(res.phi_hat[-1], [0.8, 3.3], atol=1e-3)
    np.testing.assert_array_equal(res.phi, [0.8, 3.3])
    truth = res.monitors["phi_true"]
    np.testing.assert_array_equal(truth[res.t < 5.0], np.broadcast_to(PHI, truth[res.t < 5.0].shape))
    np.testing.assert_array_equal(truth[res.t >= 5.0], np.broadcast_to([0.8, 3.3], truth[res.t >= 5.0].shape))
    dV = np.diff(res.V)
    jump = np.argmax(dV)
    assert res.t[jump + 1] == 5.0 and dV[jump] == pytest.approx(1 / 40, rel=1e-3)
    assert np.delete(dV, jump).max() < 1e-6 * res.V[0]
    assert res.info["plant"]["payload"] == {"mass": 1.0, "offset": [0.0, 0.0, 0.0], "time": 5.0,
                                            "phi_loaded": [0.8, 3.3]}


# -- elastic joints ---------------------------------------------------------------------------------------------------

def _rk4(f, s: np.ndarray, h: float, steps: int) -> np.ndarray:
    out = [s]
    for _ in range(steps):
        k1 = f(s)
        k2 = f(s + 0.5 * h * k1)
        k3 = f(s + 0.5 * h * k2)
        k4 = f(s + h * k3)
        s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(s)
    return np.array(out)


def test_an_undamped_elastic_arm_conserves_its_energy():
    """With D = 0, τ = 0: ½ q̇ᵀM(q)q̇ + U(q) + ½ Σ J θ̇² + ½ Σ K (θ − q)² is constant (U the gravity potential of
    the point masses, spec §1.3), to RK4's error."""
    joint = ElasticJoint(2, J=[0.2, 0.1], K=[400.0, 300.0])
    plant = Plant(ARM, PHI, elastic_joint=joint)
    s = _rk4(lambda s: plant.derivative(0.0, s, np.zeros(2)), np.array([0.3, -0.4, 0.0, 0.0, 0.5, -0.6, 1.0, 0.0]),
             1e-4, 20000)
    q, dq, theta, dtheta = s[:, :2], s[:, 2:4], s[:, 4:6], s[:, 6:]
    m1, m2 = PHI
    U = (m1 + m2) * 9.8 * np.sin(q[:, 0]) + m2 * 9.8 * np.sin(q[:, 0] + q[:, 1])
    E = (0.5 * (dq * matvec(ARM.mass_matrix(q, PHI), dq)).sum(-1) + U + 0.5 * (joint.J * dtheta**2).sum(-1)
         + 0.5 * (joint.K * (theta - q) ** 2).sum(-1))
    assert np.ptp(E) < 1e-8 * np.abs(E).max()
    assert np.ptp(theta - q) > 1e-2  # the springs did work


def test_an_elastic_arm_starts_at_rest_with_its_springs_holding_gravity():
    plant = Plant(ARM, PHI, elastic_joint=ElasticJoint(2, J=0.1, K=1000.0, D=2.0))
    q0 = np.array([0.4, -0.3])
    s0 = plant.initial_state(q0, np.zeros(2))
    G = ARM.gravity(q0, PHI)
    np.testing.assert_allclose(s0[4:6], q0 + G / 1000.0)
    ds = plant.derivative(0.0, s0, G)  # the motors hold the springs' torque: everything at rest
    np.testing.assert_allclose(ds, 0.0, atol=1e-12)


def test_slotine_li_survives_a_stiff_joint_and_diverges_on_a_soft_one():
    """Example 6.3.1's controller (rigid model) on elastic joints: K = 1e4 N m/rad, J = 0.05 kg m² (resonance
    ≈ 450 rad/s, far above the loop's bandwidth) tracks as on the rigid arm; K = 2000, J = 0.1, D = 1 (≈ 140 rad/s,
    lightly damped) is excited by the initial torque peak and diverges within a second."""
    stiff = load("example-6.3.1", ["plant.elastic_joint={J=0.05, K=1e4, D=5.0}", "simulation.t_final=2"]).run()
    rigid = load("example-6.3.1", ["simulation.t_final=2"]).run()
    assert stiff.ok and np.abs(stiff.e - rigid.e).max() < 0.02  # 0.013: J is inertia the model lacks
    assert set(stiff.monitors) >= {"motor_angle", "motor_velocity"}
    soft = load("example-6.3.1", ["plant.elastic_joint={J=0.1, K=2000.0, D=1.0}", "simulation.t_final=2"]).run()
    assert soft.status.startswith("diverged at t=0.")


# -- DC motors --------------------------------------------------------------------------------------------------------

MOTOR = dict(R=1.2, L=2e-3, k_t=0.08, k_b=0.08, gear_ratio=60.0)


@pytest.mark.parametrize("gain", [0.0, 25.0])
def test_at_stall_the_current_settles_where_the_joint_torque_is_the_command(gain):
    motor = DCMotor(2, **MOTOR, current_gain=gain)
    u = np.array([3.0, -1.5])
    i_ref = u / (60.0 * 0.08)
    np.testing.assert_allclose(motor.current_rate(u, i_ref, np.zeros(2)), 0.0, atol=1e-12)
    np.testing.assert_allclose(motor.torque(i_ref), u)


def test_back_emf_is_a_damping_the_model_lacks():
    """Steady state at joint speed ω with K_c = 0: di/dt = 0 gives τ_joint = u − N² k_t k_b ω / R."""
    motor = DCMotor(1, **MOTOR)
    u, w = np.array([2.0]), np.array([0.7])
    i = (1.2 * u / (60 * 0.08) - 0.08 * 60 * w) / 1.2
    np.testing.assert_allclose(motor.current_rate(u, i, w), 0.0, atol=1e-12)
    np.testing.assert_allclose(motor.torque(i), u - 60**2 * 0.08 * 0.08 * w / 1.2)


def test_the_voltage_limit_caps_the_drive():
    motor = DCMotor(1, **MOTOR, current_gain=50.0, voltage_limit=24.0)
    rate = motor.current_rate(np.array([1e3]), np.array([0.0]), np.array([0.0]))
    np.testing.assert_allclose(rate, 24.0 / 2e-3)


def test_a_rigidly_geared_rotor_adds_its_reflected_inertia():
    motor = DCMotor(2, **MOTOR, rotor_inertia=[2e-4, 1e-4])
    plant = Plant(ARM, PHI, motor=motor)
    q, dq, i = np.array([0.3, 0.5]), np.array([0.2, -0.1]), np.array([1.0, 0.4])
    ds = plant.derivative(0.0, np.concatenate([q, dq, i]), np.zeros(2))
    M = ARM.mass_matrix(q, PHI) + np.diag(60.0**2 * np.array([2e-4, 1e-4]))
    bias = ARM.inverse_dynamics(q, dq, np.zeros(2), PHI)
    np.testing.assert_allclose(ds[2:4], np.linalg.solve(M, 60 * 0.08 * i - bias), rtol=1e-12)


def test_a_fast_current_loop_needs_a_short_enough_step():
    with pytest.raises(ConfigError) as info:
        load("example-6.3.1", ["plant.motor={R=1.0, L=1e-3, k_t=0.1, k_b=0.1, gear_ratio=50, current_gain=20}"]).run()
    assert info.value.field == "simulation.dt" and "dt ≤ 0.000119 s" in str(info.value)  # 2.5 L/(R + K_c)


def test_example_6_3_1_through_voltage_driven_motors_tracks_with_wrong_estimates():
    """Back-EMF damping (N² k_t k_b / R = 25 N m s/rad per joint) the model lacks: the error stays small, the estimate
    absorbs the damping and leaves the true masses."""
    res = load("example-6.3.1", ["plant.motor={R=1.0, L=1e-3, k_t=0.1, k_b=0.1, gear_ratio=50}",
                                 "simulation.t_final=4"]).run()
    assert res.ok and np.abs(res.e[-1]).max() < 0.1
    assert np.linalg.norm(res.phi_hat[-1] - PHI) > 1.0
    assert res.info["plant"]["motor"]["gear_ratio"] == [50.0, 50.0] and "current" in res.monitors


# -- a different true model --------------------------------------------------------------------------------------------

def test_friction_the_model_lacks_leaves_the_truth_outside_the_controllers_parameterization():
    res = load("example-6.3.1", ["plant.robot={kind='two_link', friction_terms=true}", "plant.phi=[0.8, 2.3, 1, 1]",
                                 "simulation.t_final=1"]).run()
    assert res.ok and res.phi is None and res.V is None and res.passivity is None
    assert res.info["plant"]["model"] == {"class": "TwoLinkArm", "param_names": ["m1", "m2", "fv1", "fv2"],
                                          "phi": [0.8, 2.3, 1.0, 1.0]}
    assert "plant" not in load("example-6.3.1", ["simulation.t_final=0.01"]).run().info


@pytest.mark.parametrize(("sets", "field"), [
    (["plant.robot={kind='one_link'}", "plant.phi=[1, 1]"], "plant.robot"),
    (["plant.robot={kind='two_link', l1=-1}"], "plant.robot.l1"),
    (["plant.robot={kind='two_link', friction_terms=true}"], "plant.phi"),
    (["plant.payload_time=5"], "plant.payload"),
    (["plant.payload=-1"], "plant.payload"),
    (["plant.elastic_joint={J=0.1}"], "plant.elastic_joint.K"),
    (["plant.elastic_joint={J=0.1, K=100, C=1}"], "plant.elastic_joint.C"),
    (["plant.motor=3"], "plant.motor"),
    (["plant.motor={R=1, L=1e-3, k_t=0.1, k_b=-0.1}"], "plant.motor.k_b"),
])
def test_scenario_keys_of_unmodeled_dynamics_are_checked(sets, field):
    with pytest.raises(ConfigError) as info:
        load("example-6.3.1", sets)
    assert info.value.field == field


def test_continuous_runs_with_extra_plant_states_keep_their_layout():
    """x is still the controller's state: the plant's θ, θ̇ sit between q̇ and x in z, and the result splits them."""
    ctrl = InertiaRelated(ARM, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    res = simulate(Plant(ARM, PHI, elastic_joint=ElasticJoint(2, J=0.05, K=1e4, D=5.0)), ctrl, sinusoid(2),
                   t_final=0.2, integrator=RK4(1e-3))
    assert res.x.shape == (201, 2) and res.monitors["motor_angle"].shape == (201, 2)
    np.testing.assert_array_equal(res.phi_hat, res.x)


def test_a_urdf_truth_with_the_friction_its_controller_model_lacks():
    """An n-DOF truth from a URDF: the Panda with its URDF's joint damping (0.003 N m s/rad) under a Slotine–Li
    controller whose model has no friction columns; the truth is outside the controller's parameterization."""
    pytest.importorskip("pinocchio")
    res = load("panda-slotine-li", ["plant.robot={kind='example_robot', name='panda', viscous=true}",
                                    "simulation.t_final=0.05"]).run()
    assert res.ok and res.phi is None
    model = res.info["plant"]["model"]
    assert model["class"] == "KinematicTree" and model["param_names"][-7:] == [f"fv{i}" for i in range(1, 8)]
    np.testing.assert_array_equal(model["phi"][-7:], 0.003)
