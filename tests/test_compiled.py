"""The compiled backend (robotadapt.sim.compiled): the same step under jax.jit and lax.scan equals the numpy backend."""

import dataclasses
from importlib import resources

import numpy as np
import pytest
import tomllib

from robotadapt.analysis.metrics import metrics
from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, simulate
from robotadapt.sim.batch import simulate_batch
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid
from robotadapt.validation import ConfigError

jax = pytest.importorskip("jax", reason="the compiled backend needs the [jax] extra (make test installs it)")

ARM, PHI = TwoLinkArm(), np.array([0.8, 2.3])


def _both(name: str, *overrides: str):
    base = ["simulation.t_final=1.0", *overrides]
    return load(name, base).run(), load(name, [*base, "simulation.backend='jax'"]).run()


@pytest.mark.parametrize("name", ["example-6.3.1", "example-6.5.1", "problem-6.4-1", "problem-6.4-2", "example-6.6.3",
                                  "example-6.7.1", "sigma-modification", "example-7.2.1", "payload-change"])
def test_the_books_examples_equal_the_numpy_backend(name):
    """Every law that traces (Slotine–Li, passivity with PD and PID servos and Landau's law, composite, k_d sgn r,
    σ-modification, DCAL, a payload picked up mid-run) gives the numpy run's samples to 1e-9."""
    a, b = _both(name)
    assert a.status == b.status == "ok"
    np.testing.assert_array_equal(a.t, b.t)
    for field in ("q", "dq", "x", "tau"):
        scale = max(1.0, float(np.abs(getattr(a, field)).max()))
        np.testing.assert_allclose(getattr(b, field), getattr(a, field), rtol=0, atol=1e-9 * scale, err_msg=field)
    assert metrics(a)["final_abs_error"] == pytest.approx(metrics(b)["final_abs_error"], abs=1e-9)


def test_an_n_dof_symbolic_arm_compiles_too():
    pytest.importorskip("sympy")
    a, b = _both("puma560-slotine-li", "simulation.t_final=0.2")
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-9 * max(1.0, float(np.abs(a.x).max())))


def test_a_diverging_run_stops_where_the_numpy_run_stops():
    """The divergence guard inside the scan: same status text, same partial record."""
    a, b = _both("example-6.3.1", "simulation.max_state=5.0", "simulation.log_every=1")
    assert a.status.startswith("diverged at t=") and b.status == a.status
    assert b.t.shape == a.t.shape and 1 < a.t.size < 1001
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-12)


def test_a_batch_equals_the_numpy_batch_run_by_run():
    """Per-run true masses and gains, one run made to diverge by a huge Γ: statuses and records agree."""
    rng = np.random.default_rng(5)
    N = 6
    plants = [Plant(ARM, PHI * rng.uniform(0.8, 1.2, 2)) for _ in range(N)]
    gammas = [20.0] * (N - 1) + [1e9]
    ctrls = [InertiaRelated(ARM, 2.5, float(kv), g, [0.0, 0.0]) for kv, g in zip(rng.uniform(5, 20, N), gammas, strict=True)]
    kw = dict(t_final=1.0, log_every=20, max_state=1e4)
    a = simulate_batch(plants, ctrls, sinusoid(2), integrator=RK4(1e-3), **kw)
    b = simulate_batch(plants, ctrls, sinusoid(2), integrator=RK4(1e-3, "jax"), **kw)
    assert a.status == b.status and a.status[-1].startswith("diverged") and a.status[0] == "ok"
    np.testing.assert_array_equal(a.n_logged, b.n_logged)
    for i in range(N):
        ra, rb = a.run(i), b.run(i)
        np.testing.assert_allclose(rb.x, ra.x, rtol=0, atol=1e-9 * max(1.0, float(np.abs(ra.x).max())))


def test_loops_of_one_shape_share_a_program_and_keep_their_own_gains():
    """The second controller reuses the first one's compiled program (its gains are arguments, not constants) and
    still gets its own answer."""
    from robotadapt.tracing import PROGRAMS

    runs = []
    for kv in (5.0, 20.0):
        ctrl = InertiaRelated(ARM, 2.5, kv, 20.0, [0.0, 0.0])
        a, b = (simulate_batch([Plant(ARM, PHI)], [ctrl], sinusoid(2), t_final=0.5, integrator=RK4(1e-3, backend))
                for backend in ("numpy", "jax"))
        np.testing.assert_allclose(b.run(0).x, a.run(0).x, rtol=0, atol=1e-9)
        runs.append((a.run(0).x[-1], len(PROGRAMS)))
    assert not np.allclose(runs[0][0], runs[1][0])
    assert runs[1][1] == runs[0][1]


@pytest.mark.parametrize(("overrides", "message"), [
    (["simulation.backend='cuda'"], r"^simulation\.backend: expected one of (auto, )?numpy, jax(, c)?; got 'cuda'"),
    (["simulation.backend='jax'", "simulation.method='RK45'"], r"^simulation\.method: a controller with a delay line"),
])
def test_what_cannot_be_compiled_is_a_clear_error(overrides, message):
    with pytest.raises(ConfigError, match=message):
        load("example-7.2.2", ["simulation.t_final=0.1", *overrides]).run()


@dataclasses.dataclass(frozen=True, eq=False)
class HostSide(InertiaRelated):
    """Test double: Slotine–Li (Table 6.3.1) with a host-side look at the state, which tracing cannot follow."""

    def __call__(self, t, x, q, dq, ref):
        if float(np.max(np.abs(q))) > 1e3:
            raise RuntimeError("unreachable")
        return super().__call__(t, x, q, dq, ref)


def test_a_law_that_checks_concrete_values_names_itself():
    with pytest.raises(ConfigError, match=r"^simulation\.backend: HostSide on TwoLinkArm cannot be compiled "):
        simulate(Plant(ARM, PHI), HostSide(ARM, 2.5, 10.0, 20.0, [0.0, 0.0]), sinusoid(2), t_final=0.1,
                 integrator=RK4(1e-3, "jax"))


# -- every continuous-time scenario compiles (issue 14) ----------------------------------------------------------------

SCENARIOS = sorted(p.name[: -len(".toml")] for p in resources.files("robotadapt.studies.scenarios").iterdir()
                   if p.name.endswith(".toml"))


def _skip_reason(name: str) -> str | None:
    data = tomllib.loads((resources.files("robotadapt.studies.scenarios") / f"{name}.toml").read_text("utf-8"))
    if "control_period" in data.get("simulation", {}):
        return "sampled-data control: its ticks are compared across the backends in tests/test_sampled.py"
    if data["robot"]["kind"] in ("urdf", "example_robot"):
        return ("a URDF arm: its numpy reference is Pinocchio's model, compared with the compiled KinematicTree in "
                "tests/test_kinematic_tree.py")
    return None


def assert_same(a, b, fields=("q", "dq", "x", "tau")) -> None:
    """Same status and instants; each array equal to 1e-9 relative to its largest entry (at least 1)."""
    assert b.status == a.status
    np.testing.assert_array_equal(b.t, a.t)
    for field in fields:
        want, got = getattr(a, field), getattr(b, field)
        scale = max(1.0, float(np.abs(want).max())) if want.size else 1.0
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * scale, err_msg=field)


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_continuous_time_scenario_compiles_and_equals_numpy(name):
    """Each packaged continuous-time scenario, 0.2 s: the compiled run's q, q̇, x, τ and status are the numpy run's."""
    reason = _skip_reason(name)
    if reason is not None:
        pytest.skip(reason)
    a, b = (load(name, ["simulation.t_final=0.2", f"simulation.backend='{backend}'"]).run()
            for backend in ("numpy", "jax"))
    assert a.t.size > 1 or name == "example-6.2.2"  # as the book ran it: stops in its first step
    assert_same(a, b)


@pytest.mark.parametrize(("name", "overrides"), [
    ("example-6.2.2", []),  # M̂ turns indefinite in a later RK4 stage of the first step: φ̂ of that stage named
    ("example-6.2.2", ["simulation.dt=1e-6", "simulation.t_final=1e-4", "simulation.log_every=3"]),  # at t = 2.2e-5 s
    ("example-6.2.2", ["controller.phi_hat0=[-0.5, 2.2]"]),  # indefinite at once
])
def test_adaptive_computed_torque_stops_where_and_as_the_numpy_run_stops(name, overrides):
    """Table 6.2.1's guard inside the program: the same step, the same status text (φ̂ of the failing stage), the same
    partial record."""
    a, b = (load(name, ["simulation.t_final=0.1", *overrides, f"simulation.backend='{backend}'"]).run()
            for backend in ("numpy", "jax"))
    assert a.status.startswith("diverged within the step from ") and "M̂(q) is no longer positive definite (φ̂ = " in a.status
    assert_same(a, b)


def test_adaptive_computed_torque_runs_compiled_with_and_without_its_box():
    """Problem 6.2-1: with the bound m̂ ≥ 0.1 it runs; without it M̂ turns singular at t ≈ 0.144 s, in both backends."""
    s = load("problem-6.2-1").setup
    for ctrl in (s.controller, dataclasses.replace(s.controller, phi_min=None)):
        a, b = (simulate(s.plant, ctrl, s.trajectory, t_final=0.3, integrator=RK4(s.integrator.dt, backend), q0=s.q0,
                         dq0=s.dq0, log_every=2) for backend in ("numpy", "jax"))
        assert_same(a, b)
    assert a.status.startswith("diverged within the step from 0.14") and b.t.size < 100


REPETITIVE = ["trajectory.omega=10.0", "controller.period=0.6283185307179586", "simulation.dt=0.0015707963267948966",
              "simulation.t_final=1.4"]  # N = 400 steps a period, 2.2 periods: the ring wraps twice


@pytest.mark.parametrize(("name", "log_every"), [("example-7.2.2", 1), ("problem-7.2-4", 3), ("problem-7.2-5", 4)])
def test_the_repetitive_laws_delay_line_is_carried_through_the_scan(name, log_every):
    """Table 7.2.2 (plain, saturated, polar arm): the delay line in the carried state gives the numpy run's samples,
    the û_d applied at t_k logged at t_k, and the extra sample at t_final (when log_every divides the steps)."""
    a, b = (load(name, [*REPETITIVE, f"simulation.log_every={log_every}", f"simulation.backend='{backend}'"]).run()
            for backend in ("numpy", "jax"))
    assert a.ok and a.t[-1] > 2 * 0.6283 and np.abs(a.x[-1]).max() > 1.0  # it learnt something
    assert_same(a, b)


def test_a_repetitive_batch_compiles_one_line_per_run():
    s = load("example-7.2.2", REPETITIVE).setup
    q0 = np.array([[0.0, 0.0], [0.2, -0.1], [-0.3, 0.4]])
    kw = dict(t_final=s.t_final, q0=q0, log_every=2)
    a, b = (simulate_batch(s.plant, s.controller, s.trajectory, integrator=RK4(s.integrator.dt, backend), **kw)
            for backend in ("numpy", "jax"))
    assert a.status == b.status == ("ok",) * 3
    np.testing.assert_array_equal(a.n_logged, b.n_logged)
    np.testing.assert_allclose(b.z, a.z, rtol=0, atol=1e-9 * np.abs(a.z).max())
    one = simulate(s.plant, s.controller, s.trajectory, integrator=s.integrator, q0=q0[1], t_final=s.t_final,
                   log_every=2)
    assert_same(one, b.run(1))


def test_a_batch_where_one_computed_torque_run_stops_and_the_others_go_on():
    """Example 6.2.2 with ė(0) = 1 in runs 1 and 3 (M̂ indefinite in the first step) and ė(0) = 0 in runs 0 and 2:
    the compiled batch stops runs 1 and 3 with the numpy batch's statuses and records; 0 and 2 run on."""
    s = load("example-6.2.2").setup
    dq0 = np.array([[1.0, 1.0], [0.0, 0.0], [1.0, 1.0], [0.0, 0.1]])
    a, b = (simulate_batch(s.plant, s.controller, s.trajectory, t_final=0.2, dq0=dq0, log_every=10,
                           integrator=RK4(1e-3, backend)) for backend in ("numpy", "jax"))
    assert b.status == a.status
    assert [st == "ok" for st in b.status] == [True, False, True, False]
    assert b.status[1].startswith("diverged within the step from 0 to ")
    assert "the estimated mass matrix M̂(q) is no longer positive definite" in b.status[1]
    np.testing.assert_array_equal(b.n_logged, a.n_logged)
    for i in range(4):
        assert_same(a.run(i), b.run(i))


@pytest.mark.parametrize("overrides", [
    pytest.param(["plant.elastic_joint={J=0.05, K=1e4, D=5.0}"], id="elastic-joint"),
    pytest.param(["plant.motor={R=1.0, L=1e-3, k_t=0.1, k_b=0.1, gear_ratio=50, current_gain=20, rotor_inertia=1e-5}",
                  "simulation.dt=1e-4"], id="dc-motor"),
    pytest.param(["plant.elastic_joint={J=0.05, K=1e4, D=5.0}", "simulation.dt=1e-4",
                  "plant.motor={R=1.0, L=1e-3, k_t=0.1, k_b=0.1, gear_ratio=50, current_gain=20}"], id="both"),
    pytest.param(["plant.torque_limit=20"], id="torque-limit"),
    pytest.param(["plant.robot={kind='two_link', friction_terms=true}", "plant.phi=[0.8, 2.3, 1, 1]"],
                 id="friction-the-model-lacks"),
])
def test_plant_effects_in_continuous_time_compile(overrides):
    """Example 6.3.1 through the real-world effects that act in continuous time: the compiled run is the numpy run."""
    a, b = (load("example-6.3.1", ["simulation.t_final=0.1", *overrides, f"simulation.backend='{backend}'"]).run()
            for backend in ("numpy", "jax"))
    assert a.ok
    assert_same(a, b)
    for name in a.monitors:
        np.testing.assert_allclose(b.monitors[name], a.monitors[name], rtol=0,
                                   atol=1e-9 * max(1.0, float(np.abs(a.monitors[name]).max())), err_msg=name)


def test_auto_compiles_long_runs_steps_short_ones_and_falls_back_for_numpy_only_code():
    """The default backend: a run of at least AUTO_MIN_STEPS steps is compiled (to C where a compiler is present), a
    shorter one stepped by numpy, and a law written with numpy only (a user's own, as in the tutorial) is stepped by
    numpy instead of failing."""
    from dataclasses import dataclass

    from robotadapt.sim import simulate
    from robotadapt.sim.integrators import AUTO_MIN_STEPS

    ctrl = InertiaRelated(ARM, 2.5, 10.0, 20.0, [0.0, 0.0])
    long_run = simulate(Plant(ARM, PHI), ctrl, sinusoid(2), t_final=AUTO_MIN_STEPS * 1e-3, log_every=100)
    short_run = simulate(Plant(ARM, PHI), ctrl, sinusoid(2), t_final=(AUTO_MIN_STEPS - 1) * 1e-3, log_every=100)
    from robotadapt.native.build import compiler

    assert long_run.info["backend"] == ("c" if compiler() else "jax") and short_run.info["backend"] == "numpy"

    @dataclass(frozen=True, eq=False)
    class NumpyOnly(InertiaRelated):
        def __call__(self, t, x, q, dq, ref):
            tau, dx = super().__call__(t, x, q, dq, ref)
            return np.asarray(tau) + 0.0, dx  # np.asarray of a traced array: JAX cannot trace this law

    res = simulate(Plant(ARM, PHI), NumpyOnly(ARM, 2.5, 10.0, 20.0, [0.0, 0.0]), sinusoid(2),
                   t_final=AUTO_MIN_STEPS * 1e-3, log_every=100)
    assert res.ok and res.info["backend"] == "numpy"
    np.testing.assert_allclose(res.q, long_run.q, rtol=0, atol=1e-9)


def test_auto_takes_jax_where_the_c_translator_lacks_a_primitive():
    """Under "auto", a single run whose program holds a primitive the C translator lacks (an eigendecomposition here)
    is compiled by JAX instead, with a warning naming the primitive; asked for by name, "c" fails in one line."""
    from dataclasses import dataclass

    from robotadapt.arrays import array_namespace
    from robotadapt.native.build import compiler
    from robotadapt.sim.integrators import AUTO_MIN_STEPS, NotTraceableWarning
    from robotadapt.validation import ConfigError

    if compiler() is None:
        pytest.skip("no C compiler")

    @dataclass(frozen=True, eq=False)
    class WithEigh(InertiaRelated):
        def __call__(self, t, x, q, dq, ref):
            tau, dx = super().__call__(t, x, q, dq, ref)
            xp = array_namespace(q)
            return tau + 0.0 * xp.linalg.eigh(xp.eye(2) + 1e-3 * q[..., :1, None] ** 2)[0], dx

    law = WithEigh(ARM, 2.5, 10.0, 20.0, [0.0, 0.0])
    with pytest.warns(NotTraceableWarning, match="eigh"):
        res = simulate(Plant(ARM, PHI), law, sinusoid(2), t_final=AUTO_MIN_STEPS * 1e-3, log_every=100)
    assert res.ok and res.info["backend"] == "jax"
    with pytest.raises(ConfigError, match="^native: the C translator has no primitive 'eigh'"):
        simulate(Plant(ARM, PHI), law, sinusoid(2), t_final=0.1, integrator=RK4(1e-3, "c"))
