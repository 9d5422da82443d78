"""The constant pullback metric of Lee, Kwon & Park (issue item 8, docs/natural.md#the-constant-pullback-metric): the
natural law's metric frozen at P₀ = J(φ₀), dĴ/dt = P₀ B P₀ / γ. Its rate against the equations written here (B with the
paper's ½), its agreement with the natural law at P₀ = Ĵ, its V (dV/dt = −rᵀK_v r along a run, the error → 0), every
backend, the laws that take it, the bad input it refuses, and one-line changes to the law that these checks catch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.controllers import DCAL, AdaptiveComputedTorque, InertiaRelated
from robotadapt.controllers.geometry import Natural, Pullback
from robotadapt.robots.consistency import DUAL, link_parameters, parts
from robotadapt.studies.scenarios import load
from robotadapt.validation import ConfigError
from test_natural import NAMES, hand_J, urdf_arm  # pure helpers (its RNG is its own: not drawn from here)

RNG = np.random.default_rng(8)
LAYOUT = tuple(parts(NAMES))  # two links of 10, then the scalars fv1 and Ia2


def hand_B(b: np.ndarray) -> np.ndarray:
    """The paper's pseudo-inertia form of b = (b_m, b_h, b_Ixx, b_Ixy, b_Iyy, b_Ixz, b_Iyz, b_Izz), written out:
    B = [[tr(C) 𝟙 − C, ½ b_h], [½ b_hᵀ, b_m]] with C = [[b_xx, ½ b_xy, ½ b_xz], [·, b_yy, ½ b_yz], [·, ·, b_zz]]
    (the ½ that the authors' b2B.m lacks), so that tr(J(v) B) = vᵀb."""
    bm, bx, by, bz, bxx, bxy, byy, bxz, byz, bzz = b
    C = np.array([[bxx, bxy / 2, bxz / 2], [bxy / 2, byy, byz / 2], [bxz / 2, byz / 2, bzz]])
    B = np.zeros((4, 4))
    B[:3, :3] = np.trace(C) * np.eye(3) - C
    B[:3, 3] = B[3, :3] = np.array([bx, by, bz]) / 2
    B[3, 3] = bm
    return B


def parameters_of(J: np.ndarray) -> np.ndarray:
    """The 10 parameters of a pseudo-inertia, written out: m = J₃₃, h = J[:3, 3], I = tr(Σ) 𝟙 − Σ."""
    Sigma = J[:3, :3]
    inertia = np.trace(Sigma) * np.eye(3) - Sigma
    return np.array([J[3, 3], *J[:3, 3], inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2],
                     inertia[2, 2]])


def hand_rate(phi_ref: np.ndarray, b: np.ndarray, gamma: float) -> np.ndarray:
    """dφ̂/dt of the pullback law: φ(P₀ B P₀ / γ) per link (P₀ = J(φ₀)), θ₀² b / γ per scalar."""
    out = np.zeros_like(b)
    for part in LAYOUT:
        idx = list(part.entries)
        if len(idx) == 10:
            P0 = hand_J(phi_ref[idx])
            out[idx] = parameters_of(P0 @ hand_B(b[idx]) @ P0 / gamma)
        else:
            out[idx] = phi_ref[idx] ** 2 * b[idx] / gamma
    return out


def hand_V(phi_ref: np.ndarray, phi_hat: np.ndarray, phi: np.ndarray, gamma: float) -> float:
    """(γ/2) Σ tr(P₀⁻¹ J̃ P₀⁻¹ J̃) + (γ/2) Σ θ̃²/θ₀², J̃ = J(φ − φ̂)."""
    total = 0.0
    for part in LAYOUT:
        idx = list(part.entries)
        if len(idx) == 10:
            A = np.linalg.inv(hand_J(phi_ref[idx])) @ hand_J(phi[idx] - phi_hat[idx])
            total += np.trace(A @ A)
        else:
            total += ((phi[idx[0]] - phi_hat[idx[0]]) / phi_ref[idx[0]]) ** 2
    return 0.5 * gamma * total


def consistent_link() -> np.ndarray:
    """A random real body: J = ∫[x;1][x;1]ᵀ dm of four point masses, as 10 parameters."""
    points, masses = RNG.normal(size=(4, 3)) * 0.2, RNG.uniform(0.5, 2.0, 4)
    return parameters_of(sum(w * np.outer(np.append(p, 1), np.append(p, 1)) for p, w in zip(points, masses, strict=True)))


def random_phi() -> np.ndarray:
    return np.concatenate([consistent_link(), consistent_link(), RNG.uniform(0.05, 2.0, 2)])


def pullback(phi_ref: np.ndarray, gamma: float = 0.7, cls: type = Pullback) -> Pullback:
    return cls(gamma, LAYOUT, phi_ref)


def test_b_written_out_with_the_half_is_the_dual_of_j():
    for _ in range(3):
        v, b = RNG.normal(size=10), RNG.normal(size=10)
        assert np.trace(hand_J(v) @ hand_B(b)) == pytest.approx(v @ b, rel=1e-12)
        np.testing.assert_allclose(np.einsum("k,kab->ab", b, DUAL), hand_B(b), atol=1e-13)


def rate_is_hand_written(geometry: Pullback, phi_ref: np.ndarray) -> bool:
    """At three random states and b: the law's dφ̂/dt equals :func:`hand_rate` (x does not enter the rate)."""
    ok = True
    for _ in range(3):
        x, b = random_phi(), RNG.normal(size=phi_ref.size)
        ok &= np.allclose(geometry.rate(x, b), hand_rate(phi_ref, b, geometry.gamma), rtol=1e-10, atol=1e-12)
    return bool(ok)


def v_cancels_the_cross_term(geometry: Pullback, phi_ref: np.ndarray) -> bool:
    """V equals :func:`hand_V`, and along dφ̂/dt = rate(φ̂, b) its derivative is −φ̃ᵀb (φ̃ = φ − φ̂): V is quadratic in
    φ̂, so the central difference is exact to round-off."""
    phi, phi_hat, b = random_phi(), random_phi(), RNG.normal(size=phi_ref.size)
    dx, eps = geometry.rate(phi_hat, b), 1e-3
    dV = (geometry.lyapunov(phi_hat + eps * dx, phi) - geometry.lyapunov(phi_hat - eps * dx, phi)) / (2 * eps)
    return bool(np.isclose(geometry.lyapunov(phi_hat, phi), hand_V(phi_ref, phi_hat, phi, geometry.gamma), rtol=1e-10)
                and np.isclose(dV, -(phi - phi_hat) @ b, rtol=1e-8))


def test_the_rate_is_p0_b_p0_over_gamma_and_v_falls_by_phi_tilde_b():
    phi_ref = random_phi()
    law = pullback(phi_ref)
    assert rate_is_hand_written(law, phi_ref) and v_cancels_the_cross_term(law, phi_ref)
    phi = random_phi()
    assert law.lyapunov(phi, phi) == pytest.approx(0.0, abs=1e-14) and law.lyapunov(random_phi(), phi) > 0
    x = law.initial_state(phi)
    np.testing.assert_array_equal(law.estimate(x), phi)
    np.testing.assert_allclose(law.step(x, law.rate(x, phi), 0.01), phi + 0.01 * law.rate(x, phi), rtol=1e-15)


def test_it_is_the_euclidean_law_for_a_symmetric_positive_definite_block_gamma():
    """b ↦ dφ̂/dt is a constant Γ_P, symmetric positive definite, block-diagonal by parts, and V = ½ φ̃ᵀ Γ_P⁻¹ φ̃: the
    book's proofs with this Γ hold as written."""
    phi_ref = random_phi()
    law = pullback(phi_ref)
    Gamma = np.stack([law.rate(phi_ref, e) for e in np.eye(phi_ref.size)], axis=-1)
    np.testing.assert_allclose(Gamma, Gamma.T, rtol=1e-12, atol=1e-14)
    assert np.linalg.eigvalsh(Gamma).min() > 0
    assert np.all(Gamma[:10, 10:] == 0) and np.all(Gamma[10:20, 20:] == 0) and Gamma[20, 21] == 0
    phi, phi_hat = random_phi(), random_phi()
    error = phi - phi_hat
    by_gamma = 0.5 * error @ np.linalg.solve(Gamma, error)
    assert law.lyapunov(phi_hat, phi) == pytest.approx(by_gamma, rel=1e-6)  # Γ_P⁻¹ (ill-conditioned) costs digits


def natural_rate(phi_hat: np.ndarray, b: np.ndarray, gamma: float) -> np.ndarray:
    """The natural law's dφ̂/dt at φ̂, differenced through its log-Cholesky coordinates."""
    nat = Natural(gamma, LAYOUT)
    x = nat.initial_state(phi_hat)
    dx, eps = nat.rate(x, b), 1e-6
    return (nat.estimate(x + eps * dx) - nat.estimate(x - eps * dx)) / (2 * eps)


def test_at_p0_equal_to_the_estimate_the_rate_is_the_natural_laws():
    """Ĵ B Ĵ / γ at Ĵ = P₀ is P₀ B P₀ / γ (θ̂² b / γ at θ̂ = θ₀): the pullback law is the natural one frozen at P₀."""
    for _ in range(3):
        phi_hat, b = random_phi(), RNG.normal(size=22)
        np.testing.assert_allclose(pullback(phi_hat, 0.3).rate(phi_hat, b), natural_rate(phi_hat, b, 0.3), rtol=1e-7,
                                   atol=1e-10)


def test_v_is_the_natural_divergence_to_second_order_at_p0():
    """With P₀ = J: γ D(J‖Ĵ) = (γ/2) tr(J⁻¹ J̃ J⁻¹ J̃) + O(‖φ̃‖³), so their ratio tends to 1 as φ̂ → φ, by ε (φ̂ moved
    by ε in the metric's own scale: J̃ = ε L S Lᵀ with J = L Lᵀ and S symmetric of order 1, θ̃ = ε θ z)."""
    phi = random_phi()
    links = []
    for k in range(2):
        L, S = np.linalg.cholesky(hand_J(phi[10 * k:10 * k + 10])), RNG.normal(size=(4, 4))
        links.append(parameters_of(L @ (S + S.T) @ L.T))
    direction = np.concatenate([*links, phi[20:] * RNG.normal(size=2)])
    nat, law = Natural(0.7, LAYOUT), pullback(phi)

    def gap(eps: float) -> float:
        phi_hat = phi + eps * direction
        return abs(nat.lyapunov(nat.initial_state(phi_hat), phi) / law.lyapunov(phi_hat, phi) - 1)

    coarse, fine = gap(1e-3), gap(1e-4)
    assert coarse < 1e-2 and 5 < coarse / fine < 20


# One-line changes to the law: each must fail one of the two checks above.
def _drop_a_p0(self, x, b):
    P0, _, theta0 = self._reference
    B = np.einsum("...k,kab->...ab", self._split(b)[0], DUAL)
    return self._join(np, link_parameters(P0 @ B / self.gamma), theta0 * theta0 * self._split(b)[1] / self.gamma)


def _gamma_on_top(self, x, b):
    return Pullback.rate(self, x, b) * self.gamma ** 2  # P₀ B P₀ γ


def _no_half_in_b(self, x, b):  # the authors' b2B.m: b_h, not ½ b_h, in B's last column
    links, scalars = self._split(b)
    links = links.copy()
    links[..., 1:4] *= 2
    return Pullback.rate(self, x, self._join(np, links, scalars))


def _one_theta0(self, x, b):  # θ₀ b / γ for a scalar
    links, scalars = self._split(Pullback.rate(self, x, b))
    return self._join(np, links, scalars / self._reference[2])


def _p0_for_its_inverse(self, x, phi):
    P0, _, theta0 = self._reference
    links, scalars = self._split(phi - x)
    from robotadapt.robots.consistency import pseudo_inertia

    A = P0 @ pseudo_inertia(links)
    return 0.5 * self.gamma * ((A * np.swapaxes(A, -1, -2)).sum(axis=(-2, -1)).sum(-1) + (scalars ** 2 / theta0 ** 2).sum())


def _no_half_in_v(self, x, phi):
    return 2 * Pullback.lyapunov(self, x, phi)


@pytest.mark.parametrize("name, method, change", [
    ("rate", "rate", _drop_a_p0), ("rate", "rate", _gamma_on_top), ("rate", "rate", _no_half_in_b),
    ("rate", "rate", _one_theta0), ("V", "lyapunov", _p0_for_its_inverse), ("V", "lyapunov", _no_half_in_v)])
def test_a_one_line_change_to_the_law_fails_the_checks(name, method, change):
    mutant = dataclasses.make_dataclass("Mutant", [], bases=(Pullback,), frozen=True, eq=False,
                                        namespace={method: change})
    phi_ref = random_phi()
    law = pullback(phi_ref, cls=mutant)
    assert not (rate_is_hand_written(law, phi_ref) and v_cancels_the_cross_term(law, phi_ref)), name


def test_adaptive_computed_torque_and_dcal_move_their_own_b_by_p0_b_p0(tmp_path):
    """At a random state: the pullback ACT moves φ̂ by φ(P₀ B P₀/γ) with b = Wᵀ M̂⁻¹ E1 (6.2.19), DCAL with b = Y_dᵀ r
    (7.2.7), P₀ of the given phi_ref (not φ̂(0)); both b written here from the model."""
    from robotadapt.trajectories import sinusoid

    arm = urdf_arm(tmp_path)
    phi_hat0, phi_ref = 0.8 * arm.default_phi, 1.3 * arm.default_phi
    q, dq, ddq = RNG.normal(size=2), RNG.normal(size=2), RNG.normal(size=2)
    ref = sinusoid(2, amplitude=0.5, omega=2.0)(0.3)
    e, de = ref.q_des - q, ref.dq_des - dq
    kw = dict(adaptation="pullback", gamma=0.3, phi_hat0=phi_hat0, phi_ref=phi_ref)
    act = AdaptiveComputedTorque(arm, Kp=20.0, Kv=8.0, **kw)
    dcal = DCAL(arm, Kv=5.0, Kp=5.0, Ka=1.0, **kw)
    E1 = act.lyapunov_pair[0][2:, :] @ np.concatenate([e, de])
    b_act = arm.regressor(q, dq, dq, ddq).T @ np.linalg.solve(arm.mass_matrix(q, phi_hat0), E1)
    b_dcal = arm.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des).T @ (de + e)
    P0 = [hand_J(phi_ref[10 * k:10 * k + 10]) for k in range(2)]
    for dx, b in [(act.update(0.3, act.initial_state(q, dq), q, dq, ddq, ref), b_act),
                  (dcal(0.3, dcal.initial_state(q, dq), q, dq, ref)[1], b_dcal)]:
        expected = np.concatenate([parameters_of(P0[k] @ hand_B(b[10 * k:10 * k + 10]) @ P0[k] / 0.3) for k in range(2)])
        np.testing.assert_allclose(dx, expected, rtol=1e-10, atol=1e-12)
    with pytest.raises(ConfigError) as info:
        AdaptiveComputedTorque(arm, Kp=20.0, Kv=8.0, phi_min=0.0, **kw)
    assert info.value.field == "controller.phi_min" and "diagonal" in str(info.value)


def test_adaptive_computed_torque_keeps_dv_dt_minus_xqx_with_the_scalar_metric():
    """Example 6.2.2's arm (φ = the masses m1, m2: the scalar metric θ₀² b / γ) and gains: V = xᵀPx + γ Σ θ̃²/θ₀²
    (2 V_φ, (6.2.11)) against ∫ −xᵀQx by the trapezoid (O(dt²): 1e-3 of V(0) at dt = 1 ms)."""
    from scipy.integrate import cumulative_trapezoid

    sc = load("example-6.2.2", ['controller={kind="adaptive_computed_torque", Kp=125.0, Kv=50.0, adaptation='
                                '"pullback", gamma=5.0, phi_hat0=[0.85, 2.2]}', "simulation.t_final=1.0",
                                "simulation.backend=numpy"])
    res = sc.run()
    Q = sc.setup.controller.lyapunov_pair[1]
    x = np.concatenate([res.q_des - res.q, res.dq_des - res.dq], axis=-1)
    rate = -np.einsum("ti,ij,tj->t", x, Q, x)
    assert np.abs(res.phi_hat[-1] - res.phi_hat[0]).max() > 1e-3
    assert np.abs(res.V - res.V[0] - cumulative_trapezoid(rate, res.t, initial=0.0)).max() < 1e-3 * res.V[0]


# A spatial two-link DH arm with full inertias and viscous friction (22 parameters: two links of 10, fv1, fv2), the
# closed-form model (fast on numpy)
DH_ARM = """[robot]
kind = "dh"
model = "sympy"
[[robot.links]]
alpha = 1.5707963267948966
d = 0.3
m = 2.0
com = [0.0, -0.1, 0.02]
inertia = [0.03, 0.02, 0.025]
viscous = 0.3
[[robot.links]]
a = 0.4
m = 1.0
com = [-0.2, 0.01, 0.0]
inertia = [0.004, 0.02, 0.02]
viscous = 0.2
[plant]
q0 = [0.0, 0.0]
[trajectory]
kind = "sum_of_sines"
amplitude = 0.6
omega = [1.0, 2.3, 3.7]
[controller]
kind = "slotine_li"
Lam = 5.0
Kv = 2.0
adaptation = "pullback"
gamma = 0.1
phi_hat0 = {scale = 0.7}
[simulation]
t_final = 1.0
dt = 1e-3
"""


def dh_arm(tmp_path, *settings: str):
    path = tmp_path / "dh.toml"
    path.write_text(DH_ARM)
    return load(str(path), list(settings))


def test_v_never_rises_and_the_error_goes_to_zero_on_a_dh_arm(tmp_path):
    """20 s of Slotine–Li with the pullback law (continuous, RK4 at 1 ms, on C): V(t) − V(0) = ∫ −rᵀK_v r to the
    trapezoid's O(dt²) (2.3e-4 of V(0), most of it in the first steps, where rᵀK_v r is largest), V never rises, the
    estimate stays in the sublevel set V_φ ≤ V(0), and the RMS tracking error of the last 2 s is under a tenth of the
    first 2 s's."""
    from scipy.integrate import cumulative_trapezoid

    sc = dh_arm(tmp_path, "simulation.t_final=20.0", 'simulation.backend="c"')
    res = sc.run()
    ctrl = sc.setup.controller
    assert res.status.ok and type(ctrl.geometry) is Pullback and ctrl.model.param_names[-2:] == ("fv1", "fv2")
    rate = -np.einsum("ti,ij,tj->t", res.r, ctrl.Kv, res.r)
    assert np.abs(res.V - res.V[0] - cumulative_trapezoid(rate, res.t, initial=0.0)).max() < 1e-3 * res.V[0]
    assert np.diff(res.V).max() <= 1e-12 * res.V[0]
    phi = sc.setup.plant.phi
    assert np.all(ctrl.geometry.lyapunov(res.phi_hat, phi) <= res.V[0])
    e = res.q_des - res.q
    k = len(res.t) // 10
    first, last = np.sqrt((e[:k] ** 2).mean()), np.sqrt((e[-k:] ** 2).mean())
    print(f"V {res.V[0]:.4g} → {res.V[-1]:.4g}; RMS error {first:.3g} → {last:.3g} rad")
    assert last < first / 10


@pytest.mark.parametrize("sampled", [False, True])
def test_numpy_jax_and_c_give_the_same_run(tmp_path, sampled):
    """The DH arm for 0.3 s, continuous (RK4) or sampled at 1 kHz (the law's `step`, x + Ts·ẋ), on each backend."""
    pytest.importorskip("jax")
    from robotadapt.native.build import compiler

    backends = ["numpy", "jax"] + (["c"] if compiler() is not None else [])
    extra = ["simulation.control_period=1e-3"] if sampled else []
    runs = {b: dh_arm(tmp_path, "simulation.t_final=0.3", f'simulation.backend="{b}"', *extra).run() for b in backends}
    ref = runs["numpy"]
    assert np.abs(ref.phi_hat[-1] - ref.phi_hat[0]).max() > 1e-4
    for name, res in runs.items():
        for what in ("q", "dq", "phi_hat", "V"):
            np.testing.assert_allclose(getattr(res, what), getattr(ref, what), rtol=0, atol=1e-9, err_msg=name + what)


def test_a_batch_with_phi_hat0_per_run_takes_each_runs_own_p0():
    """φ₀ defaults to φ̂(0), which a batch varies per run: the batched runs equal the runs one by one."""
    from robotadapt.plant import Plant
    from robotadapt.robots import TwoLinkArm
    from robotadapt.sim import RK4, simulate, simulate_batch
    from robotadapt.trajectories import sinusoid

    arm, phi = TwoLinkArm(), np.array([0.8, 2.3])
    laws = [InertiaRelated(arm, 2.5, 10.0, adaptation="pullback", gamma=2.0, phi_hat0=p) for p in ([0.5, 1.0],
                                                                                                    [1.2, 3.0])]
    kw = dict(t_final=0.5, integrator=RK4(1e-3, backend="numpy"))
    batch = simulate_batch(Plant(arm, phi), laws, sinusoid(2), **kw)
    for i, law in enumerate(laws):
        one = simulate(Plant(arm, phi), law, sinusoid(2), **kw)
        np.testing.assert_allclose(batch.run(i).phi_hat, one.phi_hat, rtol=1e-12, atol=1e-14)
    assert not np.allclose(batch.run(0).phi_hat[-1] - [0.5, 1.0], batch.run(1).phi_hat[-1] - [1.2, 3.0])


def test_set_switches_the_panda_study_to_pullback_at_its_start():
    """`robotadapt run panda-natural --set controller.adaptation="pullback"`: γ is the file's, Γ unused, P₀ = J of
    the payload-free URDF estimate φ̂(0)."""
    ctrl = load("panda-natural", ['controller.adaptation="pullback"']).setup.controller
    assert type(ctrl.geometry) is Pullback and ctrl.gamma == 0.1 and ctrl.Gamma is None and ctrl.phi_ref is None
    np.testing.assert_array_equal(ctrl.geometry.phi_ref, ctrl.phi_hat0)


def bad_run(tmp_path, capsys, settings: list[str], scenario: str = "example-6.3.1") -> str:
    args = ["run", scenario, "--out", str(tmp_path / "out")]
    for s in settings:
        args += ["--set", s]
    assert main(args) == 2
    assert not (tmp_path / "out").exists()
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    return err


LAW = 'controller={kind="slotine_li", Lam=2.5, Kv=10, adaptation="pullback", gamma=5.0, '


@pytest.mark.parametrize("rest, field, words", [
    ("phi_hat0=[0.0, 1.0]}", "controller.phi_hat0", ["m1 = 0", "controller.phi_ref"]),
    ("phi_hat0=[0.5, 1.0], phi_ref=[1.0, -2.0]}", "controller.phi_ref", ["m2 = -2"]),
    ("phi_hat0=[0.5, 1.0], phi_ref=[1.0]}", "controller.phi_ref", ["2 numbers"]),
])
def test_an_inconsistent_or_malformed_reference_is_one_line_and_exit_2(tmp_path, capsys, rest, field, words):
    err = bad_run(tmp_path, capsys, [LAW + rest])
    assert err.startswith(f"error: {field}") or f"{field}:" in err, err
    assert all(w in err for w in words), err


def test_a_link_that_is_no_body_names_its_eigenvalue(tmp_path, capsys):
    path = tmp_path / "dh.toml"
    path.write_text(DH_ARM.replace("phi_hat0 = {scale = 0.7}", "phi_hat0 = {scale = -0.7}"))
    err = bad_run(tmp_path, capsys, [], str(path))
    assert "controller.phi_hat0" in err and "link 1" in err and "smallest eigenvalue" in err and "phi_ref" in err


def test_other_bad_input_and_what_is_allowed(tmp_path, capsys):
    err = bad_run(tmp_path, capsys, ['controller={kind="slotine_li", Lam=2.5, Kv=10, adaptation="pullback", '
                                     'phi_hat0=[0.5, 1.0]}'])
    assert "controller.gamma" in err and "required" in err and "P₀ B P₀" in err
    err = bad_run(tmp_path, capsys, ['controller={kind="slotine_li", Lam=2.5, Kv=10, Gamma=20, phi_ref=[1.0, 2.0]}'])
    assert "controller.phi_ref" in err and "pullback" in err
    # φ̂(0) = 0, the book's start, is no body, but a consistent φ₀ of its own makes the metric
    arm = load("example-6.3.1").setup.controller.model  # φ = (m1, m2)
    ctrl = InertiaRelated(arm, 2.5, 10.0, adaptation="pullback", gamma=5.0, phi_hat0=[0.0, 0.0], phi_ref=[1.0, 2.0])
    np.testing.assert_array_equal(ctrl.geometry.phi_ref, [1.0, 2.0])
    assert ctrl.geometry.rate(np.zeros(2), np.ones(2)) == pytest.approx([1 / 5, 4 / 5])
    none = InertiaRelated(arm, 2.5, 10.0, adaptation="none", phi_hat0=[0.0, 0.0], phi_ref=[1.0, -1.0])
    assert none.phi_ref is None  # "none" ignores every gain
