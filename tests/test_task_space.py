"""The task-space laws (docs/task-space.md) against their papers' equations written out here, on the book's two-link
arm with its kinematics in closed form and a hand-written RK4: Cartesian Slotine–Li (Slotine & Li 1988), the adaptive
Jacobian (Cheah, Liu & Slotine 2006) and operational-space control (Khatib 1987); what their proofs promise (V
nonincreasing, x_e → 0, θ̂_k bounded); the packaged scenarios; every engine equal; the reach check."""

from __future__ import annotations

import json

import numpy as np
import pytest

import robotadapt as ra
from robotadapt.cli import main
from robotadapt.controllers.task_space import AdaptiveJacobian, OperationalSpace, TaskSlotineLi
from robotadapt.task_trajectories import Circle

ARM = ra.TwoLinkArm()  # l1 = l2 = 1 m, g = 9.8
PHI = np.array([0.8, 2.3])
PATH = Circle([1.0, 0.5], 0.3, 1.0, ramp=1.0)
DT, T = 1e-3, 2.0


def fk(q: np.ndarray, l1: float = 1.0, l2: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """x = (l1 c1 + l2 c12, l1 s1 + l2 s12) and its Jacobian, by hand."""
    s1, c1, s12, c12 = np.sin(q[0]), np.cos(q[0]), np.sin(q[0] + q[1]), np.cos(q[0] + q[1])
    return (np.array([l1 * c1 + l2 * c12, l1 * s1 + l2 * s12]),
            np.array([[-l1 * s1 - l2 * s12, -l2 * s12], [l1 * c1 + l2 * c12, l2 * c12]]))


def jdot(q: np.ndarray, dq: np.ndarray, l1: float = 1.0, l2: float = 1.0) -> np.ndarray:
    """dJ/dt by hand."""
    s1, c1, s12, c12 = np.sin(q[0]), np.cos(q[0]), np.sin(q[0] + q[1]), np.cos(q[0] + q[1])
    w1, w12 = dq[0], dq[0] + dq[1]
    return np.array([[-l1 * c1 * w1 - l2 * c12 * w12, -l2 * c12 * w12], [-l1 * s1 * w1 - l2 * s12 * w12, -l2 * s12 * w12]])


def q_start() -> np.ndarray:
    """Elbow-up inverse kinematics of x_d(0), by hand (law of cosines)."""
    x = PATH(0.0).q_des
    c2 = (x @ x - 2.0) / 2.0
    q2 = np.arccos(c2)
    return np.array([np.arctan2(x[1], x[0]) - np.arctan2(np.sin(q2), 1.0 + c2), q2])


def dynamics(q: np.ndarray, dq: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return ARM.mass_matrix(q, phi), ARM.coriolis_matrix(q, dq, phi), ARM.gravity(q, phi)


def rk4(rhs, z: np.ndarray) -> np.ndarray:
    """The plant and the law's state together, RK4 at DT, logged every step."""
    out = [z]
    for k in range(round(T / DT)):
        t = k * DT
        k1 = rhs(t, z)
        k2 = rhs(t + DT / 2, z + DT / 2 * k1)
        k3 = rhs(t + DT / 2, z + DT / 2 * k2)
        k4 = rhs(t + DT, z + DT * k3)
        z = z + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(z)
    return np.array(out)


def test_cartesian_slotine_li_is_the_paper_written_out():
    """x_e = x_d − x, ẋ_r = ẋ_d + Λx_e, q̇_r = J⁻¹ẋ_r, q̈_r = J⁻¹(ẍ_r − J̇q̇_r), s = q̇_r − q̇ (square J, λ = 0),
    τ = M̂ q̈_r + V̂_m q̇_r + Ĝ + K_v s, dφ̂/dt = Γ Yᵀ s: the law's run equals this loop to round-off, and V falls."""
    Lam, Kv, Gamma = 5.0, 10.0, 5.0
    law = TaskSlotineLi(ARM, Lam=Lam, Kv=Kv, Gamma=Gamma, phi_hat0=[0.0, 0.0], damping=0.0)

    def rhs(t: float, z: np.ndarray) -> np.ndarray:
        q, dq, phi_hat = z[:2], z[2:4], z[4:]
        ref = PATH(t)
        x, J = fk(q)
        Ji = np.linalg.inv(J)
        xe, dxe = ref.q_des - x, ref.dq_des - J @ dq
        dq_r = Ji @ (ref.dq_des + Lam * xe)
        ddq_r = Ji @ (ref.ddq_des + Lam * dxe - jdot(q, dq) @ dq_r)
        s = dq_r - dq
        M, C, G = dynamics(q, dq, phi_hat)
        tau = M @ ddq_r + C @ dq_r + G + Kv * s
        Mt, Ct, Gt = dynamics(q, dq, PHI)
        ddq = np.linalg.solve(Mt, tau - Ct @ dq - Gt)
        return np.concatenate([dq, ddq, Gamma * ARM.regressor(q, dq, dq_r, ddq_r).T @ s])

    q0 = q_start()
    mine = rk4(rhs, np.concatenate([q0, [0.0, 0.0], [0.0, 0.0]]))
    res = ra.simulate(ra.Plant(ARM, PHI), law, PATH, t_final=T, q0=q0, dq0=[0.0, 0.0], integrator=ra.RK4(DT))
    assert res.ok and res.space == "task"
    np.testing.assert_allclose(res.q, mine[:, :2], atol=1e-10)
    np.testing.assert_allclose(res.phi_hat, mine[:, 4:], atol=1e-9)
    assert np.max(np.diff(res.V)) <= 1e-9 * res.V[0]  # dV/dt = −sᵀK_v s
    x_end = fk(res.q[-1])[0]
    np.testing.assert_allclose(res.e[-1], PATH(res.t[-1]).q_des - x_end, atol=1e-14)


def test_the_adaptive_jacobian_is_the_paper_written_out():
    """Cheah, Liu & Slotine (2006) with Ĵ = J(q, l̂1, l̂2): Δx = x − x_d, ẋ_r = ẋ_d − αΔx, q̇_r = Ĵ⁻¹ẋ_r,
    q̈_r = Ĵ⁻¹(ẍ_r − d(Ĵ)/dt q̇_r), ẍ_r = ẍ_d − αΔẋ, s = q̇ − q̇_r,
    τ = −Ĵᵀ(K_vΔẋ̂ + K_pΔx) − K_s s + M̂q̈_r + V̂_m q̇_r + Ĝ, dφ̂/dt = −ΓYᵀs, dθ̂/dt = L_k Y_kᵀ(K_p + αK_v)Δx:
    the law's run equals this loop to round-off; V of the paper falls; θ̂_k stays bounded."""
    alpha, Kv, Kp, Ks, Gamma, Lk = 5.0, 20.0, 100.0, 1.0, 5.0, 2.0
    law = AdaptiveJacobian(ARM, alpha=alpha, Kv=Kv, Kp=Kp, Ks=Ks, Gamma=Gamma, Gamma_k=Lk, phi_hat0=[0.56, 1.61],
                           theta_hat0=[0.8, 1.2])

    def rhs(t: float, z: np.ndarray) -> np.ndarray:
        q, dq, phi_hat, (l1, l2) = z[:2], z[2:4], z[4:6], z[6:]
        ref = PATH(t)
        x, J = fk(q)
        _, Jh = fk(q, l1, l2)
        dx = x - ref.q_des
        s1, c1, s12, c12 = np.sin(q[0]), np.cos(q[0]), np.sin(q[0] + q[1]), np.cos(q[0] + q[1])
        Yk = np.array([[-s1 * dq[0], -s12 * (dq[0] + dq[1])], [c1 * dq[0], c12 * (dq[0] + dq[1])]])  # Ĵq̇ = Y_k θ̂
        dtheta = Lk * Yk.T @ ((Kp + alpha * Kv) * dx)
        dJh = jdot(q, dq, l1, l2) + np.array([[-s1, 0.0], [c1, 0.0]]) * dtheta[0] + np.array(
            [[-s12, -s12], [c12, c12]]) * dtheta[1]
        Jhi = np.linalg.inv(Jh)
        dq_r = Jhi @ (ref.dq_des - alpha * dx)
        ddq_r = Jhi @ (ref.ddq_des - alpha * (J @ dq - ref.dq_des) - dJh @ dq_r)
        s = dq - dq_r
        M, C, G = dynamics(q, dq, phi_hat)
        tau = -Jh.T @ (Kv * (Jh @ dq - ref.dq_des) + Kp * dx) - Ks * s + M @ ddq_r + C @ dq_r + G
        Mt, Ct, Gt = dynamics(q, dq, PHI)
        ddq = np.linalg.solve(Mt, tau - Ct @ dq - Gt)
        return np.concatenate([dq, ddq, -Gamma * ARM.regressor(q, dq, dq_r, ddq_r).T @ s, dtheta])

    q0 = q_start()
    mine = rk4(rhs, np.concatenate([q0, [0.0, 0.0], [0.56, 1.61], [0.8, 1.2]]))
    res = ra.simulate(ra.Plant(ARM, PHI), law, PATH, t_final=T, q0=q0, dq0=[0.0, 0.0], integrator=ra.RK4(DT))
    assert res.ok
    np.testing.assert_allclose(res.q, mine[:, :2], atol=1e-10)
    np.testing.assert_allclose(res.x, mine[:, 4:], atol=1e-9)
    assert np.max(np.diff(res.V)) <= 1e-8 * res.V[0]  # dV/dt = −Δẋ̂ᵀK_vΔẋ̂ − αΔxᵀK_pΔx − sᵀK_s s
    assert np.all(np.abs(res.monitors["theta_hat"] - 1.0) < 0.25)  # bounded near the truth


def test_operational_space_control_with_the_true_model_tracks_exactly():
    """Khatib's law with φ̂ = φ makes ẍ = ẍ_d + K_v ẋ_e + K_p x_e: from a start on the path, x_e stays at round-off."""
    law = OperationalSpace(ARM, Kp=100.0, Kv=20.0, phi_hat0=PHI)
    res = ra.simulate(ra.Plant(ARM, PHI), law, PATH, t_final=T, q0=q_start(), dq0=[0.0, 0.0], integrator=ra.RK4(DT))
    assert res.ok and np.max(np.abs(res.e)) < 1e-10
    wrong = OperationalSpace(ARM, Kp=100.0, Kv=20.0, phi_hat0=0.7 * PHI)
    off = ra.simulate(ra.Plant(ARM, PHI), wrong, PATH, t_final=T, q0=q_start(), dq0=[0.0, 0.0], integrator=ra.RK4(DT))
    assert np.max(np.abs(off.e)) > 1e-4  # the test can fail: a wrong model leaves an error


@pytest.mark.parametrize("name, theta", [("task-circle-2link", None), ("task-jacobian-2link", [1.0, 1.0])])
def test_the_packaged_two_link_scenarios_reach_the_path(name, theta, tmp_path, capsys):
    """task_final_error below 1 mm after 10 s; the adaptive Jacobian's link lengths found; the summary in metres."""
    assert main(["run", name, "--out", str(tmp_path), "--no-plots"]) == 0
    out = capsys.readouterr().out
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["error_space"] == "task" and m["task_final_error"] < 1e-3 and m["task_rms_error"] < 0.01
    assert "m (hand)" in out
    if theta is not None:
        np.testing.assert_allclose(m["final_theta_hat"], theta, atol=1e-3)
        assert m["theta_true"] == theta


@pytest.mark.parametrize("name", ["task-circle-2link", "task-jacobian-2link"])
def test_every_engine_runs_the_task_laws_alike(name):
    """numpy, JAX and C, continuous and sampled at 2 ms: the same q and τ to 1e-9."""
    for extra in ([], ["simulation.control_period=0.002"]):
        runs = {b: ra.load(name, [f'simulation.backend="{b}"', "simulation.t_final=1.0", *extra]).run()
                for b in ("numpy", "jax", "c")}
        for b in ("jax", "c"):
            assert runs[b].status == runs["numpy"].status == "ok"
            np.testing.assert_allclose(runs[b].q, runs["numpy"].q, atol=1e-9)
            np.testing.assert_allclose(runs[b].tau, runs["numpy"].tau, atol=1e-9 * max(1, np.abs(runs["numpy"].tau).max()))


def test_a_path_out_of_reach_is_one_line(tmp_path, capsys):
    code = main(["run", "task-circle-2link", "--set", "trajectory.radius=1.2", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "trajectory" in err[0] and "reach" in err[0]


def test_the_comparison_of_a_task_scenario_runs_the_task_laws(tmp_path):
    assert main(["compare", "task-circle-2link", "--t-final", "1", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "comparison.json").read_text())["rows"]
    assert {r["controller"] for r in rows} == {"operational_space", "task_slotine_li", "adaptive_jacobian"}


@pytest.mark.parametrize("adaptation", ["natural", "pullback"])
def test_cartesian_slotine_li_takes_every_update_law(adaptation):
    """On the Panda (URDF bodies): the natural and the pullback law keep V falling and every estimate a real body."""
    res = ra.load("panda-task-circle", [f'controller.adaptation="{adaptation}"', "controller.gamma=0.1",
                                        "simulation.t_final=0.5"]).run()
    m = ra.metrics(res)
    assert res.ok and m["physically_consistent"] and m["task_max_error"] < 0.01
    assert np.max(np.diff(res.V)) <= 1e-9 * res.V[0]


def test_a_task_run_draws_its_path_and_kinematic_estimates(tmp_path):
    """path.png (the hand over the desired path, in the arm's plane) and kinematics.png (θ̂_k and its truth)."""
    from robotadapt.report.figures import kinematics_figure, path_figure

    res = ra.load("task-jacobian-2link", ["simulation.t_final=1.0"]).run()
    written = {p.name for p in ra.save_figures(res, tmp_path, "aj")}
    assert {"path.png", "kinematics.png", "tracking_error.png"} <= written
    ax = path_figure(res).axes[0]
    hand, desired = (line.get_xydata() for line in ax.get_lines()[:2])
    np.testing.assert_allclose(desired, res.q_des)
    np.testing.assert_allclose(hand, res.q_des - res.e)
    lines = kinematics_figure(res).axes[0].get_lines()
    np.testing.assert_allclose(lines[0].get_ydata(), res.monitors["theta_hat"][:, 0])
    np.testing.assert_allclose(lines[1].get_ydata(), 1.0)


def test_a_run_that_passes_near_a_singularity_says_when():
    """A circle that reaches out to 1.99995 m of the two-link arm's 2 m: the arm nearly stretches; σ_min(J) logged,
    metrics.json and the summary's warning name the instant. The packaged circle never comes near one."""
    from robotadapt.analysis.metrics import SINGULAR, health_warnings

    far = ra.load("task-circle-2link", ["trajectory.centre=[1.69995, 0.0]", "trajectory.radius=0.3",
                                         "simulation.t_final=4.0"]).run()
    m = ra.metrics(far)
    sigma = far.monitors["hand_sigma_min"]
    k = int(np.argmax(sigma < SINGULAR))
    assert m["min_hand_sigma"] < SINGULAR and m["near_singularity_t"] == pytest.approx(far.t[k])
    J = fk(far.q[k])[1]
    assert sigma[k] == pytest.approx(np.linalg.svd(J, compute_uv=False)[-1], rel=1e-9)
    assert any(w.startswith("singularity:") for w in health_warnings(m))
    near = ra.metrics(ra.load("task-circle-2link", ["simulation.t_final=2.0"]).run())
    assert near["near_singularity_t"] is None and not any(w.startswith("singularity") for w in health_warnings(near))
