"""Error-controlled runs compiled through diffrax (`robotadapt.sim.compiled_ivp`, `backend = "jax"` with a solve_ivp
method) against scipy's solve_ivp on the same closed loop: the same Runge–Kutta pair and tolerances, so the two runs
agree to the tolerance's global error (they choose their steps independently), stop at the same event time, and what
has no compiled counterpart is one clear error."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from robotadapt.studies.scenarios import load
from robotadapt.validation import ConfigError

SHORT = ["simulation.t_final=2.0", "simulation.rtol=1e-9", "simulation.atol=1e-11"]


def both(name: str, overrides: list[str]):
    """(compiled, scipy) runs of a scenario."""
    return (load(name, [*SHORT, *overrides, f"simulation.backend='{b}'"]).run() for b in ("jax", "numpy"))


@pytest.mark.parametrize("method", ["RK45", "DOP853", "RK23"])
def test_each_explicit_method_equals_scipys_run_to_its_tolerance(method):
    """Example 6.3.1 (Slotine–Li): every sample every 1 ms within 1e-6 of scipy's (the global error of rtol 1e-9 over
    2 s); the run really moved (the estimates left zero)."""
    jax_run, scipy_run = both("example-6.3.1", [f"simulation.method='{method}'"])
    assert jax_run.status == scipy_run.status == "ok"
    assert jax_run.info["backend"] == "jax" and scipy_run.info["backend"] == "numpy"
    np.testing.assert_array_equal(jax_run.t, scipy_run.t)
    for name in ("q", "dq", "x"):
        np.testing.assert_allclose(getattr(jax_run, name), getattr(scipy_run, name), rtol=0, atol=1e-6, err_msg=name)
    assert np.abs(jax_run.phi_hat[-1]).min() > 0.1


def test_a_law_with_filters_and_a_passivity_servo_compiles_too():
    """Composite adaptation (Example 6.6.3: φ̂, P, the filtered torque and regressor in x) and the passivity-based law
    with a PID servo (Problem 6.4-1)."""
    for name in ("example-6.6.3", "problem-6.4-1"):
        jax_run, scipy_run = both(name, ["simulation.method='RK45'", "simulation.t_final=1.0"])
        assert jax_run.status == scipy_run.status == "ok"
        np.testing.assert_allclose(jax_run.x, scipy_run.x, rtol=0, atol=1e-6 * max(1.0, np.abs(scipy_run.x).max()))


def test_a_runaway_stops_at_scipys_event_time_and_keeps_its_samples():
    """max_state below the motion: both stop where max|z| crosses it (root-found), with the samples before."""
    jax_run, scipy_run = both("example-6.3.1", ["simulation.method='RK45'", "simulation.max_state=2.5"])
    assert scipy_run.status.startswith("diverged at t=")
    assert jax_run.status == scipy_run.status
    assert jax_run.t.size == scipy_run.t.size > 1
    np.testing.assert_allclose(jax_run.q, scipy_run.q, rtol=0, atol=1e-8)


@pytest.mark.parametrize(("name", "overrides", "message"), [
    ("example-6.3.1", ["simulation.method='Radau'"], r"^simulation\.backend: Radau has no compiled counterpart"),
    ("example-6.2.2", ["simulation.method='RK45'"], r"^simulation\.backend: AdaptiveComputedTorque \(a guard"),
])
def test_what_diffrax_cannot_run_is_one_clear_error(name, overrides, message):
    with pytest.raises(ConfigError, match=message):
        load(name, [*SHORT, *overrides, "simulation.backend='jax'"]).run()


def test_the_command_line_runs_it_and_refuses_radau_in_one_line(tmp_path):
    run = [sys.executable, "-m", "robotadapt", "run", "example-6.3.1", "--no-plots", "--backend", "jax", "--t-final",
           "0.5", "--set", "simulation.method='DOP853'", "--out", str(tmp_path / "ok")]
    done = subprocess.run(run, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "ok" / "metrics.json").is_file()
    bad = subprocess.run([*run[:-2], "--set", "simulation.method='BDF'", "--out", str(tmp_path / "bad")],
                         capture_output=True, text=True)
    assert bad.returncode == 2
    assert bad.stderr.count("\n") == 1 and "simulation.backend: BDF has no compiled counterpart" in bad.stderr
