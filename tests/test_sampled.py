"""Sampled-data control (`robotadapt.sim.Sampled`, `robotadapt.sim.sampled`): the zero-order hold against the exact
discretization of a linear loop, the discrete rules of the controller's state, the Ts → 0 limit (first order), the
stability limit of a sampled loop that is stable in continuous time, and every controller family at its ticks.

The linear reference is the one-link arm m q̈ + b q̇ = u (φ = [m, b], spec §1.4) under PD, u_k = K_p e_k + K_v ė_k held
over [kTs, (k+1)Ts): with x = [q, q̇], x_{k+1} = A_d x_k + B_d u_k, where [[A_d, B_d], [0, 1]] = expm([[A, B], [0, 0]] Ts)
(the exact zero-order-hold discretization). Regulating to q_d = 0, u_k = −K x_k and x_{k+1} = (A_d − B_d K) x_k: the
sampled loop is stable exactly while the spectral radius of A_d − B_d K is below 1, which fails for Ts above a limit Ts*
although the continuous loop is stable for every positive gain.
"""

from __future__ import annotations

import contextlib
import io
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from scipy.linalg import expm

from robotadapt.cli import main
from robotadapt.controllers import PD, InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import OneLinkArm, TwoLinkArm
from robotadapt.sim import RK4, Sampled, simulate
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import constant, sinusoid
from robotadapt.validation import ConfigError

M, B, KP, KV = 1.0, 1.0, 25.0, 10.0


def zoh(Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """(A_d, B_d) of m q̈ + b q̇ = u, x = [q, q̇], held u (module docstring)."""
    F = np.zeros((3, 3))
    F[0, 1], F[1, 1], F[1, 2] = 1.0, -B / M, 1.0 / M
    E = expm(F * Ts)
    return E[:2, :2], E[:2, 2]


def radius(Ts: float) -> float:
    A_d, B_d = zoh(Ts)
    return float(np.max(np.abs(np.linalg.eigvals(A_d - np.outer(B_d, [KP, KV])))))


def stability_limit() -> float:
    """Ts* where the spectral radius of the sampled PD loop crosses 1 (bisection; it rises through 1 once here)."""
    lo, hi = 1e-3, 1.0
    assert radius(lo) < 1 < radius(hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if radius(mid) < 1 else (lo, mid)
    return lo


def one_link(Ts: float, t_final: float, **kw: Any):
    model = OneLinkArm()
    return simulate(Plant(model, [M, B]), PD(model, Kp=KP, Kv=KV, phi_hat0=[0.0, 0.0]), constant(1, 0.0),
                    t_final=t_final, integrator=Sampled(Ts, dt=Ts / 50), q0=[0.3], dq0=[-1.0], **kw)


def test_the_plant_under_a_held_torque_is_the_exact_zero_order_hold_discretization():
    """Logged ticks obey x_{k+1} = A_d x_k + B_d u_k with the logged (applied) u_k, to RK4's error on 50 sub-steps; and
    u_k is the PD law at the sampled x_k: the controller runs only at the ticks and its torque is held between them."""
    Ts = 0.05
    res = one_link(Ts, 2.0)
    assert res.ok
    np.testing.assert_allclose(res.t, Ts * np.arange(41), rtol=0, atol=1e-12)
    A_d, B_d = zoh(Ts)
    x = np.stack([res.q[:, 0], res.dq[:, 0]], axis=1)
    predicted = x[:-1] @ A_d.T + np.outer(res.tau[:-1, 0], B_d)
    np.testing.assert_allclose(x[1:], predicted, rtol=0, atol=1e-10)
    np.testing.assert_allclose(res.tau[:, 0], -KP * x[:, 0] - KV * x[:, 1], rtol=1e-13, atol=1e-13)


def test_a_loop_stable_in_continuous_time_goes_unstable_sampled_too_slowly_and_the_guard_says_so():
    """The documented case: PD on the one-link arm, stable for any positive gains in continuous time. Sampled below
    the limit Ts* (0.199 s here) the error decays at the spectral radius; above it the state grows until the divergence
    guard stops the run, keeping the samples before."""
    limit = stability_limit()
    assert 0.15 < limit < 0.25  # 0.199 s for m = b = 1, K_p = 25, K_v = 10; ρ = 0.77 at 0.9 Ts*, 1.24 at 1.1 Ts*
    model = OneLinkArm()
    continuous = simulate(Plant(model, [M, B]), PD(model, Kp=KP, Kv=KV, phi_hat0=[0.0, 0.0]), constant(1, 0.0),
                          t_final=5.0, integrator=RK4(1e-2), q0=[0.3], dq0=[-1.0])
    assert continuous.ok and abs(continuous.q[-1, 0]) < 1e-6  # poles −3.3, −7.7

    stable = one_link(0.9 * limit, 100 * limit, max_state=1e3)
    assert stable.ok
    norms = np.hypot(stable.q[:, 0], stable.dq[:, 0])
    assert norms[-1] < radius(0.9 * limit) ** 60  # decays like ρ^k, ρ < 1

    unstable = one_link(1.1 * limit, 200 * limit, max_state=1e3)
    assert unstable.status.startswith("diverged at t=") and "exceeded 1000" in unstable.status
    assert unstable.t[-1] < 200 * limit and np.all(np.isfinite(unstable.q))
    assert np.abs(unstable.q).max() > 10  # it grew before the guard stopped it


def test_example_6_3_1_sampled_at_20_ms_diverges_and_the_cli_reports_it(tmp_path):
    """Slotine–Li on the two-link arm (digital-6.3.1's loop) is fine at 10 ms and diverges at 20 ms; `robotadapt run`
    keeps the partial result, names the time and the reason, and exits 1."""
    assert load("digital-6.3.1", ["simulation.control_period=0.01", "simulation.t_final=3"]).run().ok
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["run", "example-6.3.1", "--set", "simulation.control_period=0.02", "--t-final", "3",
                     "--no-plots", "--out", str(tmp_path)])
    assert code == 1
    assert "diverged at t=1.12 s: non-finite state" in out.getvalue()
    assert np.isfinite(np.load(tmp_path / "result.npz")["q"]).all()


@pytest.mark.parametrize("scenario", ["example-6.3.1", "problem-6.4-1"])
def test_sampled_runs_tend_to_the_continuous_run_to_first_order(scenario):
    """Max over [0, 0.5] s of |q − q_continuous| and |φ̂ − φ̂_continuous| at the ticks falls like Ts (a fitted log-log
    slope of 1 ± 0.15), for Slotine–Li (state φ̂) with forward Euler and the PID-servo passivity law (state φ̂ and
    the servo's integral) with the hold rule. The continuous reference is RK4 at 0.125 ms (its error ~1e-12)."""
    s = load(scenario).setup
    ref = simulate(s.plant, s.controller, s.trajectory, t_final=0.5, integrator=RK4(1.25e-4), q0=s.q0, dq0=s.dq0)
    rule = "euler" if scenario == "example-6.3.1" else "hold"
    periods = np.array([2e-3, 1e-3, 5e-4, 2.5e-4])
    errors = []
    for Ts in periods:
        res = simulate(s.plant, s.controller, s.trajectory, t_final=0.5, integrator=Sampled(Ts, Ts / 2, rule),
                       q0=s.q0, dq0=s.dq0)
        k = np.rint(res.t / 1.25e-4).astype(int)
        errors.append(max(np.abs(res.q - ref.q[k]).max(), np.abs(res.phi_hat - ref.phi_hat[k]).max()))
    slope = np.polyfit(np.log(periods), np.log(errors), 1)[0]
    assert 0.85 < slope < 1.15, (errors, slope)


@dataclass(frozen=True, eq=False)
class FilteredPD:
    """Test double: PD plus a first-order filter state, dx/dt = −a x + e (x does not enter the torque)."""

    model: Any
    a: float = 4.0

    @property
    def state_names(self) -> tuple[str, ...]:
        return ("xf",)

    def initial_state(self, q0: Any, dq0: Any) -> np.ndarray:
        return np.zeros(1)

    def phi_hat(self, x: Any) -> Any:
        return x[..., :0]

    def __call__(self, t: Any, x: Any, q: Any, dq: Any, ref: Any) -> tuple[Any, Any]:
        e, de = ref.q_des - q, ref.dq_des - dq
        return KP * e + KV * de, -self.a * x + e


@pytest.mark.parametrize("rule", ["euler", "hold"])
def test_the_discrete_rules_of_the_controller_state(rule):
    """With e_k the sampled error: "euler" gives x_{k+1} = x_k + Ts(−a x_k + e_k) to round-off; "hold" gives the exact
    discretization with e held, x_{k+1} = e^{−a Ts} x_k + (1 − e^{−a Ts}) e_k / a, to RK4's error on the sub-steps."""
    Ts, a = 0.02, 4.0
    model = OneLinkArm()
    res = simulate(Plant(model, [M, B]), FilteredPD(model, a), sinusoid(1, amplitude=0.5, omega=2.0), t_final=1.0,
                   integrator=Sampled(Ts, Ts / 10, rule), q0=[0.3])
    x, e = res.x[:, 0], res.e[:, 0]
    if rule == "euler":
        np.testing.assert_allclose(x[1:], x[:-1] + Ts * (-a * x[:-1] + e[:-1]), rtol=0, atol=1e-15)
    else:
        decay = math.exp(-a * Ts)
        np.testing.assert_allclose(x[1:], decay * x[:-1] + (1 - decay) * e[:-1] / a, rtol=0, atol=1e-11)


def test_hold_is_euler_when_the_state_derivative_does_not_depend_on_the_state():
    """Slotine–Li's dφ̂/dt = Γ Yᵀ r does not depend on φ̂: both rules give the same run (to round-off of the sums)."""
    arm = TwoLinkArm()
    ctrl = InertiaRelated(arm, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    runs = [simulate(Plant(arm, [0.8, 2.3]), ctrl, sinusoid(2), t_final=0.3, integrator=Sampled(2e-3, 1e-3, rule))
            for rule in ("euler", "hold")]
    np.testing.assert_allclose(runs[0].x, runs[1].x, rtol=1e-12, atol=1e-12)


def test_logging_every_few_ticks_keeps_the_same_samples():
    s = load("example-6.3.1").setup
    kw = dict(t_final=0.2, integrator=Sampled(2e-3), q0=s.q0, dq0=s.dq0)
    every = simulate(s.plant, s.controller, s.trajectory, **kw)
    fifth = simulate(s.plant, s.controller, s.trajectory, log_every=5, **kw)
    np.testing.assert_array_equal(fifth.t, every.t[::5])
    for name in ("q", "dq", "x", "tau"):
        np.testing.assert_array_equal(getattr(fifth, name), getattr(every, name)[::5])
    assert every.info["sampling"] == {"control_period": 2e-3, "dt": 1e-3, "substeps": 2, "discretization": "euler"}


# Every controller family at its ticks (Ts = the scenario's step), against its own continuous run over 1 s: they differ
# by O(Ts); the bound is about twice the difference measured here (the fast adaptive transients of 6.3.1 and 6.4-1 the most)
FAMILIES = [
    ("example-6.3.1", [], 0.1),                                                      # Slotine–Li
    ("example-6.2.2", ["controller.phi_min=0.1", "controller.phi_max=10"], 0.01),    # needs q̈; projection
    ("problem-6.4-1", [], 0.1),                                                      # passivity, PID servo
    ("example-6.6.3", [], 1e-3),                                                     # composite: filters and P
    ("example-6.7.2", [], 0.02),                                                     # k_d sgn(r)
    ("example-7.2.1", [], 0.01),                                                     # DCAL, Y_d tabulated
    ("example-7.2.2", [], 1e-3),                                                     # repetitive: delay line
]


@pytest.mark.parametrize(("name", "sets", "tolerance"), FAMILIES, ids=[f[0] for f in FAMILIES])
def test_every_controller_family_runs_sampled_close_to_its_continuous_run(name, sets, tolerance):
    scenario = load(name, [*sets, "simulation.t_final=1.0"])
    s = scenario.setup
    continuous = scenario.run()
    sampled = simulate(s.plant, s.controller, s.trajectory, t_final=1.0, integrator=Sampled(s.integrator.dt),
                       q0=s.q0, dq0=s.dq0, log_every=s.log_every)
    assert continuous.ok and sampled.ok, sampled.status
    np.testing.assert_allclose(sampled.t, continuous.t, rtol=0, atol=1e-12)
    assert np.abs(sampled.q - continuous.q).max() < tolerance
    if name == "example-6.2.2":  # the projection holds at every tick
        assert sampled.phi_hat.min() >= 0.1 and sampled.phi_hat.max() <= 10


def test_a_delay_line_counts_control_ticks():
    """The repetitive law's period must be a whole number of control periods; the error names the control period."""
    s = load("example-7.2.2").setup
    with pytest.raises(ConfigError) as info:
        simulate(s.plant, s.controller, s.trajectory, t_final=1.0, integrator=Sampled(1e-3))
    assert info.value.field == "simulation.control_period"


@pytest.mark.parametrize(("kw", "field"), [
    (dict(control_period=0.0), "simulation.control_period"),
    (dict(control_period=1e-3, dt=2e-3), "simulation.dt"),
    (dict(control_period=1e-3, dt=3e-4), "simulation.dt"),
    (dict(control_period=1e-3, discretization="tustin"), "simulation.discretization"),
    (dict(control_period=1.0, dt=1e-7), "simulation.dt"),  # 10⁷ plant steps per tick
])
def test_sampled_rejects_bad_options(kw, field):
    with pytest.raises(ConfigError) as info:
        Sampled(**kw)
    assert info.value.field == field


def test_sampled_steps_default_to_the_largest_divisor_of_the_period_up_to_1_ms():
    assert (Sampled(1e-4).dt, Sampled(1e-4).substeps) == (1e-4, 1)
    assert Sampled(5e-3).substeps == 5 and Sampled(1.5e-3).substeps == 2
    assert Sampled(1e-3, 2.5e-4).substeps == 4


@pytest.mark.parametrize(("sets", "field"), [
    (["simulation.control_period=1e-3", "simulation.method='RK45'"], "simulation.method"),
    (["simulation.control_period=1e-3", "simulation.dt=3e-4"], "simulation.dt"),
    (["simulation.control_period=20"], "simulation.control_period"),
    (["simulation.discretization='hold'"], "simulation.discretization"),
    (["simulation.control_period=1e-3", "simulation.rtol=1e-6"], "simulation.rtol"),
])
def test_scenario_sampling_keys_are_checked(sets, field):
    with pytest.raises(ConfigError) as info:
        load("example-6.3.1", sets)
    assert info.value.field == field


def test_the_controller_runs_only_at_the_ticks():
    """A recording test double sees exactly the instants k·Ts, once each, with the "euler" rule."""
    seen: list[float] = []
    arm = TwoLinkArm()
    inner = InertiaRelated(arm, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])

    @dataclass(frozen=True, eq=False)
    class Recording:
        model: Any = arm
        state_names: tuple[str, ...] = inner.state_names

        def initial_state(self, q0: Any, dq0: Any) -> Any:
            return inner.initial_state(q0, dq0)

        def phi_hat(self, x: Any) -> Any:
            return x

        def __call__(self, t: Any, x: Any, q: Any, dq: Any, ref: Any) -> Any:
            if np.ndim(t) == 0:  # the recomputed outputs after the run pass every logged instant at once
                seen.append(float(t))
            return inner(t, x, q, dq, ref)

    simulate(Plant(arm, [0.8, 2.3]), Recording(), sinusoid(2), t_final=0.1, integrator=Sampled(1e-2, 1e-3))
    np.testing.assert_allclose(seen, 1e-2 * np.arange(11), rtol=0, atol=1e-15)


@pytest.mark.slow
def test_digital_6_3_1_study_fails_between_10_and_15_ms():
    """The study of the scenario: every period up to 10 ms tracks (final |e| < 1e-3), 15 ms and 20 ms diverge."""
    from robotadapt.studies.study import run_study

    runs = run_study(load("digital-6.3.1"))["simulation.control_period"]
    for run in runs:
        if run.value <= 1e-2:
            assert run.result.ok and np.abs(run.result.e[-1]).max() < 1e-3, run.value
        else:
            assert run.result.status.startswith("diverged at t="), run.value
