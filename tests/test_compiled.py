"""The compiled backend (robotadapt.sim.compiled): the same step under jax.jit and lax.scan equals the numpy backend."""

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4
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
    from robotadapt import compiled

    runs = []
    for kv in (5.0, 20.0):
        ctrl = InertiaRelated(ARM, 2.5, kv, 20.0, [0.0, 0.0])
        a, b = (simulate_batch([Plant(ARM, PHI)], [ctrl], sinusoid(2), t_final=0.5, integrator=RK4(1e-3, backend))
                for backend in ("numpy", "jax"))
        np.testing.assert_allclose(b.run(0).x, a.run(0).x, rtol=0, atol=1e-9)
        runs.append((a.run(0).x[-1], len(compiled._PROGRAMS)))
    assert not np.allclose(runs[0][0], runs[1][0])
    assert runs[1][1] == runs[0][1]


@pytest.mark.parametrize(("overrides", "message"), [
    (["simulation.backend='jax'"], r"^simulation\.backend: a controller with a delay line"),
    (["simulation.backend='cuda'"], r"^simulation\.backend: expected one of numpy, jax; got 'cuda'"),
    (["simulation.backend='jax'", "simulation.method='RK45'"], r"^simulation\.backend: the compiled backend steps"),
])
def test_what_cannot_be_compiled_is_a_clear_error(overrides, message):
    with pytest.raises(ConfigError, match=message):
        load("example-7.2.2", ["simulation.t_final=0.1", *overrides]).run()


def test_a_law_that_checks_concrete_values_names_itself():
    """Adaptive computed torque stops a run when M̂ loses definiteness (a host-side check): refused, by name."""
    with pytest.raises(ConfigError, match=r"^simulation\.backend: AdaptiveComputedTorque on TwoLinkArm cannot be "):
        load("example-6.2.2", ["simulation.t_final=0.1", "simulation.backend='jax'"]).run()
