"""Tuning laws that switch or kink (docs/tuning.md#switching-laws): k_d sgn(r) (6.7.6) and the switching σ ramp
(6.7.14) are differentiated through smooth surrogates (tanh(r/w); a rounded ramp) whose width narrows round by round,
and the answer is chosen and scored on the exact law.

The surrogates' gradients are checked against central differences of normal forward runs of the surrogate laws
themselves (user kinds `robotadapt.controllers.robust:SmoothedSign`, `robotadapt.controllers.adaptation:SmoothedSigma`),
their switching terms against hand-written formulas, and a tuning's numbers against forward runs of the exact law."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.controllers.adaptation import SwitchingSigma
from robotadapt.studies.gain_space import locate, parse_objective, tuned_scenario
from robotadapt.studies.scenarios import load
from robotadapt.studies.tune import Problem, score, switching_parts
from tuning_checks import assert_matches, central_differences

SIGN = ("example-6.7.2", ["simulation.t_final=1.0", "simulation.dt=1e-3", "simulation.log_every=1",
                          "simulation.backend='jax'"],
        ["controller.base.Kv", "controller.base.Lam", "controller.base.Gamma"])
SIGMA = ("sigma-modification", ["simulation.t_final=1.0", "simulation.backend='jax'"],
         ["controller.Kv", "controller.servo.Lam", "controller.law.Gamma"])
SURROGATE = {"example-6.7.2": ("controller", "robotadapt.controllers.robust:SmoothedSign"),
             "sigma-modification": ("controller.law", "robotadapt.controllers.adaptation:SmoothedSigma")}


def test_the_surrogates_are_the_hand_written_formulas():
    r = np.linspace(-0.3, 0.3, 13)
    sign = load(*SIGN[:2]).setup.controller
    assert switching_parts(sign) == [()]
    np.testing.assert_array_equal(sign.switching(r), np.sign(r))
    np.testing.assert_allclose(sign.surrogate(0.05).switching(r), np.tanh(r / 0.05), rtol=1e-15)
    law = SwitchingSigma(p=2, Gamma=1.0, phi0=2.0, sigma0=0.7)
    xa = np.array([[0.0, 0.0], [1.0, 1.0], [2.5, 1.0], [3.0, 3.0], [5.0, 0.0]])
    norm = np.linalg.norm(xa, axis=1)
    np.testing.assert_allclose(law.sigma(xa), 0.7 * np.clip(norm / 2.0 - 1.0, 0.0, 1.0), rtol=1e-15)
    w = 0.02
    u = np.sqrt(norm**2 + (2.0 * w) ** 2) / 2.0 - 1.0
    smooth = 0.7 * w * (np.log1p(np.exp(u / w)) - np.log1p(np.exp((u - 1.0) / w)))
    np.testing.assert_allclose(law.surrogate(w).sigma(xa), smooth, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(law.surrogate(w).sigma(xa), law.sigma(xa), atol=0.7 * w)  # within σ0·w·ln 2 of the ramp


@pytest.mark.parametrize("case", [SIGN, SIGMA], ids=["sign", "sigma"])
def test_surrogate_gradients_equal_central_differences_of_its_forward_runs(case):
    """jax.grad of the surrogate of width w against central differences of forward runs of the surrogate law, to 1e-6
    of the largest component; the exact law's objective is another number (the surrogate is not the law)."""
    name, sets, fields = case
    width = 0.05
    section, kind = SURROGATE[name]
    scenario = load(name, sets)
    smooth = load(name, sets + [f"{section}.kind='{kind}'", f"{section}.width={width}"])
    goal = parse_objective("rms_error+1e-6*energy")
    problem = Problem(scenario, [locate(scenario, f) for f in fields], goal, None)
    _, grad, objective, *_ = problem.evaluate(problem.theta0, width=width)
    assert objective == pytest.approx(score(smooth, goal).objective, rel=1e-9)
    fd = central_differences(smooth, [locate(smooth, f) for f in fields], goal, problem.theta0)
    assert_matches(grad, fd)
    exact, _ = problem.objectives(problem.theta0[None])
    assert exact[0] == pytest.approx(score(scenario, goal).objective, rel=1e-9)


def test_a_switching_law_is_tuned_and_scored_on_the_exact_law(tmp_path, capsys):
    """`robotadapt tune` on k_d sgn(r): the gains it writes meet the budget on the exact law (sgn, not tanh), and
    `robotadapt run tuned.toml` reproduces its objective to 1e-9."""
    name, sets, fields = SIGN
    out = tmp_path / "tune"
    args = ["tune", name, *[a for s in sets for a in ("--set", s)], *[a for f in fields for a in ("--vary", f)],
            "--max-torque", "150", "--max-runs", "12", "--screen", "16", "--out", str(out), "--no-plots"]
    assert main(args) == 0, capsys.readouterr()
    summary = json.loads((out / "tune.json").read_text())
    assert summary["initial"]["max_abs_torque"] > 150 >= summary["max_abs_torque"]
    assert summary["forward_runs"] > summary["screened_runs"] + 2  # the evaluations scored again on the exact law
    assert main(["run", str(out / "tuned.toml"), "--out", str(tmp_path / "run"), "--no-plots"]) == 0
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["rms_error_norm"] == pytest.approx(summary["objective"], rel=1e-9, abs=0)
    assert max(m["max_abs_torque"]) <= 150
    tuned = load(str(out / "tuned.toml"))
    assert tuned.data["controller"]["kind"] == "sign_robust" and tuned.data["controller"]["boundary_layer"] == 0.0
    theta = np.log([summary["gains"][f] for f in fields])
    scenario = load(name, sets)
    again = score(tuned_scenario(scenario, [locate(scenario, f) for f in fields], theta), parse_objective("rms_error"))
    assert again.objective == pytest.approx(summary["objective"], rel=1e-9)


def test_a_surrogate_of_a_surrogate_is_a_surrogate_of_the_law():
    """Tuning a scenario that already holds a surrogate (a user kind) narrows it again instead of failing."""
    sign = load(*SIGN[:2]).setup.controller.surrogate(0.05)
    np.testing.assert_allclose(sign.surrogate(0.01).switching(np.array([0.02])), np.tanh([2.0]), rtol=1e-15)
    sigma = SwitchingSigma(p=2, Gamma=1.0, phi0=2.0).surrogate(0.1)
    assert sigma.surrogate(0.01).width == 0.01
