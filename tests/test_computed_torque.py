"""Adaptive computed torque (Table 6.2.1; spec §2.2–§2.3): one instant, the Lyapunov pair, dV/dt along the closed
loop, the projection, the stop when M̂ loses definiteness, and the scenarios of Example 6.2.2 and Problems 6.2-1, 6.2-2.

Expected values are written out here from the spec: the two-link closed forms of spec §1.3 (shared with
test_controllers), M̂⁻¹ and the per-joint update laws (5)–(6) of Example 6.2.2, the book's P and the corrected Q, and the
Problem 6.2-2 family (spec §2.3).
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import re

import numpy as np
import pytest

from robotadapt.analysis.metrics import lyapunov_increase
from robotadapt.cli import main
from robotadapt.controllers.computed_torque import AdaptiveComputedTorque
from robotadapt.robots import PolarArm
from robotadapt.sim import simulate
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import Reference
from robotadapt.validation import ConfigError
from test_controllers import BOOK, OTHER, random_instant, spec_G, spec_inverse_dynamics, spec_M, spec_Vm, spec_Y

KP, KV, GAMMA = 125.0, 50.0, 500.0  # Example 6.2.2 (spec §2.3)
BOX = ["controller.phi_min=0.1", "controller.phi_max=10"]  # the projection box spec §2.3 recommends
SEEDS = range(6)
ARMS = [pytest.param(BOOK, id="book-arm"), pytest.param(OTHER, id="other-arm")]
# Independent reference for Example 6.2.2 as the book ran it (no projection): the ODE of spec §1.3/§2.3 written out by
# hand and integrated with solve_ivp (DOP853, rtol 1e-12, atol 1e-14) with an event on det M̂ = 0 reaches it at
# t = 2.27904e-05 s, with m̂1 → 0 from 0.85 at an initial rate of −3.74e4 /s.
SINGULAR_AT = 2.27904e-05


def book_controller(arm=BOOK, phi_hat0=(0.85, 2.2), **kw):
    return AdaptiveComputedTorque(arm, **{"Kp": KP, "Kv": KV, "Gamma": GAMMA, "phi_hat0": np.array(phi_hat0), **kw})


def random_spd(rng, n, scale=1.0):
    B = rng.uniform(-1, 1, (n, n))
    return scale * (B @ B.T + n * np.eye(n))


def stop_time(status: str) -> float:
    match = re.match(r"diverged within the step from (\S+) to \S+ s: ", status)
    assert match, status
    return float(match.group(1))


# --------------------------------------------------------------------------------------------------------------------
# One instant


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_exact_estimate_and_zero_error_gives_inverse_dynamics_and_no_update(arm, seed):
    phi, _, _, ref = random_instant(np.random.default_rng(seed))
    ctrl = book_controller(arm, phi)
    q, dq = ref.q_des.copy(), ref.dq_des.copy()
    tau = ctrl.torque(0.3, phi, q, dq, ref)
    np.testing.assert_allclose(tau, spec_inverse_dynamics(arm, q, dq, ref.ddq_des, phi), rtol=1e-12, atol=1e-12)
    ddq = arm.forward_dynamics(q, dq, tau, phi)  # the plant follows the desired acceleration ...
    np.testing.assert_allclose(ddq, ref.ddq_des, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(ctrl.update(0.3, phi, q, dq, ddq, ref), np.zeros(2))  # ... and E1 = 0: no update


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_torque_and_update_written_per_joint(arm, seed):
    """Example 6.2.2 written out (spec §2.3): τ of (6.2.5), s = E1 = ½ e + ė, and the update laws (5)–(6)
    dm̂1/dt = γ1 [(W11 MI11 + W21 MI21) s1 + (W11 MI12 + W21 MI22) s2], dm̂2/dt likewise with W12, W22."""
    rng = np.random.default_rng(seed)
    _, q, dq, ref = random_instant(rng)
    m1, m2 = phi_hat = rng.uniform(0.3, 3.0, 2)
    ddq = rng.uniform(-5, 5, 2)
    ctrl = book_controller(arm, phi_hat)
    e, de = ref.q_des - q, ref.dq_des - dq
    u = ref.ddq_des + KV * de + KP * e
    tau = spec_M(arm, q, phi_hat) @ u + spec_Vm(arm, q, dq, phi_hat) @ dq + spec_G(arm, q, phi_hat)
    np.testing.assert_allclose(ctrl.torque(0.0, phi_hat, q, dq, ref), tau, rtol=1e-12, atol=1e-9)

    l1, l2, c2, s2 = arm.l1, arm.l2, np.cos(q[1]), np.sin(q[1])
    det = m2 * l1**2 * l2**2 * (m1 + m2 * s2**2)
    MI11, MI12 = m2 * l2**2 / det, -(m2 * l2**2 + m2 * l1 * l2 * c2) / det
    MI22 = ((m1 + m2) * l1**2 + m2 * l2**2 + 2 * m2 * l1 * l2 * c2) / det
    W = spec_Y(arm, q, dq, dq, ddq)
    s = 0.5 * e + de
    expected = GAMMA * np.array([(W[0, 0] * MI11 + W[1, 0] * MI12) * s[0] + (W[0, 0] * MI12 + W[1, 0] * MI22) * s[1],
                                 (W[0, 1] * MI11 + W[1, 1] * MI12) * s[0] + (W[0, 1] * MI12 + W[1, 1] * MI22) * s[1]])
    np.testing.assert_allclose(ctrl.update(0.0, phi_hat, q, dq, ddq, ref), expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ctrl.filtered_error(0.0, phi_hat, q, dq, ref), s, rtol=1e-14, atol=1e-14)


def test_batch_equals_stacked_single_calls():
    rng, lead = np.random.default_rng(5), (3, 4)
    ctrl = AdaptiveComputedTorque(OTHER, Kp=random_spd(rng, 2, 10), Kv=random_spd(rng, 2, 5), Gamma=[20.0, 5.0],
                                  phi_hat0=[0.85, 2.2], Q=random_spd(rng, 4), phi_min=0.2, phi_max=[2.0, 2.5])
    x = rng.uniform(0.1, 3.0, lead + (2,))  # some entries outside the box, on either side
    q, dq, ddq = (rng.uniform(-2, 2, lead + (2,)) for _ in range(3))
    ref = Reference(*(rng.uniform(-2, 2, lead + (2,)) for _ in range(3)))
    t, phi = rng.uniform(0, 10, lead), np.array([0.8, 2.3])
    tau, dx = ctrl.torque(t, x, q, dq, ref), ctrl.update(t, x, q, dq, ddq, ref)
    V, E1 = ctrl.lyapunov(t, x, q, dq, ref, phi), ctrl.filtered_error(t, x, q, dq, ref)
    assert tau.shape == dx.shape == E1.shape == lead + (2,) and V.shape == lead
    for i in np.ndindex(*lead):
        ref_i = Reference(*(a[i] for a in ref))
        np.testing.assert_allclose(tau[i], ctrl.torque(t[i], x[i], q[i], dq[i], ref_i), rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(dx[i], ctrl.update(t[i], x[i], q[i], dq[i], ddq[i], ref_i), rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(E1[i], ctrl.filtered_error(t[i], x[i], q[i], dq[i], ref_i), rtol=1e-13)
        assert V[i] == pytest.approx(ctrl.lyapunov(t[i], x[i], q[i], dq[i], ref_i, phi), rel=1e-13)


# --------------------------------------------------------------------------------------------------------------------
# The Lyapunov pair (6.2.16)


def system_matrix(Kp, Kv):
    n = len(Kp)
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Kp, -Kv]])  # (6.2.10)


def test_default_pair_is_the_books_P_with_the_corrected_Q():
    """P = [[(k_p + k_v/2) I, ½ I], [½ I, I]] (Example 6.2.2) and Q = diag(k_p I, (2k_v − 1) I) (spec §2.3)."""
    P, Q = book_controller().lyapunov_pair
    eye = np.eye(2)
    np.testing.assert_array_equal(P, np.block([[(KP + KV / 2) * eye, 0.5 * eye], [0.5 * eye, eye]]))
    np.testing.assert_array_equal(Q, np.diag([KP, KP, 2 * KV - 1, 2 * KV - 1]))
    A = system_matrix(KP * eye, KV * eye)
    np.testing.assert_allclose(A.T @ P + P @ A, -Q, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_P_solves_the_lyapunov_equation_for_a_given_Q(seed):
    rng = np.random.default_rng(seed)
    Kp, Kv, Q = random_spd(rng, 2, 20), random_spd(rng, 2, 5), random_spd(rng, 4)
    ctrl = AdaptiveComputedTorque(BOOK, Kp=Kp, Kv=Kv, Gamma=1.0, phi_hat0=[1.0, 1.0], Q=Q)
    P, Q_used = ctrl.lyapunov_pair
    np.testing.assert_array_equal(Q_used, Q)
    A = system_matrix(Kp, Kv)
    np.testing.assert_allclose(A.T @ P + P @ A, -Q, rtol=0, atol=1e-10 * np.abs(Q).max())
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > 0
    # without P or Q, gains that are not multiples of I take Q = I
    P, Q_used = AdaptiveComputedTorque(BOOK, Kp=Kp, Kv=Kv, Gamma=1.0, phi_hat0=[1.0, 1.0]).lyapunov_pair
    np.testing.assert_array_equal(Q_used, np.eye(4))
    np.testing.assert_allclose(A.T @ P + P @ A, -np.eye(4), rtol=0, atol=1e-10)


@pytest.mark.parametrize(("p2", "p3"), [(0.5, 1.0), (1.0, 1.0), (3.0, 0.2)])
def test_problem_6_2_2_family(p2, p3):
    """P_i = [[p1, p2], [p2, p3]], p1 = p2 k_v + p3 k_p gives Q_i = diag(2 p2 k_p, 2 (p3 k_v − p2)) and
    E1 = p2 e + p3 ė (spec §2.3); p2 = ½, p3 = 1 is the book's pair."""
    eye = np.eye(2)
    P = np.block([[(p2 * KV + p3 * KP) * eye, p2 * eye], [p2 * eye, p3 * eye]])
    ctrl = book_controller(P=P)
    np.testing.assert_allclose(ctrl.lyapunov_pair[1], np.diag([2 * p2 * KP] * 2 + [2 * (p3 * KV - p2)] * 2), atol=1e-9)
    ref = Reference(np.array([0.3, -0.2]), np.array([1.0, 0.5]), np.zeros(2))
    E1 = ctrl.filtered_error(0.0, ctrl.phi_hat0, np.zeros(2), np.zeros(2), ref)
    np.testing.assert_allclose(E1, p2 * ref.q_des + p3 * ref.dq_des, rtol=1e-14)


def test_problem_6_2_2_scenario_uses_p2_p3_equal_one():
    ctrl = load("problem-6.2-2").setup.controller
    np.testing.assert_allclose(ctrl.lyapunov_pair[1], np.diag([2 * KP, 2 * KP, 2 * (KV - 1), 2 * (KV - 1)]), atol=1e-9)


BAD_PAIRS = [
    pytest.param({"P": np.eye(4)}, "controller.P", id="P-whose-Q-is-indefinite"),
    pytest.param({"P": np.diag([1.0, 1.0, -1.0, 1.0])}, "controller.P", id="P-indefinite"),
    pytest.param({"P": np.triu(np.ones((4, 4))) + 4 * np.eye(4)}, "controller.P", id="P-non-symmetric"),
    pytest.param({"P": np.eye(2)}, "controller.P", id="P-wrong-shape"),
    pytest.param({"P": [[1.0, np.nan, 0, 0]] * 4}, "controller.P", id="P-nan"),
    pytest.param({"P": 1e300}, "controller.P", id="P-huge"),
    pytest.param({"P": np.eye(4), "Q": np.eye(4)}, "controller.P", id="P-and-Q"),
    pytest.param({"Q": -np.eye(4)}, "controller.Q", id="Q-negative"),
    pytest.param({"Kv": 0.5}, "controller.Kv", id="book-P-needs-kv-above-half"),
    pytest.param({"phi_min": [1.0, 3.0]}, "controller.phi_hat0", id="estimate-below-the-box"),
    pytest.param({"phi_min": 1.0, "phi_max": [2.0, 0.5]}, "controller.phi_max", id="empty-box"),
    pytest.param({"phi_max": [1.0, 2.0, 3.0]}, "controller.phi_max", id="box-wrong-length"),
]


@pytest.mark.parametrize(("kw", "field"), BAD_PAIRS)
def test_bad_lyapunov_pair_or_box_names_the_field(kw, field):
    with pytest.raises(ConfigError, match=rf"^{re.escape(field)}: ") as info:
        book_controller(**kw)
    assert info.value.field == field


def test_replace_keeps_what_was_given():
    ctrl = book_controller(phi_min=0.1)
    other = dataclasses.replace(ctrl, Kv=20.0)
    np.testing.assert_array_equal(other.lyapunov_pair[1], np.diag([KP, KP, 39.0, 39.0]))
    np.testing.assert_array_equal(other.bounds[0], [0.1, 0.1])


# --------------------------------------------------------------------------------------------------------------------
# dV/dt along the closed loop at one instant (6.2.18)


def closed_loop_dVdt(ctrl, arm, phi, q, dq, x, ref, flip=False, h=1e-3):
    """dV/dt by a central difference in time. q, q̇, φ̂, q_d, q̇_d move with q̇, q̈ (the plant's acceleration for the
    controller's τ), dφ̂/dt, q̇_d, q̈_d; V is quadratic in them, so the central difference is exact up to round-off."""
    tau = ctrl.torque(0.0, x, q, dq, ref)
    ddq = arm.forward_dynamics(q, dq, tau, phi)
    dx = ctrl.update(0.0, x, q, dq, ddq, ref) * (-1.0 if flip else 1.0)

    def V(s):
        ref_s = Reference(ref.q_des + s * ref.dq_des, ref.dq_des + s * ref.ddq_des, ref.ddq_des)
        return ctrl.lyapunov(s, x + s * dx, q + s * dq, dq + s * ddq, ref_s, phi)

    return (V(h) - V(-h)) / (2 * h), dx


def instants():
    rng = np.random.default_rng(2024)
    for kind, arm in [("book-arm", BOOK), ("other-arm", OTHER), ("polar", PolarArm(friction_terms=True))]:
        for seed in range(4):
            n, p = arm.n, arm.p
            q = rng.uniform(-np.pi, np.pi, n)
            if isinstance(arm, PolarArm):
                q[1] = rng.uniform(0.3, 2.0)
            ref = Reference(q + rng.uniform(-0.5, 0.5, n), rng.uniform(-2, 2, n), rng.uniform(-3, 3, n))
            gains = {"Kp": random_spd(rng, n, 10), "Kv": random_spd(rng, n, 3), "Gamma": random_spd(rng, p, 5),
                     "Q": random_spd(rng, 2 * n)}
            yield pytest.param(arm, gains, rng.uniform(0.3, 3.0, p), q, rng.uniform(-2, 2, n),
                               rng.uniform(0.3, 3.0, p), ref, id=f"{kind}-{seed}")


def xQx(ctrl, q, dq, ref):
    x = np.concatenate([ref.q_des - q, ref.dq_des - dq])
    return x @ ctrl.lyapunov_pair[1] @ x


@pytest.mark.parametrize(("arm", "gains", "phi", "q", "dq", "phi_hat", "ref"), list(instants()))
def test_lyapunov_derivative_is_minus_xQx(arm, gains, phi, q, dq, phi_hat, ref):
    """(6.2.18) dV/dt = −xᵀ Q x for any φ̂ with M̂ positive definite; flipping the update adds 4 φ̃ᵀ Γ⁻¹ dφ̂/dt."""
    ctrl = AdaptiveComputedTorque(arm, phi_hat0=phi_hat, **gains)
    expected = -xQx(ctrl, q, dq, ref)
    dVdt, dx = closed_loop_dVdt(ctrl, arm, phi, q, dq, phi_hat, ref)
    assert dVdt == pytest.approx(expected, rel=1e-7, abs=1e-7)
    gap = 4 * (phi - phi_hat) @ np.linalg.solve(ctrl.Gamma, dx)
    assert abs(gap) > 1e-3
    flipped, _ = closed_loop_dVdt(ctrl, arm, phi, q, dq, phi_hat, ref, flip=True)
    assert flipped == pytest.approx(expected + gap, rel=1e-7, abs=1e-7)


@pytest.mark.parametrize(("arm", "gains", "phi", "q", "dq", "phi_hat", "ref"), list(instants()))
def test_projection_only_lowers_dVdt(arm, gains, phi, q, dq, phi_hat, ref):
    """With Γ diagonal and φ in the box, zeroing the components of dφ̂/dt that point out of the box at a bound gives
    dV/dt = −xᵀQx + 2 Σ_active φ̃_i (dφ̂_i/dt)/γ_i ≤ −xᵀQx (spec §2.2 "Projection")."""
    gains = {**gains, "Gamma": np.diag(np.diag(gains["Gamma"]))}
    for signs in itertools.product((1.0, -1.0), repeat=arm.p):  # φ̂ = φ ∓ 25 %, until some bound can be active
        phi_hat = phi * (1.0 - 0.25 * np.array(signs))
        free = AdaptiveComputedTorque(arm, phi_hat0=phi_hat, **gains)
        tau = free.torque(0.0, phi_hat, q, dq, ref)
        dx_free = free.update(0.0, phi_hat, q, dq, arm.forward_dynamics(q, dq, tau, phi), ref)
        lower, upper = (dx_free < 0) & (phi > phi_hat), (dx_free > 0) & (phi < phi_hat)
        if np.any(lower | upper):
            break
    # the estimate sits on a bound where its update points out of the box; the truth is inside the box
    box = {"phi_min": np.where(lower, phi_hat, np.minimum(phi, phi_hat) - 1.0),
           "phi_max": np.where(upper, phi_hat, np.maximum(phi, phi_hat) + 1.0)}
    ctrl = dataclasses.replace(free, **box)
    dVdt, dx = closed_loop_dVdt(ctrl, arm, phi, q, dq, phi_hat, ref)
    np.testing.assert_array_equal(dx, np.where(lower | upper, 0.0, dx_free))
    gap = 2 * (phi - phi_hat) @ ((dx_free - dx) / np.diag(gains["Gamma"]))
    assert gap < 0
    assert dVdt == pytest.approx(-xQx(ctrl, q, dq, ref) + gap, rel=1e-7, abs=1e-7)


# --------------------------------------------------------------------------------------------------------------------
# Closed loop: Example 6.2.2 with the projection box, and the stops without it


def converges(res, t_final: float) -> bool:
    """Table 6.2.1's claim over a short run: it reaches `t_final`, max |e| over its last 0.5 s is below 2e-3 rad on
    both joints (measured 7.5e-4 at t_final = 3 s), φ̂ stays in the box [0.1, 10], and V(t) of (6.2.11) never
    increases from one logged step to the next by more than 1e-9 V(0). V̇ = −xᵀQx < 0 (6.2.18), and with Γ diagonal
    and φ in the box the projection only lowers it; with RK4 at dt = 1e-3 the measured largest step change of V is a
    decrease (−8.6e-9 over 5 s), so 1e-9 V(0) (V(0) = 2) is a margin for round-off, not for integration error."""
    last = res.t >= t_final - 0.5 - 1e-9
    return bool(
        res.status == "ok"
        and abs(res.t[-1] - t_final) < 1e-9
        and np.all(np.abs(res.e[last]) < 2e-3)
        and np.all((res.phi_hat >= 0.1) & (res.phi_hat <= 10.0))
        and lyapunov_increase(res.V) < 1e-9
    )


class FlippedUpdate(AdaptiveComputedTorque):
    """The same controller with dφ̂/dt of the opposite sign."""

    def update(self, t, x, q, dq, ddq, ref):
        return -super().update(t, x, q, dq, ddq, ref)


@pytest.fixture(scope="module")
def projected_book_setup():
    return load("example-6.2.2", ["simulation.t_final=3", *BOX]).setup


def run(s, controller=None):
    return simulate(s.plant, s.controller if controller is None else controller, s.trajectory, t_final=s.t_final,
                    integrator=s.integrator, q0=s.q0, dq0=s.dq0, max_state=s.max_state)


def test_example_6_2_2_with_projection_converges(projected_book_setup):
    res = run(projected_book_setup)
    assert converges(res, 3.0), (res.status, np.abs(res.e[-1]), lyapunov_increase(res.V))
    assert res.phi_hat[:, 0].min() == 0.1  # the lower bound was hit: the projection was needed, and it held
    np.testing.assert_allclose(res.phi_hat[-1], [0.8, 2.3], atol=0.01)


def test_example_6_2_2_with_the_update_flipped_does_not_converge(projected_book_setup):
    c = projected_book_setup.controller
    flipped = FlippedUpdate(**{f.name: getattr(c, f.name) for f in dataclasses.fields(c) if f.init})
    res = run(projected_book_setup, flipped)
    assert not converges(res, 3.0)


def test_example_6_2_2_as_the_book_ran_it_stops_where_M_hat_turns_singular():
    """Without projection the estimate m̂1 reaches 0 (det M̂ = 0) at t = 2.279e-5 s (independent reference above);
    resolved with dt = 1e-6, the run stops in the step that contains that instant or the one before, keeping the
    finite samples up to there."""
    res = load("example-6.2.2", ["simulation.dt=1e-6", "simulation.t_final=1e-4"]).run()
    assert "the estimated mass matrix M̂(q) is no longer positive definite" in res.status
    t_stop = stop_time(res.status)
    assert SINGULAR_AT - 2e-6 <= t_stop <= SINGULAR_AT
    assert res.t[-1] == pytest.approx(t_stop, abs=1e-12)
    assert np.all(np.isfinite(res.x)) and res.phi_hat[-1, 0] < 0.1


def test_a_negative_mass_estimate_stops_at_once_naming_the_estimate():
    res = load("example-6.2.2", ["controller.phi_hat0=[-0.5, 2.2]", "simulation.t_final=0.1"]).run()
    assert res.status.startswith("diverged within the step from 0 to ")  # not "at t=0": the state at 0 was fine
    assert "the estimated mass matrix M̂(q) is no longer positive definite" in res.status
    assert "φ̂ = [-0.5  2.2]" in res.status and "controller.phi_min/phi_max" in res.status
    assert res.t.shape == (1,)


def test_the_stop_through_the_cli_is_a_status_not_a_traceback(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["run", "example-6.2.2", "--out", str(out), "--no-plots", "--t-final", "0.01"])
    captured = capsys.readouterr()
    assert code == 1
    assert "Traceback" not in captured.err + captured.out
    status = json.loads((out / "metrics.json").read_text())["status"]
    assert status.startswith("diverged within the step from ") and "M̂" in status


def test_a_batch_with_one_singular_estimate_stops_naming_it():
    """The guard names the run whose M̂ is indefinite, its update is NaN there only, and the stop reason names φ̂."""
    ctrl = book_controller()
    x = np.array([[0.85, 2.2], [-0.3, 1.0], [0.8, 2.3]])
    q, dq = np.zeros((3, 2)), np.zeros((3, 2))
    ref = Reference(np.zeros((3, 2)), np.ones((3, 2)), np.zeros((3, 2)))
    np.testing.assert_array_equal(ctrl.guard(0.0, x, q, dq, ref), [True, False, True])
    dx = ctrl.update(0.0, x, q, dq, np.zeros((3, 2)), ref)
    assert np.all(np.isnan(dx[1])) and np.all(np.isfinite(dx[[0, 2]]))
    assert "φ̂ = [-0.3  1. ]" in ctrl.stop_reason(q[1], x[1])


# --------------------------------------------------------------------------------------------------------------------
# Problem 6.2-1: the polar arm


def test_problem_6_2_1_needs_its_projection():
    """[P] gains K_p = 25, K_v = 10, Γ = 20, m̂(0) = 0.5: without the bound m̂ ≥ 0.1, m̂ overshoots to 5.1 and then falls
    through zero, M̂ = diag(m̂ r², m̂) turns singular at t = 0.144 s (the same at dt = 1e-3 and 1e-4); with the bound the
    estimate rests on it and the run goes on."""
    s = load("problem-6.2-1", ["simulation.t_final=0.5"]).setup
    free = run(s, dataclasses.replace(s.controller, phi_min=None))
    assert "M̂(q) is no longer positive definite" in free.status
    assert 0.1 < stop_time(free.status) < 0.2
    res = run(s)
    assert res.status == "ok"
    assert res.phi_hat.min() == 0.1


@pytest.mark.slow
def test_problem_6_2_1_converges():
    """20 s: |e| < 1e-6 and m̂ → 1 (measured |e(20)| < 2e-8, m̂(20) = 1.0000), V never increases."""
    res = load("problem-6.2-1").run()
    assert res.status == "ok"
    assert np.all(np.abs(res.e[-1]) < 1e-6)
    assert res.phi_hat[-1, 0] == pytest.approx(1.0, abs=1e-4)
    assert lyapunov_increase(res.V) < 1e-9


@pytest.mark.slow
@pytest.mark.parametrize(("name", "overrides"), [("example-6.2.2", BOX), ("problem-6.2-2", [])])
def test_both_lyapunov_pairs_converge_over_20_s(name, overrides):
    """Problem 6.2-2: the book's pair and p2 = p3 = 1 both give e → 0 and φ̂ → (0.8, 2.3) (measured |e(20)| ≤ 1.2e-7,
    |φ̂(20) − φ| ≤ 2e-6 for both; RMS e 1.66e-3 / 1.61e-3 rad on joint 1)."""
    res = load(name, overrides).run()
    assert res.status == "ok"
    assert np.all(np.abs(res.e[-1]) < 1e-6)
    np.testing.assert_allclose(res.phi_hat[-1], [0.8, 2.3], atol=1e-4)
    assert lyapunov_increase(res.V) < 1e-9


# --------------------------------------------------------------------------------------------------------------------
# The guard as an indicator (issue 14): what a compiled loop reads, since traced code cannot raise


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_positive_definite_is_the_cholesky_test_matrix_by_matrix(x64, n):
    """The closed forms (n ≤ 2) and the stacked Cholesky agree with numpy's Cholesky, one matrix at a time, on
    definite, semidefinite, indefinite and non-finite matrices (not definite); JAX gives the same answers."""
    from robotadapt.controllers.base import positive_definite

    rng = np.random.default_rng(n)
    A = rng.normal(size=(40, n, n))
    S = A @ A.mT + rng.uniform(-1.0, 1.0, size=(40, 1, 1)) * np.eye(n)  # some shifted out of definiteness
    S[0] = 0.0
    S[1] = np.eye(n)
    S[2, 0, 0] = np.nan

    def cholesky_ok(a):  # a finite factor: numpy's Cholesky passes NaNs through
        try:
            return bool(np.all(np.isfinite(np.linalg.cholesky(a))))
        except np.linalg.LinAlgError:
            return False

    want = np.array([cholesky_ok(a) for a in S])
    assert 0 < want.sum() < len(want)
    np.testing.assert_array_equal(positive_definite(np, S), want)
    np.testing.assert_array_equal(positive_definite(np, S[1]), True)
    jnp = pytest.importorskip("jax").numpy
    from robotadapt.tracing import jax_module

    jax_module()
    np.testing.assert_array_equal(np.asarray(positive_definite(jnp, jnp.asarray(S))), want)


def test_on_traced_arrays_the_update_returns_nan_where_the_guard_fails(x64):
    """The same law on JAX arrays: no exception (tracing cannot raise), NaN for the run whose M̂ is indefinite, the
    numpy values for the others, and `guard` says which, as on numpy arrays."""
    pytest.importorskip("jax")
    from robotadapt.tracing import jax_module

    jnp = jax_module().numpy
    ctrl = book_controller()
    x = np.array([[0.85, 2.2], [-0.3, 1.0], [0.8, 2.3]])
    q, dq, ddq = np.zeros((3, 2)), np.zeros((3, 2)), np.ones((3, 2))
    ref = Reference(np.zeros((3, 2)), np.ones((3, 2)), np.zeros((3, 2)))
    np.testing.assert_array_equal(ctrl.guard(0.0, x, q, dq, ref), [True, False, True])
    traced = jax_module().jit(lambda *a: (ctrl.update(0.0, *a[:4], Reference(*a[4:])), ctrl.guard(0.0, *a[:3],
                                                                                                     Reference(*a[4:]))))
    dx, ok = (np.asarray(a) for a in traced(*(jnp.asarray(a) for a in (x, q, dq, ddq, *ref))))
    np.testing.assert_array_equal(ok, [True, False, True])
    assert np.all(np.isnan(dx[1]))
    keep = [0, 2]
    want = ctrl.update(0.0, x[keep], q[keep], dq[keep], ddq[keep], Reference(*(a[keep] for a in ref)))
    np.testing.assert_allclose(dx[keep], want, rtol=1e-12)
    assert ctrl.stop_reason(q[1], x[1]).startswith("the estimated mass matrix M̂(q) is no longer positive definite")
