"""Persistency of excitation (spec §5): the windowed Gram matrix of Y_d against closed forms, the book's Example 6.5.1
(not PE, rank one), `sin t` for the two-parameter one-link model (PE, α = π over 2π: the book's Example 6.5.2 claim is
wrong), the three-parameter model with a spring (not PE, eigenvalues {0, π, 2π}), the infinite-integral test (6.6.18),
and `robotadapt pe` on the three packaged scenarios.
"""

from __future__ import annotations

import contextlib
import io
import json
import re

import numpy as np
import pytest

from robotadapt.analysis.excitation import excitation
from robotadapt.cli import main
from robotadapt.robots import OneLinkArm, TwoLinkArm
from robotadapt.trajectories import SumOfSines, exponential_step, sinusoid
from robotadapt.validation import ConfigError

TWO = OneLinkArm()  # τ = m q̈ + b q̇
THREE = OneLinkArm(stiffness=True)  # τ = m q̈ + b q̇ + k q
SIN_PLUS_COS3 = SumOfSines.make(1, [1.0, 1.0], [1.0, 3.0], [0.0, np.pi / 2])  # Example 6.5.2(b)


def pe_json(*argv: str) -> tuple[int, dict]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["pe", *argv, "--json"])
    return code, json.loads(out.getvalue())


def test_example_6_5_1_is_not_exciting_rank_one_and_the_window_matches_the_closed_form():
    """q_d = 1 − e^{−2t}: Y_dᵀY_d = e^{−4t}[[16, −8], [−8, 4]] (spec §5.1), so every window has the null direction
    (m, b) ∝ (1, 2) and λ_max = 20 ∫ e^{−4t} = 5 (e^{−4 t0} − e^{−4 (t0+ρ)})."""
    exc = excitation(TWO, exponential_step(1), horizon=20.0, window=2.0)
    assert not exc.persistently_exciting
    assert exc.rank == 1
    assert exc.alpha_min < 1e-12 * exc.beta_max
    np.testing.assert_allclose(np.abs(exc.weakest), np.array([1.0, 2.0]) / np.sqrt(5.0), atol=1e-9)
    expected = 5.0 * (np.exp(-4 * exc.t0) - np.exp(-4 * (exc.t0 + 2.0)))
    np.testing.assert_allclose(exc.beta, expected, rtol=1e-9, atol=1e-15)
    assert not exc.integral_grows  # ∫_0^∞ is finite and rank one: (6.6.18) fails too


def test_sin_t_excites_the_two_parameter_model_alpha_pi_over_two_pi():
    """Y_d = [−sin t, cos t] and ∫ over any 2π window is π I (spec §5.2): PE, contrary to the book's Example 6.5.2."""
    exc = excitation(TWO, sinusoid(1), horizon=20.0)
    assert exc.window == pytest.approx(2 * np.pi)  # the trajectory's period is the default window
    assert exc.persistently_exciting
    assert exc.alpha_min == pytest.approx(np.pi, rel=1e-2)
    assert exc.alpha_min == pytest.approx(np.pi, rel=1e-9)  # Simpson on 2048 intervals is far better than 1 %
    np.testing.assert_allclose(exc.alpha, np.pi, rtol=1e-9)
    np.testing.assert_allclose(exc.beta, np.pi, rtol=1e-9)
    assert exc.integral_grows and exc.growth_exponent == pytest.approx(1.0, abs=0.05)


def test_sin_t_does_not_excite_the_three_parameter_model_eigenvalues_0_pi_2pi():
    """With a spring, q̈_d = −q_d makes the m and k columns dependent: eigenvalues {0, π, 2π}, null direction
    (m, b, k) ∝ (1, 0, 1) (spec §5.2 (iii)); the integral stays rank two."""
    exc = excitation(THREE, sinusoid(1), horizon=20.0)
    assert not exc.persistently_exciting
    assert exc.rank == 2
    np.testing.assert_allclose(exc.eigenvalues, [0.0, np.pi, 2 * np.pi], atol=1e-9)
    np.testing.assert_allclose(exc.weakest, np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0), atol=1e-9)
    assert not exc.integral_grows


def test_a_second_frequency_excites_the_three_parameter_model():
    """Each extra frequency adds two excited directions: sin t + cos 3t excites (m, b, k)."""
    exc = excitation(THREE, SIN_PLUS_COS3, horizon=20.0)
    assert exc.persistently_exciting and exc.rank == 3
    assert exc.alpha_min > 1.0 and exc.integral_grows


def test_windows_shorter_than_the_period_match_the_closed_form_at_every_t0():
    """For Y_d = [−sin t, cos t] over [t0, t0 + ρ]: ∫sin² = ρ/2 − (sin 2(t0+ρ) − sin 2t0)/4, ∫cos² = ρ − ∫sin²,
    ∫ −sin cos = (cos 2(t0+ρ) − cos 2t0)/4; the eigenvalues vary with t0 and must match everywhere."""
    rho = 1.0
    exc = excitation(TWO, sinusoid(1), horizon=12.0, window=rho)
    t0, t1 = exc.t0, exc.t0 + rho
    s2 = rho / 2 - (np.sin(2 * t1) - np.sin(2 * t0)) / 4
    sc = (np.cos(2 * t1) - np.cos(2 * t0)) / 4
    gram = np.stack([np.stack([s2, sc], -1), np.stack([sc, rho - s2], -1)], -2)
    lam = np.linalg.eigvalsh(gram)
    np.testing.assert_allclose(exc.alpha, lam[:, 0], rtol=1e-9)
    np.testing.assert_allclose(exc.beta, lam[:, 1], rtol=1e-9)


def test_the_two_link_arm_tracking_sin_t_is_exciting():
    """Example 6.3.1's estimates converge to (0.8, 2.3): its trajectory excites both masses."""
    exc = excitation(TwoLinkArm(), sinusoid(2), horizon=10.0)
    assert exc.persistently_exciting and exc.rank == 2 and exc.alpha_min > 1.0


@pytest.mark.parametrize("window", [0.0, -1.0, float("nan"), 30.0])
def test_a_bad_window_is_a_config_error(window):
    with pytest.raises(ConfigError, match="window"):
        excitation(TWO, sinusoid(1), horizon=20.0, window=window)


@pytest.mark.parametrize(("name", "exciting", "alpha", "rank"), [
    ("example-6.5.1", False, 0.0, 1),
    ("example-6.5.2a", True, np.pi, 2),
    ("problem-6.5-1", False, 0.0, 2),
])
def test_pe_command_on_the_three_packaged_cases(tmp_path, name, exciting, alpha, rank):
    code, report = pe_json(name, "--out", str(tmp_path))
    assert code == 0
    assert {"persistently_exciting", "alpha", "beta", "window", "weakest_direction"} <= set(report)
    assert report["persistently_exciting"] is exciting
    assert report["alpha"] == pytest.approx(alpha, abs=1e-9)
    assert report["rank_worst"] == rank
    assert set(report["weakest_direction"]) == set(report["param_names"])
    assert (tmp_path / "pe.png").stat().st_size > 10_000
    series = json.loads((tmp_path / "pe.json").read_text())["series"]
    assert len(series["t0"]) == len(series["alpha"]) > 10


def test_pe_command_text_verdict_and_window_override(tmp_path, capsys):
    assert main(["pe", "example-6.5.2a", "--window", "3.14159", "--out", str(tmp_path), "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "persistently exciting" in text and "NOT" not in text and "ρ = 3.14159 s (given)" in text
    assert not (tmp_path / "pe.png").exists()


@pytest.mark.parametrize("window", ["0", "-2", "nan", "100"])
def test_pe_command_bad_window_exits_2_with_one_line(tmp_path, capsys, window):
    assert main(["pe", "example-6.3.1", "--window", window, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("robotadapt: error: window:")


# --- issue 16, item 4: the verdict in base parameters for an arm with unidentifiable directions ----------------------

PLANAR3 = ["--set", "robot={kind='planar', n_links=3}", "--set", "plant={q0=[0.0, 0.0, 0.0], dq0=[0.0, 0.0, 0.0]}",
           "--set", "controller.phi_hat0={scale=0.7}", "--t-final", "13", "--no-plots"]


def stacked_rank(model, count: int = 40, seed: int = 3) -> int:
    """Rank of Y over random states by numpy alone: the directions any trajectory could excite."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-np.pi, np.pi, (count, model.n))
    dq, v, a = rng.standard_normal((3, count, model.n))
    Y = model.regressor(q, dq, v, a).reshape(-1, model.p)
    return int(np.linalg.matrix_rank(Y / np.linalg.norm(Y, axis=0).clip(1e-300), tol=1e-8 * np.sqrt(Y.shape[0])))


def test_pe_on_a_three_link_planar_arm_speaks_of_base_parameters(tmp_path, capsys):
    from robotadapt.robots import base_parameters
    from robotadapt.studies.scenarios import load

    model = load("example-6.3.1", [PLANAR3[1], PLANAR3[3], PLANAR3[5]]).setup.controller.model
    rank = stacked_rank(model)
    code, verdict = pe_json("example-6.3.1", *PLANAR3, "--out", str(tmp_path))
    assert code == 0 and model.p == 30 and rank == 9
    assert verdict["parameters"] == "base" and verdict["standard_parameters"] == 30
    assert verdict["unidentifiable_directions"] == model.p - rank
    assert verdict["param_names"] == list(base_parameters(model).names) and len(verdict["param_names"]) == rank
    assert list(verdict["weakest_direction"]) == verdict["param_names"] and len(verdict["eigenvalues_worst"]) == rank
    assert verdict["rank_worst"] <= rank
    assert main(["pe", "example-6.3.1", *PLANAR3, "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert f"for the {rank} base parameters (" in text
    assert re.search(rf"rank \d+ of {rank} identifiable \(21 of 30 standard directions unidentifiable by construction\)",
                     text)
    assert "Ixx1" not in text  # an inertia no planar motion can show is not listed


def test_base_false_keeps_the_standard_parameters():
    from robotadapt.studies.scenarios import load

    s = load("example-6.3.1", [PLANAR3[1], PLANAR3[3], PLANAR3[5], "simulation.t_final=13.0"]).setup
    exc = excitation(s.controller.model, s.trajectory, s.t_final, base=False)
    assert len(exc.param_names) == 30 and exc.unidentifiable == 0 and exc.as_dict()["parameters"] == "standard"
    assert exc.rank <= stacked_rank(s.controller.model)


def test_the_two_link_verdict_is_unchanged_by_the_base_analysis():
    exc = excitation(TwoLinkArm(), sinusoid(2), horizon=10.0)
    assert exc.param_names == ("m1", "m2") and exc.unidentifiable == 0 and exc.standard_parameters is None
