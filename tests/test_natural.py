"""The natural adaptive law (issue 26, docs/natural.md): its B, its divergence, its coordinates, its V, every driver,
and the bad input it refuses."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.cli import main
from robotadapt.controllers import InertiaRelated
from robotadapt.controllers.geometry import Natural
from robotadapt.plant.plant import Plant
from robotadapt.robots.consistency import DUAL, parts
from robotadapt.robots.kinematic_tree import KinematicTree
from robotadapt.sim import RK4, simulate
from robotadapt.studies.scenarios import load
from test_kinematic_tree import URDF  # a two-link arm with real inertias

RNG = np.random.default_rng(26)


def hand_J(v: np.ndarray) -> np.ndarray:
    """J = [[½ tr(I) 𝟙 − I, h], [hᵀ, m]] from (m, h, Ixx, Ixy, Iyy, Ixz, Iyz, Izz), written out."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = v
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    J[:3, 3] = J[3, :3] = hx, hy, hz
    J[3, 3] = m
    return J


def _symmetric_units() -> list[np.ndarray]:
    units = []
    for i, j in zip(*np.triu_indices(4), strict=True):
        E = np.zeros((4, 4))
        E[i, j] = E[j, i] = 1.0
        units.append(E)
    return units


UNITS = _symmetric_units()
# tr(J(e_k) E_j): B = Σ_j c_j E_j has tr(J(v) B) = vᵀb for every v iff A c = b
A = np.array([[np.trace(hand_J(v) @ E) for E in UNITS] for v in np.eye(10)])


def hand_B(b: np.ndarray) -> np.ndarray:
    """B with tr(J(v) B) = vᵀb for every v, from the ten unit vectors: a 10×10 solve for B's ten entries."""
    return sum(c * E for c, E in zip(np.linalg.solve(A, b), UNITS, strict=True))


def consistent_link() -> np.ndarray:
    """A random real body: J = ∫[x;1][x;1]ᵀ dm of four point masses, as 10 parameters."""
    points, masses = RNG.normal(size=(4, 3)) * 0.2, RNG.uniform(0.5, 2.0, 4)
    J = sum(w * np.outer(np.append(p, 1), np.append(p, 1)) for p, w in zip(points, masses, strict=True))
    Sigma = J[:3, :3]
    inertia = np.trace(Sigma) * np.eye(3) - Sigma
    return np.array([J[3, 3], *J[:3, 3], inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2],
                     inertia[2, 2]])


NAMES = tuple(f"{p}{i}" for i in (1, 2) for p in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"))
NAMES += ("fv1", "Ia2")


def law(gamma: float = 0.7) -> Natural:
    return Natural(gamma, tuple(parts(NAMES)))


def test_b_is_the_matrix_of_the_identity_tr_J_v_B_equals_v_b():
    for _ in range(5):
        v, b = RNG.normal(size=10), RNG.normal(size=10)
        B = np.einsum("k,kab->ab", b, DUAL)
        assert np.trace(hand_J(v) @ B) == pytest.approx(v @ b, rel=1e-12)
        np.testing.assert_allclose(B, hand_B(b), atol=1e-12)


def test_the_update_is_j_b_j_over_gamma_and_the_divergence_falls_by_phi_tilde_b():
    """Along dx/dt = rate(x, b): dĴ/dt = Ĵ B Ĵ / γ (differenced through the coordinates), and the written-out
    d/dt γ D(J‖Ĵ) = γ tr(Ĵ⁻¹ dĴ) − γ tr(Ĵ⁻¹ J Ĵ⁻¹ dĴ) equals −φ̃ᵀb (φ̃ = φ − φ̂), so it cancels V's cross term."""
    nat = law()
    phi_hat = np.concatenate([consistent_link(), consistent_link(), [0.4, 0.02]])
    phi = np.concatenate([consistent_link(), consistent_link(), [0.3, 0.05]])
    x = nat.initial_state(phi_hat)
    np.testing.assert_allclose(nat.estimate(x), phi_hat, rtol=1e-12, atol=1e-14)
    b = RNG.normal(size=phi.size)
    dx = nat.rate(x, b)
    eps = 1e-6
    dphi = (nat.estimate(x + eps * dx) - nat.estimate(x - eps * dx)) / (2 * eps)
    total = 0.0
    for part in parts(NAMES):
        idx = list(part.entries)
        if len(idx) == 10:
            Jh, J = hand_J(phi_hat[idx]), hand_J(phi[idx])
            dJ = Jh @ hand_B(b[idx]) @ Jh / nat.gamma
            np.testing.assert_allclose(hand_J(dphi[idx]), dJ, rtol=1e-7, atol=1e-9)
            inv = np.linalg.inv(Jh)
            total += nat.gamma * (np.trace(inv @ dJ) - np.trace(inv @ J @ inv @ dJ))
        else:
            q, p = phi_hat[idx[0]], phi[idx[0]]
            dq = q * q * b[idx[0]] / nat.gamma
            assert dphi[idx[0]] == pytest.approx(dq, rel=1e-7)
            total += nat.gamma * (dq / q - p * dq / q**2)
    assert total == pytest.approx(-(phi - phi_hat) @ b, rel=1e-6)  # the inverses of Ĵ cost digits
    dV = (nat.lyapunov(x + eps * dx, phi) - nat.lyapunov(x - eps * dx, phi)) / (2 * eps)
    assert dV == pytest.approx(total, rel=1e-6)
    assert nat.lyapunov(nat.initial_state(phi), phi) == pytest.approx(0.0, abs=1e-12) and nat.lyapunov(x, phi) > 0


def test_the_exponential_map_is_the_geodesic_and_agrees_with_the_flow_for_short_steps():
    """step(x, dx, h) = L exp(h Lᵀ B L / γ) Lᵀ, the written-out formula; for small h it is x + h dx to O(h²)."""
    nat = law()
    phi_hat = np.concatenate([consistent_link(), consistent_link(), [0.4, 0.02]])
    x, b = nat.initial_state(phi_hat), RNG.normal(size=phi_hat.size)
    dx, h = nat.rate(x, b), 0.3
    after = nat.estimate(nat.step(x, dx, h))
    from scipy.linalg import expm

    for part in parts(NAMES):
        idx = list(part.entries)
        if len(idx) == 10:
            L = np.linalg.cholesky(hand_J(phi_hat[idx]))
            expected = L @ expm(h * L.T @ hand_B(b[idx]) @ L / nat.gamma) @ L.T
            np.testing.assert_allclose(hand_J(after[idx]), expected, rtol=1e-10, atol=1e-12)
        else:
            q = phi_hat[idx[0]]
            assert after[idx[0]] == pytest.approx(q * np.exp(h * q * b[idx[0]] / nat.gamma), rel=1e-12)
    small = 1e-4
    np.testing.assert_allclose(nat.step(x, dx, small), x + small * dx, atol=50 * small**2 * np.abs(dx).max() ** 2)


def urdf_arm(tmp_path) -> KinematicTree:
    (tmp_path / "arm.urdf").write_text(URDF.format(kind="revolute"))
    return KinematicTree.from_urdf(tmp_path / "arm.urdf")


class PlainNatural(InertiaRelated):
    """The natural law integrated in φ̂ itself (state φ̂, dφ̂/dt = J⁻¹(Ĵ B Ĵ)/γ): the update as the paper writes it."""

    @property
    def state_names(self):
        return tuple(self.model.param_names)

    def initial_state(self, q0, dq0):
        return np.array(self.phi_hat0, dtype=float)

    def phi_hat(self, x):
        return x

    def __call__(self, t, x, q, dq, ref):
        Y, r = self.regressor(t, x, q, dq, ref)
        tau = np.einsum("...ij,...j->...i", Y, x) + r @ self.Kv.T
        if x.ndim > 1:  # the run's outputs, evaluated over all samples at once, ask for the torque only
            return tau, np.full_like(x, np.nan)
        b = Y.T @ r
        dphi = np.zeros_like(x)
        for k in range(len(x) // 10):
            idx = slice(10 * k, 10 * k + 10)
            Jh = hand_J(x[idx])
            dJ = Jh @ hand_B(b[idx]) @ Jh / self.gamma
            dphi[idx] = [dJ[3, 3], dJ[0, 3], dJ[1, 3], dJ[2, 3], *self._inertia(dJ)]
        return tau, dphi

    @staticmethod
    def _inertia(dJ):
        Sigma = dJ[:3, :3]
        inertia = np.trace(Sigma) * np.eye(3) - Sigma
        return inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2], inertia[2, 2]


def test_log_cholesky_coordinates_give_the_plain_update_where_j_stays_inside(tmp_path):
    """RK4 on the log-Cholesky state and RK4 on φ̂ itself (the paper's update, written here) solve one ODE: they differ
    by RK4's error only, which falls as dt⁴ (halving dt divides the gap by about 16)."""
    from robotadapt.trajectories import sinusoid

    arm = urdf_arm(tmp_path)
    phi = arm.default_phi
    kw = dict(Lam=5.0, Kv=3.0, adaptation="natural", gamma=0.05, phi_hat0=0.7 * phi)

    def gap(dt: float) -> tuple[float, float]:
        runs = [simulate(Plant(arm, phi), cls(arm, **kw), sinusoid(2, amplitude=0.5, omega=2.0), t_final=0.3,
                         integrator=RK4(dt, backend="numpy")) for cls in (InertiaRelated, PlainNatural)]
        return np.abs(runs[0].phi_hat[-1] - runs[1].phi_hat[-1]).max(), np.abs(runs[0].phi_hat[-1] - 0.7 * phi).max()

    (coarse, moved), (fine, _) = gap(2e-3), gap(1e-3)
    print(f"gap {coarse:.3g} at dt = 2 ms, {fine:.3g} at 1 ms; the estimate moved {moved:.3g}")
    assert moved > 1e-2 and coarse < 1e-4 * moved and coarse / fine > 10


def test_dv_dt_is_minus_r_kv_r_along_a_natural_run():
    """Example 6.3.1's arm with the natural law: V(t) − V(0) along the run against ∫ −rᵀK_v r (trapezoid, whose error
    is O(dt²): 4.2e-4 of V(0) = 13.7 at dt = 1 ms, 1.0e-4 at 0.5 ms)."""
    sc = load("example-6.3.1", ['controller={kind="slotine_li", Lam=2.5, Kv=10, adaptation="natural", gamma=5.0, '
                                'phi_hat0=[0.5, 1.0]}', "simulation.t_final=2.0", "simulation.backend=numpy"])
    res = sc.run()
    V, r, ctrl = res.V, res.r, sc.setup.controller
    rate = -np.einsum("ti,ij,tj->t", r, ctrl.Kv, r)
    from scipy.integrate import cumulative_trapezoid

    assert np.abs(V - V[0] - cumulative_trapezoid(rate, res.t, initial=0.0)).max() < 1e-4 * V[0]
    assert metrics(res)["physically_consistent"] is True


def run_file(tmp_path, body: str, name: str = "s.toml") -> str:
    path = tmp_path / name
    (tmp_path / "arm.urdf").write_text(URDF.format(kind="revolute"))
    path.write_text(f'robot = {{kind = "urdf", path = "{tmp_path / "arm.urdf"}"}}\n' + body)
    return str(path)


BODY = """plant = {{q0 = [0.0, 0.0], dq0 = [0.0, 0.0]}}
trajectory = {{kind = "sinusoid", amplitude = 0.8, omega = 3.0}}
[controller]
kind = "slotine_li"
Lam = 5.0
Kv = 2.0
{gains}
phi_hat0 = {{scale = 0.7}}
[simulation]
t_final = {t_final}
dt = 1e-3
control_period = 1e-3
log_every = 1
backend = "jax"
"""


def test_a_hundred_thousand_ticks_at_an_aggressive_gamma_stay_real_bodies_and_the_euclidean_run_leaves(tmp_path):
    """10⁵ sampled ticks (exponential map) with γ = 0.002, every 10th logged: every logged Ĵᵢ ≻ 0; the Euclidean law
    from the same start with Γ = 1 leaves the set, and its metrics say when and which link."""
    natural = load(run_file(tmp_path, BODY.format(gains='adaptation = "natural"\ngamma = 0.002', t_final=100.0)),
                   ["simulation.log_every=10"])
    res = natural.run()
    m = metrics(res)
    assert res.status.ok and len(res.t) == 10_001
    assert m["physically_consistent"] is True and m["min_pseudo_inertia_eigenvalue"] > 0
    assert np.abs(res.phi_hat[-1] - res.phi_hat[0]).max() > 1e-2
    euclid = load(run_file(tmp_path, BODY.format(gains="Gamma = 1.0", t_final=10.0), "e.toml")).run()
    e = metrics(euclid)
    assert e["physically_consistent"] is False and e["left_consistent_set_part"] in ("link 1", "link 2")
    print(f"natural: min eigenvalue {m['min_pseudo_inertia_eigenvalue']:.3g} over 1e5 ticks; Euclidean left at "
          f"t = {e['left_consistent_set_t']} s ({e['left_consistent_set_part']}), "
          f"min {e['min_pseudo_inertia_eigenvalue']:.3g}")


@pytest.mark.parametrize("gains, field, words", [
    ('adaptation = "natural"\ngamma = -1.0', "controller.gamma", ["positive"]),
    ('adaptation = "natural"\ngamma = 0.0', "controller.gamma", ["positive"]),
    ('adaptation = "natural"', "controller.gamma", ["required"]),
    ('adaptation = "riemann"\ngamma = 1.0', "controller.adaptation", ["natural"]),
])
def test_bad_natural_input_is_one_line_and_exit_2(tmp_path, capsys, gains, field, words):
    path = run_file(tmp_path, BODY.format(gains=gains, t_final=0.1))
    assert main(["run", path, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and field in err and all(w in err for w in words), err
    assert not (tmp_path / "out").exists()


def test_set_switches_a_packaged_scenario_to_the_natural_law_its_gamma_unused(tmp_path):
    """`robotadapt run panda-slotine-li --set controller.adaptation="natural" --set controller.gamma=1.0`: the file's Γ
    is the Euclidean law's and goes unused."""
    scenario = load("panda-slotine-li", ['controller.adaptation="natural"', "controller.gamma=1.0"])
    ctrl = scenario.setup.controller
    assert ctrl.Gamma is None and ctrl.gamma == 1.0 and type(ctrl.geometry).__name__ == "Natural"


def test_an_inconsistent_start_and_a_model_without_pseudo_inertias_are_refused(capsys, tmp_path):
    bad = ('controller={kind="slotine_li", Lam=2.5, Kv=10, adaptation="natural", gamma=5.0, phi_hat0=[0.0, 1.0]}')
    assert main(["run", "example-6.3.1", "--set", bad, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip()
    assert "controller.phi_hat0" in err and "m1" in err and err.count("\n") == 0
    link = hand_J(consistent_link())
    assert np.linalg.eigvalsh(link).min() > 0
    path = run_file(tmp_path, BODY.format(gains='adaptation = "natural"\ngamma = 1.0', t_final=0.1).replace(
        "phi_hat0 = {scale = 0.7}", "phi_hat0 = {scale = -0.7}"))
    assert main(["run", path, "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert "controller.phi_hat0" in err and "link 1" in err and "smallest eigenvalue" in err
    from robotadapt.robots.identifiability import BaseParameterModel, base_parameters

    model = BaseParameterModel(base_parameters(urdf_arm(tmp_path)))
    with pytest.raises(Exception) as info:
        InertiaRelated(model, Lam=1.0, Kv=1.0, adaptation="natural", gamma=1.0, phi_hat0=np.ones(model.p))
    assert getattr(info.value, "field", None) == "controller.adaptation" and "euclidean" in str(info.value)


@pytest.mark.parametrize("sampled", [False, True])
def test_tune_differentiates_gamma_through_the_natural_law(tmp_path, sampled):
    """`robotadapt tune --vary controller.gamma`: the program's gradient (through the log-Cholesky RK4 step, or the
    exponential map of a sampled tick) against central differences of forward runs."""
    from robotadapt.studies.gain_space import locate
    from tuning_checks import assert_gradient_is_central_differences

    body = BODY.format(gains='adaptation = "natural"\ngamma = 0.05', t_final=0.3).replace("log_every = 1\n", "")
    if not sampled:
        body = body.replace("control_period = 1e-3\n", "")
    scenario = load(run_file(tmp_path, body))
    assert_gradient_is_central_differences(scenario, [locate(scenario, "controller.gamma")])


def natural_rate_by_hand(phi_hat: np.ndarray, b: np.ndarray, gamma: float) -> np.ndarray:
    """dφ̂/dt of the natural law written out for links of 10: J⁻¹(Ĵ B Ĵ / γ) link by link."""
    out = []
    for k in range(len(phi_hat) // 10):
        Jh = hand_J(phi_hat[10 * k:10 * k + 10])
        dJ = Jh @ hand_B(b[10 * k:10 * k + 10]) @ Jh / gamma
        out += [dJ[3, 3], dJ[0, 3], dJ[1, 3], dJ[2, 3], *PlainNatural._inertia(dJ)]
    return np.array(out)


def test_adaptive_computed_torque_and_dcal_move_their_own_b_naturally(tmp_path):
    """At a random state: the natural ACT moves φ̂ by J⁻¹(Ĵ B Ĵ/γ) with b = Wᵀ M̂⁻¹ E1 (6.2.19), DCAL with b = Y_dᵀ r
    (7.2.7), both b written here from the model (dφ̂/dt differenced through the coordinates)."""
    from robotadapt.controllers import DCAL, AdaptiveComputedTorque
    from robotadapt.trajectories import sinusoid

    arm = urdf_arm(tmp_path)
    phi_hat0 = 0.8 * arm.default_phi
    q, dq, ddq = RNG.normal(size=2), RNG.normal(size=2), RNG.normal(size=2)
    ref = sinusoid(2, amplitude=0.5, omega=2.0)(0.3)
    e, de = ref.q_des - q, ref.dq_des - dq
    act = AdaptiveComputedTorque(arm, Kp=20.0, Kv=8.0, adaptation="natural", gamma=0.3, phi_hat0=phi_hat0)
    dcal = DCAL(arm, Kv=5.0, Kp=5.0, Ka=1.0, adaptation="natural", gamma=0.3, phi_hat0=phi_hat0)
    E1 = act.lyapunov_pair[0][2:, :] @ np.concatenate([e, de])
    b_act = arm.regressor(q, dq, dq, ddq).T @ np.linalg.solve(arm.mass_matrix(q, phi_hat0), E1)
    Yd = arm.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)
    b_dcal = Yd.T @ (de + e)
    eps = 1e-6
    for ctrl, dx, b in [(act, act.update(0.3, act.initial_state(q, dq), q, dq, ddq, ref), b_act),
                        (dcal, dcal(0.3, dcal.initial_state(q, dq), q, dq, ref)[1], b_dcal)]:
        x = ctrl.initial_state(q, dq)
        dphi = (ctrl.phi_hat(x + eps * dx) - ctrl.phi_hat(x - eps * dx)) / (2 * eps)
        np.testing.assert_allclose(dphi, natural_rate_by_hand(phi_hat0, b, 0.3), rtol=1e-6, atol=1e-9)


def test_natural_adaptive_computed_torque_keeps_dv_dt_minus_xqx():
    """Example 6.2.2's arm and gains, the natural law (V's parameter term 2γ Σ D): V(t) − V(0) against ∫ −xᵀQx,
    x = [e; ė], by the trapezoid, whose error is O(dt²): 7.3e-4 of V(0) at dt = 1 ms, 1.8e-4 at 0.5 ms."""
    from scipy.integrate import cumulative_trapezoid

    def gap(dt: float) -> float:
        sc = load("example-6.2.2", ['controller={kind="adaptive_computed_torque", Kp=125.0, Kv=50.0, adaptation='
                                    '"natural", gamma=5.0, phi_hat0=[0.85, 2.2]}', "simulation.t_final=1.0",
                                    "simulation.backend=numpy", f"simulation.dt={dt}"])
        res = sc.run()
        Q = sc.setup.controller.lyapunov_pair[1]
        x = np.concatenate([res.q_des - res.q, res.dq_des - res.dq], axis=-1)
        rate = -np.einsum("ti,ij,tj->t", x, Q, x)
        assert np.abs(res.phi_hat[-1] - res.phi_hat[0]).max() > 1e-3
        return float(np.abs(res.V - res.V[0] - cumulative_trapezoid(rate, res.t, initial=0.0)).max() / res.V[0])

    coarse, fine = gap(1e-3), gap(5e-4)
    assert coarse < 1e-3 and coarse / fine > 3.5


def test_no_adaptation_holds_the_estimate_and_ignores_the_gains():
    res = load("example-6.3.1", ['controller.adaptation="none"', "controller.phi_hat0=[0.5, 1.0]",
                                 "simulation.t_final=0.5", "simulation.backend=numpy"]).run()
    assert np.all(res.phi_hat == [0.5, 1.0])
