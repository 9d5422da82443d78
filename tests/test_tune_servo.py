"""Tuning the passivity-based law's servo (issue 25): the PID servo's Λ, Ψ (and the PD servo's Λ) are the servo's own
fields, D = Λ and C = Ψ derived from them (6.4.2), so a traced gain reaches the loop; K_v and the update law's gain
with them. The differentiable run against the compiled forward run, its gradients against central differences of
forward runs, a θ whose H(s) is not stable refused by the servo's own check (6.4.19), and a short tune."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.controllers.passivity import PidServo
from robotadapt.pytree import replace as replace_at
from robotadapt.studies.gain_space import locate, parse_objective
from robotadapt.studies.scenarios import load
from robotadapt.studies.tune import Problem, score, tune
from robotadapt.validation import ConfigError
from tuning_checks import assert_matches, central_differences

SHORT = ["simulation.t_final=1.0", "simulation.backend='jax'"]
SERVO = ["controller.servo.Lam", "controller.servo.Psi", "controller.Kv"]
# the PID servo with the gradient law (Problem 6.4-1) and with Landau's PI law (Problem 6.4-2)
LAWS = {"gradient": ("problem-6.4-1", "controller.law.Gamma"), "landau_pi": ("problem-6.4-2", "controller.law.F_p")}
GOAL = parse_objective("rms_error+1e-6*energy")


@pytest.fixture(scope="module", params=list(LAWS))
def problem(request):
    """(scenario, its Problem in Λ, Ψ, K_v and the law's gain): one compiled program per law for the tests below."""
    name, law_gain = LAWS[request.param]
    scenario = load(name, SHORT)
    return scenario, Problem(scenario, [locate(scenario, f) for f in [*SERVO, law_gain]], GOAL, None)


def test_the_servo_gains_are_fields_the_loop_reads():
    """locate takes Λ, Ψ of the PID servo and Λ of the PD servo; a value set on the built servo is its D (and C)."""
    scenario = load("problem-6.4-1", SHORT)
    pd = load("problem-6.4-1", SHORT + ["controller.servo={kind = 'pd', Lam = [2.5, 3.0]}"])
    assert locate(pd, "controller.servo.Lam").form == "diagonal"
    assert [locate(scenario, f).form for f in SERVO] == ["scalar"] * 3
    for servo, lam in ((scenario.setup.controller.servo, [2.5, 2.5]), (pd.setup.controller.servo, [2.5, 3.0])):
        np.testing.assert_array_equal(replace_at(servo, ("Lam",), 4.0 * np.eye(2)).D, 4.0 * np.eye(2))
        np.testing.assert_array_equal(servo.D, np.diag(lam))  # the original untouched
    np.testing.assert_array_equal(replace_at(scenario.setup.controller.servo, ("Psi",), 3.0 * np.eye(2)).C,
                                  3.0 * np.eye(2))


def test_the_differentiable_run_is_the_compiled_forward_run(problem):
    scenario, p = problem
    reference = scenario.run()
    t, e, tau, _ = p.rollout.signals(p.loop, p.trajectory, np.concatenate([p.s0, p.x0]))
    np.testing.assert_array_equal(t, reference.t)
    np.testing.assert_allclose(np.asarray(e), reference.e, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(tau), reference.tau, rtol=1e-9, atol=1e-9)


def test_gradients_equal_central_differences_of_forward_runs(problem):
    """jax.grad in θ = log(λ, ψ, k_v, law gain) against (J(θ + h) − J(θ − h)) / 2h of the forward engine, to 1e-6 of
    the largest component; the objective equal to the forward run's to 1e-9."""
    scenario, p = problem
    _, grad, objective, *_ = p.evaluate(p.theta0)
    assert objective == pytest.approx(score(scenario, GOAL).objective, rel=1e-9)
    fd = central_differences(scenario, p.gains, GOAL, p.theta0)
    assert_matches(grad, fd)


def test_gains_whose_servo_is_not_stable_are_refused(problem):
    """Λ → 0 leaves h_i(s) = s / (s² + ψ_i) with poles on the imaginary axis: the servo's construction check (6.4.19)
    refuses it, so Problem.admissible does, where the traced program would run it."""
    _, p = problem
    assert p.admissible(p.theta0)
    for log_lam, stable in ((np.log(1e-3), True), (-40.0, False)):
        theta = p.theta0.copy()
        theta[0] = log_lam
        assert p.admissible(theta) is stable
        if not stable:
            with pytest.raises(ConfigError, match="is not stable"):
                PidServo(2, np.exp(log_lam), 1.0)


def test_a_short_tune_of_the_servo_improves_the_objective():
    tuned = tune(load("problem-6.4-1", SHORT), [*SERVO, "controller.law.Gamma"], GOAL.text, max_runs=15)
    assert tuned.search.runs <= 15
    assert tuned.after.objective < 0.9 * tuned.before.objective, (tuned.before, tuned.after)
