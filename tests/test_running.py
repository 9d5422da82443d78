"""Metrics at every step (robotadapt.sim.running): the error and torque metrics a run folds at every step or tick equal
the same numbers written out by hand from a log of every step — on numpy, JAX and C, continuous and sampled, single
runs, batches and a sweep's rows — so they do not change with `simulation.log_every`."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, Sampled, running, simulate, simulate_batch
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid

FOLDED = ("rms_error", "rms_error_norm", "ise", "control_energy", "max_abs_error", "max_abs_torque",
          "convergence_time")
ARM, PHI = TwoLinkArm(), np.array([0.8, 2.3])


def by_hand(res) -> dict:
    """The metrics written out from a log of every step (the definitions of analysis.metrics), not by the package."""
    e, tau, t = res.e, res.tau, res.t
    square, power = (e**2).sum(axis=1), (tau**2).sum(axis=1)
    norm = np.sqrt(square)
    above = np.nonzero(norm > 0.01 * norm.max())[0]
    out = {"rms_error": np.sqrt((e**2).mean(axis=0)), "rms_error_norm": np.sqrt(square.mean()),
           "ise": float(np.sum(np.diff(t) * (square[1:] + square[:-1]) / 2)),
           "control_energy": float(np.sum(np.diff(t) * (power[1:] + power[:-1]) / 2)),
           "max_abs_error": np.abs(e).max(axis=0), "max_abs_torque": np.abs(tau).max(axis=0),
           "convergence_time": None if above[-1] == len(t) - 1 else t[above[-1]]}
    if "tau_commanded" in res.monitors:
        cmd = res.monitors["tau_commanded"]
        out["max_abs_commanded_torque"] = np.abs(cmd).max(axis=0)
        out["saturated_fraction"] = np.mean(np.any(np.abs(cmd - tau) > 1e-9 * (1 + np.abs(cmd)), axis=1))
    return out


def assert_equal(m: dict, hand: dict, rtol: float = 1e-12) -> None:
    for key, value in hand.items():
        if value is None:
            assert m[key] is None, key
        else:
            np.testing.assert_allclose(m[key], value, rtol=rtol, atol=1e-300, err_msg=key)


@pytest.mark.parametrize("backend", ["numpy", "jax", "c"])
@pytest.mark.parametrize("name, extra", [
    ("example-6.3.1", []),
    ("example-6.3.1", ["simulation.control_period=0.002", "controller.Kv=12.5"]),  # the issue's saturated digital run
    ("example-6.3.1", ["plant.torque_limit=150"]),  # an actuator that clips: saturated_fraction
    ("example-7.2.2", []),  # a delay line: the state applied over each step
], ids=["continuous", "sampled-2ms", "saturated", "repetitive"])
def test_folded_metrics_equal_every_steps_log_whatever_log_every(name, extra, backend) -> None:
    overrides = extra + [f"simulation.backend={backend}", "simulation.t_final=3"]
    every = load(name, overrides + ["simulation.log_every=1"]).run()
    hand = by_hand(every)
    for log_every in (1, 10, 100):
        res = every if log_every == 1 else load(name, overrides + [f"simulation.log_every={log_every}"]).run()
        assert res.status == "ok" and len(res.t) == (len(every.t) - 1) // log_every + 1
        assert_equal(metrics(res), hand)
    if "plant.torque_limit=150" in extra:
        assert 0 < metrics(every)["saturated_fraction"] < 1


def test_the_issues_numbers_no_longer_change_with_the_log() -> None:
    """Example 6.3.1 at Ts = 2 ms, K_v = 12.5 (the issue: max |τ| 608.7 N·m at log_every 1, 91.9 at 100): the same peak
    at both, and the same energy and RMS error."""
    runs = [metrics(load("example-6.3.1", ["simulation.control_period=0.002", "controller.Kv=12.5",
                                           f"simulation.log_every={k}"]).run()) for k in (1, 100)]
    for key in ("max_abs_torque", "control_energy", "rms_error_norm"):
        np.testing.assert_allclose(runs[0][key], runs[1][key], rtol=1e-12)
    assert max(runs[1]["max_abs_torque"]) > 600


@pytest.mark.parametrize("backend", ["numpy", "c"])
def test_a_stopped_run_folds_its_valid_steps_only(backend) -> None:
    """A run that diverges keeps the metrics of the steps it logged (the step that produced the runaway state too); C
    folds in its loop (running.fold_step), numpy a few steps at a time (fold_rows)."""
    law = InertiaRelated(ARM, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    every = simulate(Plant(ARM, PHI), law, sinusoid(2), t_final=3.0, integrator=RK4(1e-3, backend="numpy"),
                     max_state=3.0)
    assert every.status.startswith("diverged")
    thinned = simulate(Plant(ARM, PHI), law, sinusoid(2), t_final=3.0, integrator=RK4(1e-3, backend=backend),
                       max_state=3.0, log_every=7)
    assert thinned.status == every.status
    assert_equal(metrics(thinned), by_hand(every), rtol=1e-12 if backend == "numpy" else 1e-9)


def test_one_step_folds_as_a_call_of_steps() -> None:
    """fold_step (the C loop's, one step at a time) equals fold_rows (the host's, a call's steps at once) on rows with
    invalid steps, clipped torques and an error that rises, falls and rises again, folded in two calls."""
    rng = np.random.default_rng(3)
    steps, m, n = 40, 3, 2
    e = rng.normal(size=(steps, 2, m)) * np.exp(-np.arange(steps) / 8)[:, None, None]
    e[30] *= 50  # a late rise: convergence_time moves
    tau = rng.normal(size=(steps, 2, n))
    commanded = np.where(rng.random((steps, 2, n)) < 0.3, tau + 1.0, tau)
    ok = rng.random((steps, 2)) < 0.8
    ok[:3, 1] = False  # a run whose first steps are invalid: `first` is its first valid one
    rows = np.concatenate([e, tau, commanded, ok[..., None].astype(float)], axis=-1)
    ks = np.arange(100, 100 + steps)
    hosted = running.fold_rows(running.fold_rows(running.start(np, (2,), n, m), rows[:17], ks[:17]), rows[17:],
                               ks[17:])
    stepped = running.start(np, (2,), n, m)
    for row, k in zip(rows, ks, strict=True):
        stepped = running.fold_step(stepped, row, k)
    for name, a, b in zip(running.Running._fields, hosted, stepped, strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-13, err_msg=name)
    for i in range(2):
        assert running.values(running.run(stepped, i), 1e-3)["convergence_time"] == pytest.approx(
            running.values(running.run(hosted, i), 1e-3)["convergence_time"])


@pytest.mark.parametrize("integrator", [RK4(1e-3, backend="jax"), Sampled(2e-3, backend="jax"),
                                        RK4(1e-3, backend="numpy"), RK4(1e-3, backend="c"),
                                        Sampled(2e-3, backend="c")],
                         ids=["rk4-jax", "sampled-jax", "rk4-numpy", "rk4-c", "sampled-c"])
def test_a_batch_folds_each_run_as_its_single_run(integrator) -> None:
    law = InertiaRelated(ARM, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    plants = [Plant(ARM, PHI), Plant(ARM, 1.2 * PHI)]
    batch = simulate_batch(plants, law, sinusoid(2), t_final=2.0, integrator=integrator, log_every=50)
    for i, plant in enumerate(plants):
        single = simulate(plant, law, sinusoid(2), t_final=2.0, integrator=integrator)
        assert_equal(metrics(batch.runs()[i]), by_hand(single), rtol=1e-9)  # a vectorized step: round-off apart
        assert_equal(metrics(batch.run(i)), by_hand(single), rtol=1e-9)


def test_a_sweep_row_equals_its_single_run(tmp_path) -> None:
    """A sweep logs at most LOG_SAMPLES states per run; its row's metrics are still every step's."""
    from robotadapt.studies.sweep import make_sweep, run_sweep

    scenario = load("example-6.3.1", ["simulation.t_final=3"])
    report = run_sweep(make_sweep(scenario, ["controller.Kv=8,12"]), tmp_path, workers=1)
    for row, kv in zip(report.rows, (8, 12), strict=True):
        single = metrics(load("example-6.3.1", ["simulation.t_final=3", f"controller.Kv={kv}"]).run())
        for key in ("rms_error_norm", "ise", "control_energy"):
            np.testing.assert_allclose(row[key], single[key], rtol=1e-12, err_msg=key)
