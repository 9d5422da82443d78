"""Tuning by gradients through the closed loop (docs/tuning.md): the differentiable run against the compiled forward
engine, its gradients against central finite differences of forward runs, the objectives against hand-written sums,
`robotadapt tune` end to end (tuned.toml reproduced by `robotadapt run`), robust tuning, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.cli import main
from robotadapt.pytree import replace as replace_at
from robotadapt.sim.gradient import Rollout
from robotadapt.sim.loop import ClosedLoop
from robotadapt.studies.gain_space import locate, parse_objective, tuned_scenario
from robotadapt.studies.scenarios import load
from robotadapt.studies.tune import SCREEN, Problem, optimise, score
from robotadapt.tracing import jax_module
from tuning_checks import assert_gradient_is_central_differences

SHORT = ["simulation.t_final=1.0", "simulation.backend='jax'"]
ACT = ["controller.phi_min=0.1", "controller.phi_max=10", "controller.phi_hat0=[0.85, 2.2]"]  # inside M̂ > 0
# (scenario, gains varied, a form of each that the test also covers): Slotine–Li with a full SPD Kv (Cholesky), a
# diagonal Λ and a scalar Γ; the composite law's P0 enters its initial state P(0); DCAL's gains are plain numbers
LAWS = {
    "slotine_li": ("example-6.3.1", ["controller.Kv=[[10.0, 2.0], [2.0, 8.0]]", "controller.Lam=[2.5, 3.0]"],
                   ["controller.Kv", "controller.Lam", "controller.Gamma"]),
    "composite": ("example-6.6.3", [], ["controller.Lam", "controller.Kv", "controller.P0", "controller.a"]),
    "dcal": ("example-7.2.1", [], ["controller.Kv", "controller.Kp", "controller.Ka", "controller.Gamma"]),
    # adaptive computed torque: K_p, K_v enter the Lyapunov pair P of (6.2.16), recomputed from the traced gains — the
    # book's closed form for scalar gains, the dense solve of AᵀP + PA = −Q with a diagonal K_p and Q tuned too
    "adaptive_computed_torque": ("example-6.2.2", ACT, ["controller.Kp", "controller.Kv", "controller.Gamma"]),
    "adaptive_computed_torque_Q": ("example-6.2.2", ACT + ["controller.Kp=[125.0, 100.0]",
                                                           "controller.Q=[[2,0,0,0],[0,2,0,0],[0,0,1,0],[0,0,0,1]]"],
                                   ["controller.Kp", "controller.Kv", "controller.Q"]),
}


def law(name: str):
    scenario_name, sets, fields = LAWS[name]
    scenario = load(scenario_name, SHORT + sets)
    return scenario, [locate(scenario, f) for f in fields]


@pytest.mark.parametrize("name", list(LAWS))
def test_the_differentiable_run_is_the_compiled_forward_run(name):
    scenario, _ = law(name)
    s = scenario.setup
    reference = scenario.run()
    ctrl = s.controller.prepare(s.trajectory, s.integrator.dt, s.t_final)
    loop = ClosedLoop(s.plant, ctrl, s.plant.model.n)
    z0 = np.concatenate([s.plant.initial_state(s.q0, s.dq0), ctrl.initial_state(s.q0, s.dq0)])
    t, e, tau, _ = Rollout.make(loop, s.trajectory, s.integrator, s.t_final, s.log_every).signals(loop, s.trajectory, z0)
    np.testing.assert_array_equal(t, reference.t)
    np.testing.assert_allclose(np.asarray(e), reference.e, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(tau), reference.tau, rtol=1e-9, atol=1e-9)



@pytest.mark.parametrize("sets", [[], ["simulation.control_period=0.004", "plant.noise_q=1e-4"]],
                         ids=["rk4", "sampled"])
def test_the_scores_are_the_signals_without_the_states(sets):
    """What tuning scores (`Rollout.scores`, no state logged) is what `signals` logs: e and τ to round-off, and `ok`
    the states' check written out here — finite and within the bound, over every logged state."""
    scenario = load("example-6.6.3", SHORT + sets)  # the composite law: P is in the state
    s = scenario.setup
    ctrl = s.controller.prepare(s.trajectory, s.integrator.dt, s.t_final)
    loop = ClosedLoop(s.plant, ctrl, s.plant.model.n)
    z0 = np.concatenate([s.plant.initial_state(s.q0, s.dq0), ctrl.initial_state(s.q0, s.dq0)])
    rollout = Rollout.make(loop, s.trajectory, s.integrator, s.t_final, 1)
    t, e, tau, z = (np.asarray(a) for a in rollout.signals(loop, s.trajectory, z0))
    peak = np.max(np.abs(z))
    for bound in (2 * peak, 0.5 * peak):
        t2, e2, tau2, ok = rollout.scores(loop, z0, bound)
        np.testing.assert_array_equal(np.asarray(t2), t)
        np.testing.assert_allclose(np.asarray(e2), e, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(tau2), tau, rtol=1e-12, atol=1e-12)
        assert bool(ok) == bool(np.all(np.isfinite(z)) and peak <= bound)
    z0[0] = np.nan
    assert not bool(rollout.scores(loop, z0, 2 * peak)[3])

@pytest.mark.parametrize("name", list(LAWS))
def test_gradients_equal_central_differences_of_forward_runs(name):
    """jax.grad through the checkpointed scan (forward mode for these few gains) against (J(θ + h) − J(θ − h)) / 2h of
    the normal forward engine, to 1e-6 of the largest component."""
    assert_gradient_is_central_differences(*law(name))


def test_objectives_are_the_hand_written_sums():
    scenario = load("example-6.3.1", SHORT)
    res = scenario.run()
    goal = parse_objective("ise + 2*final_error+1e-3*energy")
    e2 = np.sum(res.e**2, axis=1)
    power = np.sum(res.tau**2, axis=1)
    dt = np.diff(res.t)
    by_hand = (np.sum(dt * (e2[1:] + e2[:-1]) / 2) + 2 * np.sqrt(e2[-1])
               + 1e-3 * np.sum(dt * (power[1:] + power[:-1]) / 2))
    assert score(scenario, goal).objective == pytest.approx(by_hand, rel=1e-12)
    assert score(scenario, parse_objective("rms_error")).objective == pytest.approx(np.sqrt(np.mean(e2)), rel=1e-12)


def test_gains_stay_positive_definite_and_round_trip(x64):
    scenario, gains = law("slotine_li")
    kv = gains[0]
    assert kv.form == "matrix" and gains[1].form == "diagonal" and gains[2].form == "scalar"
    np.testing.assert_allclose(kv.gain(kv.theta0()), [[10.0, 2.0], [2.0, 8.0]], rtol=1e-14)
    for theta in np.random.default_rng(1).normal(scale=3.0, size=(20, kv.size)):
        assert np.all(np.linalg.eigvalsh(kv.gain(theta)) > 0)
    jnp = jax_module().numpy
    np.testing.assert_allclose(np.asarray(kv.gain(jnp.asarray(kv.theta0()))), kv.gain(kv.theta0()), rtol=1e-14)


def test_a_gain_the_law_derives_constants_from_is_refused():
    """Adaptive computed torque takes the book's P for scalar gains and solves AᵀP + PA = −I otherwise: a K_p given as
    an equal-valued list would switch between the two as it is tuned, so it is refused (a scalar K_p, or a list with
    controller.Q given, is tuned)."""
    scenario = load("example-6.2.2", SHORT + ["controller.Kp=[125.0, 125.0]"])
    with pytest.raises(Exception, match="derives other constants"):
        locate(scenario, "controller.Kp")


def test_the_lyapunov_pair_solves_its_equation():
    """P from the dense Kronecker solve against (6.2.16) itself, and the book's closed form against the solve with its
    Q = diag(k_p I, (2k_v − 1) I)."""
    from robotadapt.controllers.computed_torque import lyapunov

    kp, kv, eye = np.diag([125.0, 100.0]), np.diag([50.0, 40.0]), np.eye(2)
    A = np.block([[0 * eye, eye], [-kp, -kv]])
    Q = np.diag([2.0, 2.0, 1.0, 1.0])
    P = lyapunov(np, A, Q)
    np.testing.assert_allclose(A.T @ P + P @ A, -Q, atol=1e-9)
    book = load("example-6.2.2").setup.controller
    P_book, Q_book = book.lyapunov_pair
    A = np.block([[0 * eye, eye], [-book.Kp, -book.Kv]])
    np.testing.assert_allclose(lyapunov(np, A, Q_book), P_book, rtol=1e-10, atol=1e-9)


def test_tune_writes_files_and_run_reproduces_the_objective(tmp_path, capsys):
    out = tmp_path / "tune"
    code = main(["tune", "example-6.3.1", "--t-final", "1", "--backend", "jax", "--vary", "controller.Kv=2:50",
                 "--vary", "controller.Lam=0.5:10", "--vary", "controller.Gamma=0.05:2", "--objective", "rms_error",
                 "--max-torque", "150", "--max-runs", "10", "--surface", "3", "--out", str(out)])
    assert code == 0, capsys.readouterr()
    summary = json.loads((out / "tune.json").read_text())
    printed = capsys.readouterr().out
    assert (out / "tune.png").stat().st_size > 0
    assert set(summary) >= {"objective", "max_abs_torque", "gains", "iterations", "wall_time"}
    assert summary["max_abs_torque"] <= 150
    # one count everywhere: --max-runs bounds the differentiated runs, which the line and the figure name as such; the
    # forward runs are the screen (64 by default, fewer when some gains are refused) and the start and the answer
    assert summary["differentiated_runs"] <= 10 and 2 < summary["screened_runs"] <= SCREEN
    assert summary["forward_runs"] == summary["screened_runs"] + 2
    assert summary["runs"] == summary["differentiated_runs"] + summary["forward_runs"]
    assert (f"in {summary['differentiated_runs']} differentiated runs (+ {summary['forward_runs']} forward runs: the "
            "screen, the start and the answer)") in printed
    assert all({"objective", "max_abs_torque", "gradient_norm"} <= set(it) for it in summary["iterations"])
    assert summary["initial"]["max_abs_torque"] > 150 and summary["feasible"]
    assert main(["run", str(out / "tuned.toml"), "--out", str(tmp_path / "run"), "--no-plots"]) == 0
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["rms_error_norm"] == pytest.approx(summary["objective"], rel=1e-9, abs=0)
    assert max(m["max_abs_torque"]) <= 150
    grid = summary["surface"]  # a corner of the 3 × 3 surface against a forward run with those gains
    (x_key, xs), (y_key, ys) = next(iter(grid["x"].items())), next(iter(grid["y"].items()))
    corner = load(str(out / "tuned.toml"), [f"{x_key}={xs[-1]!r}", f"{y_key}={ys[0]!r}"]).run()
    assert grid["objective"][-1][0] == pytest.approx(np.sqrt(np.mean(np.sum(corner.e**2, axis=1))), rel=1e-9)


def test_a_budget_no_gains_meet_keeps_the_best_and_exits_1(tmp_path, capsys):
    out = tmp_path / "tune"
    code = main(["tune", "example-6.3.1", "--t-final", "0.5", "--vary", "controller.Kv", "--max-torque", "1",
                 "--max-runs", "4", "--out", str(out), "--no-plots"])
    assert code == 1
    printed = capsys.readouterr().out
    assert "no gains found meet the budget" in printed
    summary = json.loads((out / "tune.json").read_text())
    assert (out / "tuned.toml").exists() and summary["feasible"] is False
    # the hint: the gain that moves the peak, its elasticity against forward runs at Kv·(1 ± 5 %) of the answer
    kv = summary["gains"]["controller.Kv"]
    elasticity = summary["peak_elasticity"]["controller.Kv"]
    assert "the peak moves most with controller.Kv" in printed and ("lower" if elasticity > 0 else "raise") in printed
    peaks = [max(metrics(load(str(out / "tuned.toml"), [f"controller.Kv={kv * f!r}"]).run())["max_abs_torque"])
             for f in (0.95, 1.05)]
    assert elasticity == pytest.approx(np.log(peaks[1] / peaks[0]) / np.log(1.05 / 0.95), rel=0.3)


def test_robust_tuning_averages_over_drawn_true_parameters(tmp_path):
    scenario = load("example-6.3.1", ["simulation.t_final=0.5"])
    goal = parse_objective("rms_error")
    phis = np.array([[0.6, 2.0], [1.0, 2.6]])
    problem = Problem(scenario, [locate(scenario, "controller.Kv")], goal, None, phis)
    _, _, objective, peak, _, _ = problem.evaluate(problem.theta0)
    each = [score(load("example-6.3.1", ["simulation.t_final=0.5", f"plant.phi={p.tolist()}"]), goal) for p in phis]
    assert objective == pytest.approx(np.mean([s.objective for s in each]), rel=1e-9)
    assert peak == pytest.approx(max(s.max_abs_torque for s in each), rel=1e-9)


def test_fewer_runs_beat_a_random_search_over_the_same_box():
    """The fast version of benchmarks/bench_tune.py: on Example 6.3.1 (2 s) under a 150 N·m budget, the gradient search
    alone (no screen) beats the best feasible one of 120 random gains drawn uniformly in the same box, simulating at
    most 12 runs."""
    box = {"controller.Kv": (2.0, 50.0), "controller.Lam": (0.5, 10.0), "controller.Gamma": (0.05, 2.0)}
    scenario = load("example-6.3.1", ["simulation.t_final=2.0", "simulation.backend='jax'"])
    goal, budget = parse_objective("rms_error"), 150.0
    problem = Problem(scenario, [locate(scenario, f"{k}={lo}:{hi}") for k, (lo, hi) in box.items()], goal, budget)
    lo, hi = np.array(list(box.values())).T
    objective, peak = problem.objectives(np.log(np.random.default_rng(0).uniform(lo, hi, size=(120, 3))))
    best_random = np.nanmin(np.where(peak <= budget, objective, np.nan))
    search = optimise(problem, 12, screen=0)
    after = score(tuned_scenario(scenario, problem.gains, search.best(budget)), goal)
    assert search.runs <= 12 and after.max_abs_torque <= budget
    assert after.objective < best_random


@pytest.mark.parametrize(("args", "message"), [
    (["--vary", "controller.phi_hat0"], "controller.phi_hat0: is not a gain"),
    (["--vary", "plant.phi"], "--vary: 'plant.phi' is not a gain"),
    (["--vary", "controller.Kv", "--objective", "speed"], "--objective: unknown objective 'speed'"),
    (["--vary", "controller.Kv", "--max-torque", "-3"], "--max-torque: must be a positive"),
    (["--vary", "controller.Kv", "--over", "plant.q0=0:1"], "--over: robust tuning draws the true parameters"),
    (["--vary", "controller.Kv", "--set", "simulation.method='RK45'"], "simulation.method: tuning differentiates"),
    (["--vary", "controller.Kv", "--surface", "5"], "--surface: needs two scalar gains"),
    (["--vary", "controller.Kv", "--objective", "0*energy"], "--objective: unknown objective"),
    (["--vary", "controller.Kv=5"], "--vary: expected section.key=lo:hi"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert main(["tune", "example-6.3.1", "--t-final", "0.2", *args, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def test_the_replaced_gain_reaches_the_step():
    scenario = load("example-6.3.1", SHORT)
    loop = ClosedLoop(scenario.setup.plant, scenario.setup.controller, 2)
    other = replace_at(loop, ("controller", "Kv"), 3.0 * np.eye(2))
    assert other.controller.Kv[0, 0] == 3.0 and loop.controller.Kv[0, 0] == 10.0
    assert other.plant is loop.plant


# --------------------------------------------------------------------------------------------------------------------
# Tuning sampled-data runs (issue 23): the tick under a checkpointed scan, as the RK4 step


SAMPLED = ["simulation.t_final=0.6", "simulation.backend='jax'", "simulation.control_period=0.004",
           "plant.noise_q=1e-4"]


def test_the_differentiable_sampled_run_is_the_compiled_forward_run():
    """Example 6.3.1 at 250 Hz with a noisy encoder: the scanned tick (Rollout of the Tick) gives the errors and the
    held torques of the compiled sampled-data run, to 1e-9, its noise drawn from the same seed."""

    scenario = load("example-6.3.1", SAMPLED)
    s = scenario.setup
    reference = scenario.run()
    loop = ClosedLoop(s.plant, s.controller, 2)
    q_m, dq_m = s.plant.sensor.first_measurement(s.q0, s.dq0, 0.004)
    z0 = np.concatenate([s.plant.initial_state(s.q0, s.dq0), s.controller.initial_state(q_m, dq_m)])
    rollout = Rollout.make(loop, s.trajectory, s.integrator, s.t_final, s.log_every)
    t, e, tau, _ = rollout.signals(loop, s.trajectory, z0)
    np.testing.assert_allclose(t, reference.t, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(e), reference.e, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(tau), reference.tau, rtol=1e-9, atol=1e-9)


def test_sampled_gradients_equal_central_differences_of_forward_runs():
    scenario = load("example-6.3.1", SAMPLED)
    assert_gradient_is_central_differences(scenario, [locate(scenario, f) for f in ("controller.Kv", "controller.Lam",
                                                                                   "controller.Gamma")])


def test_cli_tunes_a_sampled_data_scenario_and_refuses_mujoco(tmp_path, capsys):
    out = tmp_path / "tune"
    code = main(["tune", "example-6.3.1", "--t-final", "0.4", "--control-period", "0.004", "--vary", "controller.Kv",
                 "--max-runs", "3", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((out / "tune.json").read_text())
    assert summary["objective"] > 0 and (out / "tuned.toml").exists()
    pytest.importorskip("mujoco")
    assert main(["tune", "example-6.3.1", "--t-final", "0.2", "--set", "plant.engine='mujoco'", "--vary",
                 "controller.Kv", "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "plant.engine: MuJoCo steps its plant" in err, err


def test_a_gain_at_its_bound_is_written_as_the_bound():
    """exp(log 50) is 49.99999999999999 in floating point: the tuned scenario says 50."""
    gain = locate(load("example-6.3.1"), "controller.Kv=2:50")
    assert gain.value(np.log([50.0])) == 50.0 and repr(gain.value(np.log([50.0]))) == "50.0"


def test_gains_the_law_refuses_are_failed_runs_not_written():
    """The traced program skips the law's construction checks: adaptive computed torque's book P needs k_v > ½
    (6.2.16), so θ with k_v = 0.4 is scored as a failed run, and costs no run."""
    from robotadapt.studies.tune import DIVERGED, Search

    scenario, gains = law("adaptive_computed_torque")
    problem = Problem(scenario, gains, parse_objective("rms_error"), None)
    theta = problem.theta0.copy()
    assert problem.admissible(theta)
    theta[1] = np.log(0.4)  # controller.Kv
    assert not problem.admissible(theta)
    search = Search(problem, 10, None)
    value, grad = search.fun(theta, 0.0, 1.0, 0.1)
    assert value == DIVERGED and not np.any(grad) and search.runs == 0 and not search.evaluated


# --------------------------------------------------------------------------------------------------------------------
# The search (issue 25): forward-mode gradients, the batched screen, the count of runs


def test_forward_and_reverse_mode_give_the_same_gradient(monkeypatch):
    """Few gains take forward mode (jacfwd through the run), many reverse mode (through the checkpointed blocks): the
    two programs agree to round-off on the same problem."""
    import robotadapt.studies.tune as tune_module

    scenario, gains = law("slotine_li")
    goal = parse_objective("rms_error+1e-6*energy")
    forward = Problem(scenario, gains, goal, 150.0)
    monkeypatch.setattr(tune_module, "FORWARD_MODE", 0)
    reverse = Problem(scenario, gains, goal, 150.0)
    assert forward.forward_mode and not reverse.forward_mode
    theta = forward.theta0 + 0.1
    a, b = forward.evaluate(theta, 0.5, 100.0), reverse.evaluate(theta, 0.5, 100.0)
    assert a[0] == pytest.approx(b[0], rel=1e-12)
    np.testing.assert_allclose(a[1], b[1], rtol=1e-9, atol=1e-12 * np.max(np.abs(b[1])))


def test_the_screen_starts_at_its_best_point_within_the_budget():
    """The screen's rows: θ₀ clipped into the boxes, then a Latin hypercube filling each box (one point per stratum of
    every axis); the start it returns is the row of least objective whose exact peak meets the budget, by the forward
    program scored here by hand on the same rows."""
    from robotadapt.studies.tune import Search, screen_points

    box = {"controller.Kv": (2.0, 50.0), "controller.Lam": (0.5, 10.0), "controller.Gamma": (0.05, 2.0)}
    scenario = load("example-6.3.1", ["simulation.t_final=1.0", "simulation.backend='jax'"])
    problem = Problem(scenario, [locate(scenario, f"{k}={lo}:{hi}") for k, (lo, hi) in box.items()],
                      parse_objective("rms_error"), 150.0)
    rows = screen_points(problem, 16)
    lo, hi = np.log(np.array(list(box.values()))).T
    np.testing.assert_allclose(rows[0], np.clip(problem.theta0, lo, hi))
    strata = np.floor((rows[1:] - lo) / (hi - lo) * 15).astype(int)
    assert all(sorted(strata[:, k]) == list(range(15)) for k in range(3))
    search = Search(problem, 10, None)
    start = search.screen(rows)
    objective, peak = problem.objectives(rows)
    fits = np.where(peak <= 150.0, objective, np.inf)
    np.testing.assert_array_equal(start, rows[np.argmin(fits)])
    assert search.screened == 16 and search.runs == 0 and len(search.evaluated) == 16


def test_the_screens_default_is_the_one_the_help_names(capsys):
    with pytest.raises(SystemExit):
        main(["tune", "--help"])
    assert f"(default {SCREEN};" in " ".join(capsys.readouterr().out.split())
