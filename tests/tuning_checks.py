"""Checks shared by the tuning tests: a tuning's gradient against central finite differences of normal forward runs."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.studies.gain_space import Gain, Objective, parse_objective, tuned_scenario
from robotadapt.studies.scenarios import Scenario
from robotadapt.studies.tune import Problem, score

RELATIVE = 1e-6  # max |∇J − ∇J_FD| / max |∇J_FD| a gradient must meet (issue 25)


def central_differences(scenario: Scenario, gains: list[Gain], goal: Objective, theta: np.ndarray, h: float = 1e-5,
                        phis: np.ndarray | None = None) -> np.ndarray:
    """(J(θ + h e_k) − J(θ − h e_k)) / 2h for every entry k, each J a normal forward run of the tuned scenario (the mean
    over the true parameters `phis`, when given)."""
    fd = np.empty_like(theta)
    for k in range(theta.size):
        up, down = theta.copy(), theta.copy()
        up[k] += h
        down[k] -= h
        fd[k] = (score(tuned_scenario(scenario, gains, up), goal, phis).objective
                 - score(tuned_scenario(scenario, gains, down), goal, phis).objective) / (2 * h)
    return fd


def assert_gradient_is_central_differences(scenario: Scenario, gains: list[Gain], max_torque: float | None = None,
                                           objective: str = "rms_error+1e-6*energy",
                                           phis: np.ndarray | None = None) -> None:
    """The program's gradient of the objective at θ₀ against central differences of forward runs, to `RELATIVE` of the
    largest component, and its objective equal to the forward run's to 1e-9 (with a budget: the budget inactive; with
    `phis`: the mean over those true parameters, the runs batched in one program)."""
    goal = parse_objective(objective)
    problem = Problem(scenario, gains, goal, max_torque, phis)
    theta = problem.theta0
    _, grad, value, *_ = problem.evaluate(theta)
    assert value == pytest.approx(score(scenario, goal, phis).objective, rel=1e-9)
    assert_matches(grad, central_differences(scenario, gains, goal, theta, phis=phis))


def assert_matches(grad: np.ndarray, fd: np.ndarray) -> None:
    """max |∇J − ∇J_FD| ≤ `RELATIVE` max |∇J_FD|; the relative error printed (`pytest -s` shows it: docs/tuning.md)."""
    error = float(np.max(np.abs(grad - fd)) / np.max(np.abs(fd)))
    print(f"gradient vs central differences: relative error {error:.2g}")
    assert error <= RELATIVE, (grad, fd)
