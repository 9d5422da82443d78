"""Torque-based disturbance rejection, `SignRobust` (spec §7.1–7.2): τ = τ_a + k_d sgn(r) around Slotine–Li.

At one instant: the switching term written out by hand, (6.7.6)–(6.7.7); dV/dt along the disturbed closed loop equals
(6.7.9) and is ≤ −rᵀK_v r once k_d > sup |T_d,i| (6.7.12). In closed loop: the book's Examples 6.7.1/6.7.2 and the
polar-arm Problems 6.7-1/6.7-2 (spec §10, §12), run for 6 s with RK4 at dt = 1e-3 (the shipped scenarios use 2e-4 over
20 s). Measured on the runs of the `run` helper below (rebound as defined there):

| run                       | max abs e over 4–6 s | rebound of V over 0–6 s (max V − running min) |
|---------------------------|----------------------|-----------------------------------------------|
| example-6.7.1 (k_d = 0)   | [2.5e-3, 1.9e-2] rad | 3.3e-2 (V(0) = 10.9)                           |
| example-6.7.2 (k_d = 2.2) | [1.1e-4, 2.6e-4] rad | 3.7e-4                                         |
| problem-6.7-1 (k_d = 0)   | [7.6e-2, 6.0e-2]     | 1.9e-2 (V(0) = 0.545)                          |
| problem-6.7-2 (k_d = 2.5) | [3.1e-4, 3.9e-4]     | 1.2e-3                                         |

With sgn switching RK4 integrates a discontinuous vector field. Over 0–4 s the rebound of V falls from 3.7e-4 to 1.5e-4 to
4.4e-5 for dt = 1e-3, 5e-4, 2e-4 (example-6.7.2; 1.2e-3, 5.1e-4, 7.7e-5 for problem-6.7-2), and the largest one-step
increase of V falls like dt² (1.3e-5, 3.1e-6, 4.8e-7). These increases are integrator error. Without k_d the rebound
comes from the disturbance's work ∫ rᵀT_d (6.7.2) and does not depend on the step (over 0–4 s: 3.2973e-2 at
both dt = 1e-3 and 2e-4 for example-6.7.1, 1.8435e-2 for problem-6.7-1).
"""

from __future__ import annotations

import re
from functools import cache

import numpy as np
import pytest
from scipy.integrate import trapezoid

from robotadapt.controllers import (
    PD,
    AdaptiveComputedTorque,
    InertiaRelated,
)
from robotadapt.controllers.robust import SignRobust
from robotadapt.plant import Plant, sinusoidal_disturbance
from robotadapt.robots import PolarArm, TwoLinkArm
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import Reference, sinusoid
from robotadapt.validation import ConfigError

BOOK = TwoLinkArm()
POLAR = PolarArm()
FULL = {"Lam": np.array([[2.0, 0.5], [0.5, 1.0]]), "Kv": np.array([[10.0, -3.0], [-3.0, 4.0]]),
        "Gamma": np.array([[20.0, 5.0], [5.0, 3.0]])}
REST = np.zeros(2)


def slotine_li(arm, gains=None):
    """Slotine–Li with full symmetric gains (they catch a transposed gain); Γ is p×p (p = 1 for the polar arm)."""
    gains = {**FULL, "Gamma": FULL["Gamma"][: arm.p, : arm.p]} if gains is None else gains
    return InertiaRelated(arm, Lam=gains["Lam"], Kv=gains["Kv"], Gamma=gains["Gamma"], phi_hat0=np.full(arm.p, 0.5))


def random_instant(rng, arm):
    """(x, q, dq, ref) at a random instant; the polar arm's extension stays in [0.3, 2] m (M singular at r = 0)."""
    q = rng.uniform(-np.pi, np.pi, 2)
    if isinstance(arm, PolarArm):
        q[1] = rng.uniform(0.3, 2.0)
    ref = Reference(q + rng.uniform(-0.5, 0.5, 2), rng.uniform(-2, 2, 2), rng.uniform(-3, 3, 2))
    return rng.uniform(-1.0, 3.0, arm.p), q, rng.uniform(-2, 2, 2), ref


def filtered_error(gains, q, dq, ref):
    """r = ė + Λe, e = q_d − q   (6.3.8)."""
    return (ref.dq_des - dq) + gains["Lam"] @ (ref.q_des - q)


ARMS = [pytest.param(BOOK, id="two-link"), pytest.param(POLAR, id="polar")]
SEEDS = range(5)


# --------------------------------------------------------------------------------------------------------------------
# At one instant


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_zero_kd_is_the_base_exactly(arm, seed):
    x, q, dq, ref = random_instant(np.random.default_rng(seed), arm)
    base = slotine_li(arm)
    ctrl = SignRobust(arm, base, kd=0.0)
    tau, dx = ctrl(0.4, x, q, dq, ref)
    tau_a, dx_a = base(0.4, x, q, dq, ref)
    np.testing.assert_array_equal(tau, tau_a)
    np.testing.assert_array_equal(dx, dx_a)
    # everything but the torque is the base's
    phi = np.full(arm.p, 1.3)
    assert ctrl.state_names == base.state_names
    np.testing.assert_array_equal(ctrl.initial_state(q, dq), base.initial_state(q, dq))
    np.testing.assert_array_equal(ctrl.phi_hat(x), base.phi_hat(x))
    np.testing.assert_array_equal(ctrl.filtered_error(0.4, x, q, dq, ref), base.filtered_error(0.4, x, q, dq, ref))
    assert ctrl.lyapunov(0.4, x, q, dq, ref, phi) == base.lyapunov(0.4, x, q, dq, ref, phi)
    for a, b in zip(ctrl.regressor(0.4, x, q, dq, ref), base.regressor(0.4, x, q, dq, ref), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("kd", [pytest.param(2.2, id="scalar"), pytest.param([3.0, 0.5], id="per-joint")])
@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_switching_term_is_kd_sgn_r(arm, kd, seed):
    """τ − τ_a = k_d sgn(r), sgn taken per component (6.7.6)–(6.7.7); the update is the base's, unchanged."""
    x, q, dq, ref = random_instant(np.random.default_rng(seed), arm)
    base = slotine_li(arm)
    tau_a, dx_a = base(1.0, x, q, dq, ref)
    r = filtered_error(FULL, q, dq, ref)
    tau, dx = SignRobust(arm, base, kd=kd)(1.0, x, q, dq, ref)
    expected = np.array([k * (1.0 if ri > 0 else -1.0) for k, ri in zip(np.broadcast_to(kd, 2), r, strict=True)])
    np.testing.assert_allclose(tau - tau_a, expected, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(dx, dx_a)


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_boundary_layer_replaces_sgn_by_saturation(arm, seed):
    """With ε > 0: τ − τ_a = k_d sat(r/ε), linear inside |r_i| < ε, ±k_d outside (spec §7.2)."""
    x, q, dq, ref = random_instant(np.random.default_rng(seed), arm)
    base = slotine_li(arm)
    r = filtered_error(FULL, q, dq, ref)
    eps = 1.5 * np.abs(r).min()  # one component inside the layer, the other (if larger) outside
    kd = np.array([2.0, 3.0])
    tau_a, _ = base(0.0, x, q, dq, ref)
    tau, _ = SignRobust(arm, base, kd=kd, boundary_layer=eps)(0.0, x, q, dq, ref)
    expected = np.array([k * (ri / eps if abs(ri) < eps else np.sign(ri)) for k, ri in zip(kd, r, strict=True)])
    np.testing.assert_allclose(tau - tau_a, expected, rtol=1e-12, atol=1e-12)
    inside = np.abs(r) < eps
    assert inside.any()


def test_sgn_of_zero_is_zero():
    """On the desired motion r = 0 and τ = τ_a; a component with r_i = 0 gets no switching torque."""
    base = slotine_li(BOOK, {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0})
    ctrl = SignRobust(BOOK, base, kd=2.2)
    ref = sinusoid(2)(0.7)
    x = np.array([0.3, 1.0])
    np.testing.assert_array_equal(ctrl(0.7, x, ref.q_des, ref.dq_des, ref)[0], base(0.7, x, ref.q_des, ref.dq_des, ref)[0])
    q, dq = ref.q_des + [0.0, 0.1], ref.dq_des + [0.0, -0.05]  # r = [0, −0.2]
    tau, _ = ctrl(0.7, x, q, dq, ref)
    np.testing.assert_allclose(tau - base(0.7, x, q, dq, ref)[0], [0.0, -2.2], rtol=0, atol=1e-12)


def test_batch_equals_stacked_single_calls():
    """Outputs are recomputed on the whole time axis at once: leading axes must give the single calls, sgn included."""
    ctrl = SignRobust(BOOK, slotine_li(BOOK), kd=[2.2, 1.0], boundary_layer=0.0)
    rng, lead = np.random.default_rng(7), (3, 4)
    x = rng.uniform(-1, 3, lead + (2,))
    q, dq = rng.uniform(-3, 3, lead + (2,)), rng.uniform(-2, 2, lead + (2,))
    ref = Reference(*(rng.uniform(-2, 2, lead + (2,)) for _ in range(3)))
    t = rng.uniform(0, 10, lead)
    tau, dx = ctrl(t, x, q, dq, ref)
    assert tau.shape == dx.shape == lead + (2,)
    for idx in np.ndindex(*lead):
        tau_i, dx_i = ctrl(t[idx], x[idx], q[idx], dq[idx], Reference(*(a[idx] for a in ref)))
        np.testing.assert_allclose(tau[idx], tau_i, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(dx[idx], dx_i, rtol=1e-13, atol=1e-12)


def dVdt(ctrl, plant, t, x, q, dq, ref, h=1e-3):
    """dV/dt along the disturbed closed loop at one instant: fourth-order central difference of V along the motion
    (q̇, q̈ from the plant under the controller's τ and T_d(t), dx, and the desired motion's q̇_d, q̈_d)."""
    tau, dx = ctrl(t, x, q, dq, ref)
    ddq = plant.acceleration(t, q, dq, tau)

    def V(s):
        ref_s = Reference(ref.q_des + s * ref.dq_des, ref.dq_des + s * ref.ddq_des, ref.ddq_des)
        return ctrl.lyapunov(t + s, x + s * dx, q + s * dq, dq + s * ddq, ref_s, plant.phi)

    return (-V(2 * h) + 8 * V(h) - 8 * V(-h) + V(-2 * h)) / (12 * h)


@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize("seed", SEEDS)
def test_lyapunov_derivative_with_disturbance(arm, seed):
    """(6.7.9) V̇ = −rᵀK_v r + rᵀT_d − Σ k_d,i |r_i| at any instant; with k_d,i > |T_d,i| it is ≤ −rᵀK_v r (6.7.12)."""
    rng = np.random.default_rng(100 + seed)
    x, q, dq, ref = random_instant(rng, arm)
    phi = rng.uniform(0.5, 3.0, arm.p)
    dist = sinusoidal_disturbance(2, amplitude=rng.uniform(0.5, 2.0, 2), omega=10.0, phase=rng.uniform(0, 6, 2),
                                  bias=rng.uniform(-1.0, 1.0, 2))
    plant, t = Plant(arm, phi, dist), 0.37
    Td = dist(t, q, dq)
    r = filtered_error(FULL, q, dq, ref)
    dissipation = r @ FULL["Kv"] @ r
    rates = {}
    for name, kd in (("none", np.zeros(2)), ("half", 0.5 * dist.bound), ("enough", 1.1 * dist.bound)):
        rates[name] = dVdt(SignRobust(arm, slotine_li(arm), kd=kd), plant, t, x, q, dq, ref)
        assert rates[name] == pytest.approx(-dissipation + r @ Td - kd @ np.abs(r), rel=1e-8, abs=1e-8)
    assert rates["enough"] <= -dissipation + 1e-8


def test_without_kd_the_disturbance_can_raise_v():
    """(6.7.5): near the desired motion, T_d = 2 sgn(r) makes V̇ = −rᵀK_v r + 2 Σ|r_i| > 0; k_d = 2.2 makes it < 0."""
    ref = sinusoid(2)(0.7)
    q, dq = ref.q_des - [0.01, -0.02], ref.dq_des - [0.03, 0.01]
    r = filtered_error({"Lam": 2.5 * np.eye(2)}, q, dq, ref)
    plant = Plant(BOOK, [0.8, 2.3], sinusoidal_disturbance(2, bias=2.0 * np.sign(r)))
    base = slotine_li(BOOK, {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0})
    x = np.array([0.5, 2.0])
    dissipation = 10.0 * r @ r
    assert dVdt(SignRobust(BOOK, base, kd=0.0), plant, 0.7, x, q, dq, ref) > 0.05
    rate = dVdt(SignRobust(BOOK, base, kd=2.2), plant, 0.7, x, q, dq, ref)
    assert rate == pytest.approx(-dissipation - 0.2 * np.abs(r).sum(), rel=1e-8)


def test_optional_parts_follow_the_base():
    """The wrapper has a Lyapunov function and a regressor (for the passivity integral) exactly when its base does: it
    forwards every hook of the law base to its base, explicitly, and answers `has` for it."""
    robust_sl = SignRobust(BOOK, slotine_li(BOOK), kd=1.0)
    assert robust_sl.has("lyapunov") and robust_sl.has("regressor")
    assert robust_sl.has("filtered_error") and not robust_sl.has("project") and not robust_sl.has("guard")
    robust_pd = SignRobust(BOOK, PD(BOOK, Kp=25.0, Kv=10.0, phi_hat0=np.zeros(2)), kd=1.0)
    assert robust_pd.has("filtered_error")
    assert not robust_pd.has("lyapunov") and not robust_pd.has("regressor")
    q, dq, ref = np.array([0.3, -0.2]), np.array([0.1, 0.4]), sinusoid(2)(0.5)
    assert robust_pd.lyapunov(0.5, np.zeros(0), q, dq, ref, np.array([0.8, 2.3])) is None  # the base's default
    phi = np.array([0.8, 2.3])
    x = robust_sl.initial_state(q, dq)
    np.testing.assert_array_equal(robust_sl.lyapunov(0.5, x, q, dq, ref, phi),
                                  robust_sl.base.lyapunov(0.5, x, q, dq, ref, phi))


# --------------------------------------------------------------------------------------------------------------------
# Validation


@pytest.mark.parametrize("bad", [-1.0, [2.0, -0.1], float("nan"), [1.0, float("inf")], [1.0, 2.0, 3.0], "2.2", True],
                         ids=["negative", "negative-entry", "nan", "inf", "wrong-length", "string", "bool"])
def test_bad_kd_is_rejected_naming_the_field(bad):
    with pytest.raises(ConfigError, match=r"^controller\.kd: ") as info:
        SignRobust(BOOK, slotine_li(BOOK), kd=bad)
    assert info.value.field == "controller.kd"


@pytest.mark.parametrize("bad", [-0.01, float("nan"), [0.1, 0.1]], ids=["negative", "nan", "list"])
def test_bad_boundary_layer_is_rejected_naming_the_field(bad):
    with pytest.raises(ConfigError, match=r"^controller\.boundary_layer: "):
        SignRobust(BOOK, slotine_li(BOOK), kd=2.0, boundary_layer=bad)


def test_base_must_match_the_model_and_have_a_filtered_error():
    with pytest.raises(ConfigError, match=r"^controller\.base: .*differs"):
        SignRobust(POLAR, slotine_li(BOOK), kd=2.0)
    with pytest.raises(ConfigError, match=r"^controller\.base: .*filtered error"):
        SignRobust(BOOK, sinusoid(2), kd=2.0)
    # a law that needs q̈ (Table 6.2.1) has no single map (τ, dx) to add the sign term to
    needs_ddq = AdaptiveComputedTorque(BOOK, Kp=125, Kv=50, Gamma=500, phi_hat0=[0.85, 2.2])
    with pytest.raises(ConfigError, match=r"^controller\.base: .*acceleration"):
        SignRobust(BOOK, needs_ddq, kd=2.0)
    # another model object with the same joints and parameters is fine (the scenario builder passes the same one)
    assert SignRobust(TwoLinkArm(l1=0.7), slotine_li(BOOK), kd=2.0).base.model is BOOK


@pytest.mark.parametrize(("override", "field"), [("controller.kd=-1.0", "controller.kd"),
                                                 ("controller.kd=nan", "controller.kd"),
                                                 ("controller.boundary_layer=-0.1", "controller.boundary_layer")])
def test_scenario_errors_name_the_field(override, field):
    with pytest.raises(ConfigError, match=rf"^{re.escape(field)}: "):
        load("example-6.7.2", [override])


@pytest.mark.parametrize(("name", "kd", "bound"), [("example-6.7.2", 2.2, [2.0, 2.0]), ("problem-6.7-2", 2.5, [2.0, 1.0])])
def test_shipped_scenarios_satisfy_the_gain_condition(name, kd, bound):
    """The builder wraps Slotine–Li on the robot's own model, and k_d > max_i sup |T_d,i|   (6.7.8)."""
    setup = load(name).setup
    ctrl = setup.controller
    assert isinstance(ctrl, SignRobust) and isinstance(ctrl.base, InertiaRelated)
    assert ctrl.base.model is ctrl.model
    np.testing.assert_array_equal(ctrl.kd, [kd, kd])
    np.testing.assert_array_equal(setup.plant.disturbance.bound, bound)
    assert ctrl.boundary_layer == 0.0 and np.all(ctrl.kd > setup.plant.disturbance.bound)


# --------------------------------------------------------------------------------------------------------------------
# Closed loop: Examples 6.7.1 / 6.7.2 and Problems 6.7-1 / 6.7-2


@cache
def run(name, *overrides):
    scenario = load(name, ["simulation.t_final=6", "simulation.dt=1e-3", "simulation.log_every=1", *overrides])
    return scenario, scenario.run()


def late(res, start=4.0):
    return res.t >= start


def rebound(V):
    """How far V climbs above its running minimum: zero for a non-increasing V."""
    return float(np.max(V - np.minimum.accumulate(V)))


PAIRS = [pytest.param("example-6.7.1", "example-6.7.2", 1e-2, id="two-link-sin-disturbance"),
         pytest.param("problem-6.7-1", "problem-6.7-2", 3e-2, id="polar-constant-disturbance")]


@pytest.mark.parametrize(("plain", "robust", "residual"), PAIRS)
def test_kd_sgn_r_drives_the_error_to_zero_and_plain_slotine_li_keeps_a_residual(plain, robust, residual):
    """Examples 6.7.1/6.7.2, Problems 6.7-1/6.7-2: over 4–6 s, max |e| stays above `residual` without k_d and falls
    below 1e-3 (the RK4 chattering band at dt = 1e-3) with k_d > max |T_d|."""
    _, res0 = run(plain)
    _, res1 = run(robust)
    assert res0.ok and res1.ok
    e0, e1 = np.abs(res0.e[late(res0)]).max(axis=0), np.abs(res1.e[late(res1)]).max(axis=0)
    assert e0.max() > residual
    assert np.all(e1 < 1e-3)
    assert e0.max() > 20 * e1.max()


@pytest.mark.parametrize(("plain", "robust", "residual"), PAIRS)
def test_lyapunov_is_non_increasing_with_kd_and_rises_without(plain, robust, residual):
    """With k_d: V's rebound is integrator error (< 2e-3, see the module table); without: ≥ 1e-2 and 10 times more."""
    _, res0 = run(plain)
    _, res1 = run(robust)
    assert rebound(res1.V) < 2e-3
    assert rebound(res0.V) > max(1e-2, 10 * rebound(res1.V))


@pytest.mark.parametrize("plain", ["example-6.7.1", "problem-6.7-1"])
def test_without_kd_the_disturbance_work_balances_v(plain):
    """(6.7.2) integrated over 2–6 s: V(6) − V(2) = −∫ rᵀK_v r + ∫ rᵀT_d, and the disturbance's work is positive."""
    scenario, res = run(plain)
    w = res.t >= 2.0
    t, r = res.t[w], res.r[w]
    Kv = scenario.setup.controller.Kv
    Td = scenario.setup.plant.disturbance(t, res.q[w], res.dq[w])
    work = trapezoid((r * Td).sum(axis=-1), t)
    dissipated = trapezoid(np.einsum("ti,ij,tj->t", r, Kv, r), t)
    assert res.V[-1] - res.V[w][0] == pytest.approx(work - dissipated, abs=1e-4)
    assert work > 0.1


def test_lyapunov_rebound_with_sgn_is_integrator_error():
    """Example 6.7.2 over 4 s: V's rebound shrinks like dt (3.7e-4 at 1e-3, 4.4e-5 at 2e-4): numerical, not physical."""
    coarse = run("example-6.7.2", "simulation.t_final=4")[1]
    fine = run("example-6.7.2", "simulation.t_final=4", "simulation.dt=2e-4")[1]
    assert rebound(fine.V) < rebound(coarse.V) / 4


def test_boundary_layer_gives_a_residual_set_and_no_chattering():
    """Problem 6.7-2 with ε = 0.05 (constant T_d): over 3–6 s |r_i| ≤ ε but r does not vanish; the torque's total
    variation falls by more than 10×; and V̇ ≤ −rᵀK_v r + ε Σ_i sup|T_d,i|²/(4 k_d,i) integrated over 3–6 s holds."""
    eps = 0.05
    scenario, res = run("problem-6.7-2", f"controller.boundary_layer={eps}")
    _, sgn = run("problem-6.7-2")
    ctrl, bound = scenario.setup.controller, scenario.setup.plant.disturbance.bound
    w = late(res, 3.0)
    r_max = np.abs(res.r[w]).max(axis=0)
    assert np.all(r_max <= eps) and np.all(r_max > 0.2 * eps)

    def variation(result):
        return np.abs(np.diff(result.tau[late(result, 3.0)], axis=0)).sum()

    assert variation(res) < variation(sgn) / 10
    t, r = res.t[w], res.r[w]
    dissipated = trapezoid(np.einsum("ti,ij,tj->t", r, ctrl.base.Kv, r), t)
    assert dissipated <= res.V[w][0] - res.V[-1] + (t[-1] - t[0]) * eps * np.sum(bound**2 / (4 * ctrl.kd))


def test_wrapper_reports_the_landau_pi_estimate_and_its_passivity_integral():
    """Around a passivity controller with Landau's PI law, φ̂ = φ̂_I + F_p Zᵀr (6.4.20) is what the torque uses: the
    wrapper's φ̂ is the base's, computed here by hand, and its passivity integral (6.4.4) ∫ −rᵀZ(φ − φ̂) obeys the law's
    identity (docs/laws.md#landau-pi): with y = Zᵀr and φ̃_I = φ − φ̂_I, −yᵀφ̃ = d/dt(½φ̃_Iᵀ K_I⁻¹ φ̃_I) + yᵀF_p y, so
    Π(t₂) − Π(t₁) = [½φ̃_Iᵀ K_I⁻¹ φ̃_I]_{t₁}^{t₂} + ∫_{t₁}^{t₂} yᵀF_p y, the last by Simpson on 1 ms samples past the
    ~3 ms F_p transient at t = 0 (smooth there). The integral is the loop's at every RK4 step, the same at any logging
    rate. With k_d = 0 the wrapped run is the base's run."""
    from scipy.integrate import simpson

    from robotadapt.controllers.adaptation import LandauPI
    from robotadapt.controllers.passivity import PassivityBased, pid_servo
    from robotadapt.sim import RK4, simulate

    K_I, F_P = np.array([[15.0, 2.0], [2.0, 6.0]]), np.array([[2.0, 0.3], [0.3, 1.0]])
    base = PassivityBased(BOOK, pid_servo(2, FULL["Lam"], np.eye(2)), FULL["Kv"], LandauPI(2, K_I, F_P), np.zeros(2))
    wrapped = SignRobust(BOOK, base, kd=0.0)
    assert wrapped.has("phi_hat_at")
    phi = np.array([0.8, 2.3])
    plant, traj = Plant(BOOK, phi), sinusoid(2)
    runs = [simulate(plant, c, traj, t_final=2.0, integrator=RK4(1e-3), log_every=k) for c, k in ((base, 10),
                                                                                                   (wrapped, 1))]
    res = runs[1]
    Z, r = base.regressor(res.t, res.x, res.q, res.dq, traj(res.t))
    y = np.einsum("tkj,tk->tj", Z, r)
    phi_hat = res.x[:, -2:] + y @ F_P.T
    np.testing.assert_allclose(res.phi_hat, phi_hat, rtol=1e-12, atol=1e-12)
    tilde_I = phi - res.x[:, -2:]
    V_I = 0.5 * np.einsum("ti,ij,tj->t", tilde_I, np.linalg.inv(K_I), tilde_I)
    one = np.searchsorted(res.t, 0.1)
    feedthrough = simpson(np.einsum("ti,ij,tj->t", y[one:], F_P, y[one:]), x=res.t[one:])
    assert res.passivity[-1] - res.passivity[one] == pytest.approx(V_I[-1] - V_I[one] + feedthrough, abs=2e-9)
    assert res.passivity[0] == 0.0 and np.all(res.passivity >= V_I - V_I[0] - 1e-12)
    for name in ("phi_hat", "passivity", "tau", "q"):
        np.testing.assert_allclose(getattr(res, name)[::10], getattr(runs[0], name), rtol=1e-13, atol=1e-13,
                                   err_msg=name)
