"""Tuning the repetitive learning law (Table 7.2.2, issue 25): its k_L, k_v, k_p, k_a through a differentiable run that
carries the delay line of (7.2.32), so the gradient reaches back through every period's û_d(t − T); the objective and
the torque budget measured over several periods (docs/tuning.md)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.sim.gradient import Rollout
from robotadapt.studies.gain_space import locate, parse_objective
from robotadapt.studies.scenarios import load
from robotadapt.studies.tune import Problem, closed_loop, score
from tuning_checks import assert_matches, central_differences

T = 0.5  # the period: q_d = 0.1 sin(4πt), N = 200 steps of it, 2.5 periods (the ring wraps twice)
SETS = [f"trajectory.omega={2 * math.pi / T!r}", "trajectory.amplitude=0.1", f"controller.period={T!r}",
        f"simulation.dt={T / 200!r}", f"simulation.t_final={2.5 * T!r}"]  # 500 steps: "auto" steps them with numpy
SAMPLED = [f"simulation.control_period={T / 200!r}", f"simulation.dt={T / 400!r}"]  # 200 ticks, 2 plant steps each
GAINS = ["controller.kL", "controller.Kv", "controller.Kp", "controller.Ka"]
BUDGET = 300.0  # N·m: above the start's peak (255), below the peak of the gains tuned without it (≈ 370)


@pytest.mark.parametrize("sets", [[], SAMPLED], ids=["rk4", "sampled"])
def test_the_differentiable_run_is_the_compiled_forward_run(sets):
    """Over 2.5 periods, so that the torque uses û_d(t − T) learnt one and two periods earlier: the scanned step (or
    tick) with the delay line in its carry gives the forward run's e and τ to 1e-9."""
    scenario = load("example-7.2.2", [*SETS, *sets, "simulation.backend='jax'"])
    s = scenario.setup
    reference = scenario.run()
    loop = closed_loop(scenario)
    z0 = np.concatenate([s.plant.initial_state(s.q0, s.dq0), loop.controller.initial_state(s.q0, s.dq0)])
    t, e, tau, z = Rollout.make(loop, s.trajectory, s.integrator, s.t_final, s.log_every).signals(loop, s.trajectory, z0)
    held = np.asarray(loop.split(z)[2])[:, :2]  # û_d(t − T) as the law read it from the line
    assert np.all(held[t < T] == 0) and np.max(np.abs(held[t > 2 * T])) > 1.0
    np.testing.assert_allclose(t, reference.t, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(e), reference.e, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(tau), reference.tau, rtol=1e-9, atol=1e-9)


def test_gradients_equal_central_differences_of_forward_runs():
    """The problem `robotadapt tune` solves below, at the start (where the budget is inactive: the gradient is the
    objective's): jax.grad in θ = log(k_L, k_v, k_p, k_a) against (J(θ + h) − J(θ − h)) / 2h of normal forward runs,
    h = 1e-5, to 1e-6 of the largest component; the objective equal to the forward run's to 1e-9."""
    scenario = load("example-7.2.2", SETS)
    gains = [locate(scenario, name) for name in GAINS]
    goal = parse_objective("rms_error")
    problem = Problem(scenario, gains, goal, BUDGET)
    theta = problem.theta0
    _, grad, objective, _, g, _ = problem.evaluate(theta)
    assert g < 0 and objective == pytest.approx(score(scenario, goal).objective, rel=1e-9)
    fd = central_differences(scenario, gains, goal, theta)
    assert_matches(grad, fd)


def test_tune_improves_within_the_budget_and_run_reproduces_it(tmp_path, capsys):
    """`robotadapt tune` in the four gains under a torque budget the unconstrained optimum exceeds: the tuned gains
    track better and meet the budget on the forward run, and `robotadapt run` of tuned.toml reproduces both."""
    out = tmp_path / "tune"
    code = main(["tune", "example-7.2.2", *(arg for s in SETS for arg in ("--set", s)),
                 *(arg for g in GAINS for arg in ("--vary", g)), "--objective", "rms_error",
                 "--max-torque", str(BUDGET), "--max-runs", "20", "--out", str(out), "--no-plots"])
    assert code == 0, capsys.readouterr()
    summary = json.loads((out / "tune.json").read_text())
    assert summary["feasible"] and summary["differentiated_runs"] <= 20
    assert summary["objective"] < 0.8 * summary["initial"]["objective"]
    assert main(["run", str(out / "tuned.toml"), "--out", str(tmp_path / "run"), "--no-plots"]) == 0
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["rms_error_norm"] == pytest.approx(summary["objective"], rel=1e-9, abs=0)
    assert max(m["max_abs_torque"]) <= BUDGET
