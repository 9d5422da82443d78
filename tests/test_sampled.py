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
from robotadapt.controllers import PD, InertiaRelated, Law
from robotadapt.plant import Plant
from robotadapt.plant.actuators import Actuator, DCMotor
from robotadapt.plant.sensors import Sensor
from robotadapt.plant.unmodeled import ElasticJoint
from robotadapt.robots import OneLinkArm, TwoLinkArm
from robotadapt.sim import RK4, Sampled, simulate
from robotadapt.studies.scenarios import available, load
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
class FilteredPD(Law):
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
    class Recording(Law):
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


# -- the compiled loop (robotadapt.sim.driver): the same tick under jax.jit and lax.scan equals numpy ----------------

def _forced(original: Any, backend: str) -> Any:
    """`sampled.integrate` with its backend fixed, whatever `simulate` asks for."""
    def integrate(*args: Any, **kw: Any) -> Any:
        kw.pop("backend", None)
        return original(*args[:9], backend=backend, **kw)

    return integrate


def both(monkeypatch: pytest.MonkeyPatch, run: Any) -> tuple[Any, Any]:
    """`run()` (a call of simulate with a Sampled integrator) stepped by numpy, then compiled by JAX; the compiled
    driver must have been taken exactly once."""
    pytest.importorskip("jax", reason="the compiled loop needs JAX")
    from robotadapt.sim import driver, sampled

    calls: list[int] = []
    compiled = driver._scan

    def counting(*args: Any, **kw: Any) -> Any:
        calls.append(1)
        return compiled(*args, **kw)

    original = sampled.integrate
    monkeypatch.setattr(driver, "_scan", counting)
    monkeypatch.setattr(sampled, "integrate", _forced(original, "numpy"))
    a = run()
    monkeypatch.setattr(sampled, "integrate", _forced(original, "jax"))
    b = run()
    monkeypatch.setattr(sampled, "integrate", original)
    assert calls == [1]
    return a, b


def assert_same_run(a: Any, b: Any, rtol: float = 1e-9) -> None:
    """Same status, same logged instants, every logged array equal to `rtol` of its largest entry (at least 1)."""
    assert b.status == a.status
    np.testing.assert_array_equal(b.t, a.t)
    A, B = a.arrays(), b.arrays()
    assert A.keys() == B.keys()
    for name, value in A.items():
        if np.issubdtype(value.dtype, np.floating):
            scale = max(1.0, float(np.max(np.abs(value), initial=0.0, where=np.isfinite(value))))
            np.testing.assert_allclose(B[name], value, rtol=0, atol=rtol * scale, err_msg=name)
        else:
            np.testing.assert_array_equal(B[name], value, err_msg=name)


def _sampled_scenarios() -> list[str]:
    return [name for name in available() if "control_period" in load(name).data["simulation"]]


def test_the_packaged_sampled_scenarios_are_found():
    assert {"digital-6.3.1", "noise-6.3.1"} <= set(_sampled_scenarios())


@pytest.mark.parametrize("name", _sampled_scenarios())
def test_every_packaged_sampled_scenario_compiles_to_the_numpy_run(monkeypatch, name):
    a, b = both(monkeypatch, lambda: load(name, ["simulation.t_final=0.5"]).run())
    assert a.ok
    assert_same_run(a, b)


def _effects(t_final: float = 0.5, integrator: Any = None, **parts: Any) -> Any:
    arm = TwoLinkArm()
    ctrl = InertiaRelated(arm, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    return lambda: simulate(Plant(arm, [0.8, 2.3], **parts), ctrl, sinusoid(2), t_final=t_final,
                            integrator=integrator or Sampled(1e-3))


MOTOR = dict(R=1.2, L=2e-3, k_t=0.08, k_b=0.08, gear_ratio=60.0, current_gain=25.0)
EFFECTS = [
    pytest.param(_effects(actuator=Actuator(2, torque_limit=100.0, torque_rate_limit=2000.0, delay_samples=2)),
                 id="limit-rate-delay"),
    pytest.param(_effects(sensor=Sensor(2, encoder_resolution=1e-4, velocity="filter", velocity_cutoff=50.0,
                                        noise_q=1e-4, noise_dq=1e-3, seed=7)), id="encoder-filter-noise"),
    pytest.param(_effects(sensor=Sensor(2, encoder_resolution=1e-3, velocity="difference", noise_dq=1e-3, seed=2),
                          actuator=Actuator(2, delay_samples=1)), id="encoder-difference-noise-delay"),
    pytest.param(_effects(0.3, Sampled(1e-3, 1e-4), motor=DCMotor(2, **MOTOR, voltage_limit=500.0)), id="dc-motor"),
    pytest.param(_effects(0.3, Sampled(1e-3, 1e-4), motor=DCMotor(2, **MOTOR, rotor_inertia=[2e-4, 1e-4])),
                 id="dc-motor-rotor"),
    pytest.param(_effects(0.3, Sampled(1e-3, 2.5e-4), elastic_joint=ElasticJoint(2, J=0.1, K=1e4, D=5.0)),
                 id="elastic-joint"),
]


@pytest.mark.parametrize("run", EFFECTS)
def test_plant_effects_compile_to_the_numpy_run(monkeypatch, run):
    a, b = both(monkeypatch, run)
    assert a.ok
    assert_same_run(a, b)


REPETITIVE = ["trajectory.omega=10.0", "controller.period=0.6283185307179586", "simulation.t_final=1.4",
              "simulation.control_period=0.0015707963267948966"]  # N = 400 ticks a period, 2.2 periods: the ring wraps


def test_the_repetitive_laws_delay_line_is_carried_through_the_scan(monkeypatch):
    a, b = both(monkeypatch, lambda: load("example-7.2.2", [*REPETITIVE, "simulation.log_every=3"]).run())
    assert a.ok and a.t[-1] > 2 * 0.6283
    assert_same_run(a, b)


def test_the_saturated_repetitive_law_compiles(monkeypatch):
    a, b = both(monkeypatch, lambda: load("problem-7.2-4", REPETITIVE).run())
    assert a.ok
    assert_same_run(a, b)


@pytest.mark.parametrize("rule", ["euler", "hold"])
def test_acceleration_by_differences_and_a_projection_compile(monkeypatch, rule):
    """Example 6.2.2's adaptive computed torque (q̈ from the backward difference of the measured velocities, φ̂
    projected into a box) on a tachometer with noise (exact velocity: a difference of differenced positions would
    amplify round-off by 1/Ts², beyond 1e-9 in a few hundred ticks)."""
    sets = ["controller.phi_min=0.1", "controller.phi_max=10", "plant.noise_dq=1e-3", "plant.seed=4",
            "simulation.t_final=0.3", "simulation.control_period=1e-3", "simulation.dt=5e-4",
            f"simulation.discretization='{rule}'", "simulation.log_every=2"]
    a, b = both(monkeypatch, lambda: load("example-6.2.2", sets).run())
    assert a.ok and a.phi_hat.min() >= 0.1
    assert_same_run(a, b)


@pytest.mark.parametrize(("rule", "t_stop"), [("euler", "0.01"), ("hold", "0")])
def test_a_guarded_law_stops_at_the_same_tick_with_its_own_reason_compiled(monkeypatch, rule, t_stop):
    """Example 6.2.2 without a box, sampled at 10 ms: M̂(q) loses definiteness. Under "euler" the guard fails at the
    sample of tick 1 (t = 0.01 s, that tick unlogged); under "hold" in a sub-step of tick 0 (t = 0, that tick logged).
    numpy raises SimulationStop; the compiled loop reads the law's guard: the same status, with the law's φ̂."""
    sets = ["simulation.t_final=1", "simulation.control_period=1e-2", "simulation.dt=2e-3",
            f"simulation.discretization='{rule}'"]
    a, b = both(monkeypatch, lambda: load("example-6.2.2", sets).run())
    assert a.status.startswith(f"diverged at t={t_stop} s: the estimated mass matrix") and a.t.size == 1
    assert_same_run(a, b)


def test_the_hold_rule_with_a_loop_of_sub_steps_compiles(monkeypatch):
    """"hold" with 10 sub-steps (a fori_loop inside the compiled tick, for the plant and for x), and the PID servo's
    filter states of problem-6.4-1 on its 2 sub-steps."""
    model = OneLinkArm()
    a, b = both(monkeypatch, lambda: simulate(Plant(model, [M, B]), FilteredPD(model), sinusoid(1, 0.5, 2.0),
                                              t_final=1.0, integrator=Sampled(0.02, 0.002, "hold"), q0=[0.3]))
    assert_same_run(a, b)
    sets = ["simulation.t_final=0.5", "simulation.control_period=2e-3", "simulation.discretization='hold'"]
    assert_same_run(*both(monkeypatch, lambda: load("problem-6.4-1", sets).run()))


@pytest.mark.parametrize("log_every", [1, 7])
def test_a_diverging_run_stops_at_the_same_tick_compiled(monkeypatch, log_every):
    """A non-finite state (example 6.3.1 at 20 ms) and a state beyond max_state (the one-link PD above its stability
    limit): the same status text, the same partial log."""
    sets = ["simulation.t_final=3", "simulation.control_period=0.02", f"simulation.log_every={log_every}"]
    a, b = both(monkeypatch, lambda: load("example-6.3.1", sets).run())
    assert a.status == "diverged at t=1.12 s: non-finite state" and a.t.size == 55 // log_every + 1
    assert_same_run(a, b)
    a, b = both(monkeypatch, lambda: one_link(0.25, 50.0, max_state=1e3, log_every=log_every))
    assert "exceeded 1000" in a.status
    assert_same_run(a, b)


def test_sampled_loops_of_one_shape_share_a_program_and_keep_their_own_gains(monkeypatch):
    from robotadapt.tracing import PROGRAMS

    arm = TwoLinkArm()
    finals, programs = [], []
    for kv in (5.0, 20.0):
        ctrl = InertiaRelated(arm, 2.5, kv, 20.0, [0.0, 0.0])
        a, b = both(monkeypatch, lambda ctrl=ctrl: simulate(Plant(arm, [0.8, 2.3]), ctrl, sinusoid(2), t_final=0.3,
                                                            integrator=Sampled(1e-3)))
        assert_same_run(a, b)
        finals.append(b.x[-1])
        programs.append(len(PROGRAMS))
    assert not np.allclose(finals[0], finals[1]) and programs[1] == programs[0]


def test_the_delay_line_is_written_into_a_new_array(x64):
    from robotadapt.sim.sampled import ring_write

    line = np.arange(8.0).reshape(4, 2)
    before = line.copy()
    new = ring_write(line, 2, np.array([-1.0, -2.0]))
    np.testing.assert_array_equal(line, before)
    np.testing.assert_array_equal(new, [[0, 1], [2, 3], [-1, -2], [6, 7]])
    jax = pytest.importorskip("jax")
    from robotadapt.tracing import jax_module

    jnp = jax_module().numpy
    traced = jax.jit(ring_write)(jnp.asarray(line), 2, jnp.asarray([-1.0, -2.0]))
    np.testing.assert_array_equal(np.asarray(traced), new)
