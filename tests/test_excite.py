"""Exciting trajectories (issue 27, docs/identification.md#excitation): the parametrisation starts and ends at rest, the
JAX gradient of the objective equals central differences, the optimiser keeps every limit between its samples (checked
on a grid of our own), lowers cond W below its start's and the scenario's own trajectory's, reads a URDF's limits, and
`robotadapt excite` writes a trajectory a scenario runs; bad input is one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.robots.identifiability import base_parameters
from robotadapt.robots.kinematic_tree import KinematicTree
from robotadapt.studies.excite import Design, Programs, excite, resolve_limits
from robotadapt.studies.scenarios import load
from robotadapt.tracing import float64
from test_kinematic_tree import URDF  # a two-link arm with <limit lower=-1 upper=1 effort=10 velocity=1>


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    path = tmp_path_factory.mktemp("arm") / "two_link.urdf"
    path.write_text(URDF.format(kind="revolute"))
    return path


def series(design: Design, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Swevers' series written out from the design vector: the last harmonic's a_iK, b_iK from the rest-to-rest
    conditions Σ_l a_il = 0, Σ_l l b_il = 0."""
    n, K, T = design.n, design.harmonics, design.period
    m = n * (K - 1)
    a, b = x[:m].reshape(n, K - 1), x[m : 2 * m].reshape(n, K - 1)
    a = np.hstack([a, -a.sum(axis=1, keepdims=True)])
    b = np.hstack([b, -(b @ np.arange(1, K))[:, None] / K])
    q, dq, ddq = np.zeros((3, t.size, n))
    for i in range(n):
        q[:, i] = x[2 * m + i]
        for l in range(1, K + 1):
            w = 2 * np.pi / T * l
            q[:, i] += a[i, l - 1] / w * np.sin(w * t) - b[i, l - 1] / w * np.cos(w * t)
            dq[:, i] += a[i, l - 1] * np.cos(w * t) + b[i, l - 1] * np.sin(w * t)
            ddq[:, i] += -a[i, l - 1] * w * np.sin(w * t) + b[i, l - 1] * w * np.cos(w * t)
    return q, dq, ddq


def test_the_series_starts_and_ends_at_rest_and_is_the_one_written_out():
    design = Design(3, 4, 2.5)
    x = np.random.default_rng(0).normal(size=design.size)
    t = np.linspace(0.0, 2.5, 101)
    for ours, written in zip(design.motion(x, t), series(design, x, t), strict=True):
        np.testing.assert_allclose(ours, written, atol=1e-12)
    ref = design.trajectory(x)(t)  # what a scenario's [trajectory] kind = "fourier" builds
    np.testing.assert_allclose(ref.q_des, series(design, x, t)[0], atol=1e-12)
    for value in (ref.dq_des, ref.ddq_des):
        np.testing.assert_allclose(value[[0, -1]], 0.0, atol=1e-12)
    np.testing.assert_allclose(ref.q_des[0], ref.q_des[-1], atol=1e-12)


@float64
def test_the_objective_and_constraint_gradients_equal_central_differences(arm):
    model = KinematicTree.from_urdf(arm)
    design = Design(2, 3, 3.0)
    limits = resolve_limits(model, {"acceleration": np.array([5.0, 5.0])})
    independent = np.array(base_parameters(model).independent)
    rng = np.random.default_rng(1)
    x = 0.2 * rng.normal(size=design.size)
    for objective in ("cond", "logdet"):
        programs = Programs(model, design, independent, limits, design.grid(40), objective)
        f, g = programs.objective(x)
        h = 1e-6
        fd = np.array([(programs.objective(x + h * e)[0] - programs.objective(x - h * e)[0]) / (2 * h)
                       for e in np.eye(design.size)])
        assert np.max(np.abs(g - fd)) < 1e-6 * max(1.0, np.max(np.abs(g)))
    J = np.asarray(programs.jacobian(x))
    fd = np.stack([(np.asarray(programs.constraints(x + h * e)) - np.asarray(programs.constraints(x - h * e))) / (2 * h)
                   for e in np.eye(design.size)], axis=1)
    assert np.max(np.abs(J - fd)) < 1e-6 * max(1.0, np.max(np.abs(J)))


def test_the_optimum_keeps_every_limit_between_samples_and_beats_its_start(arm):
    """Position, velocity and torque from the URDF, acceleration given: on a grid 50× denser than the optimiser's, the
    trajectory and its inverse dynamics (our own numpy evaluation) stay within 0.9 × each limit; cond W, recomputed
    here from the regressor, is what it reports and below the best random start's."""
    model = KinematicTree.from_urdf(arm)
    limits = resolve_limits(model, {"acceleration": np.array([4.0, 4.0])}, fraction=0.9)
    assert limits.source["position"] == ("model", "model") and limits.source["acceleration"] == ("option", "option")
    design = Design(2, 3, 4.0)
    result = excite(model, design, limits, samples=40, starts=2)
    t = design.period * np.arange(2000) / 2000
    q, dq, ddq = series(design, result.x, t)
    tau = model.inverse_dynamics(q, dq, ddq, model.default_phi)
    for value, bound in ((np.abs(q), 0.9), (np.abs(dq), 0.9), (np.abs(ddq), 3.6), (np.abs(tau), 9.0)):
        assert np.max(value) <= bound * (1 + 1e-6)
    independent = list(base_parameters(model).independent)
    tq, tdq, tddq = series(design, result.x, design.grid(40))
    s = np.linalg.svd(model.regressor(tq, tdq, tdq, tddq)[..., independent].reshape(-1, len(independent)),
                      compute_uv=False)
    assert result.cond == pytest.approx(s[0] / s[-1], rel=1e-9)
    assert np.log(result.cond) < min(result.start_objectives) - np.log(2)
    assert result.fine.met


def test_the_panda_limits_come_from_its_urdf():
    model = load("panda-slotine-li").setup.controller.model
    limits = resolve_limits(model, {}, fraction=1.0)
    np.testing.assert_allclose(limits.upper, [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    np.testing.assert_allclose(limits.velocity, [2.175] * 4 + [2.61] * 3)
    np.testing.assert_allclose(limits.torque, [87.0] * 4 + [12.0] * 3)
    assert np.all(np.isinf(limits.acceleration)) and limits.source["acceleration"] == ("none",) * 7


def test_excite_writes_a_trajectory_a_scenario_runs(tmp_path, arm, capsys):
    scenario = tmp_path / "arm.toml"
    scenario.write_text(f'[robot]\nkind = "urdf"\npath = "{arm}"\n[plant]\nq0 = 0.0\n[trajectory]\nkind = "sinusoid"\n'
                        'amplitude = 0.5\nomega = 1.0\n[controller]\nkind = "slotine_li"\nLam = 5.0\nKv = 2.0\n'
                        'Gamma = 1.0\nphi_hat0 = {scale = 0.7}\n[simulation]\nt_final = 4.0\ndt = 1e-3\n')
    out = tmp_path / "ex"
    assert main(["excite", str(scenario), "--harmonics", "3", "--period", "4", "--starts", "1", "--samples", "40",
                 "--acceleration-limit", "4,4", "--out", str(out)]) == 0
    record = json.loads((out / "excite.json").read_text())
    assert record["limits_met"] and record["cond_after"] < record["cond_before"]
    assert record["limits"]["velocity"]["source"] == ["urdf", "urdf"]
    assert (out / "excite.png").exists() and "cond W" in capsys.readouterr().out
    written = load(str(out / "scenario.toml"))
    design = Design(2, 3, 4.0)
    x = design.vector(np.array(record["a"]), np.array(record["b"]), np.array(record["offset"]))
    t = np.linspace(0.0, 4.0, 17)
    np.testing.assert_allclose(written.setup.trajectory(t).q_des, series(design, x, t)[0], atol=1e-12)
    np.testing.assert_allclose(written.setup.q0, series(design, x, np.zeros(1))[0][0], atol=1e-12)
    assert main(["run", str(out / "scenario.toml"), "--no-plots", "--t-final", "0.5", "--out", str(tmp_path / "r")]) == 0


@pytest.mark.parametrize("args, words", [
    (["--harmonics", "1"], "--harmonics: expected a whole number ≥ 2"),
    (["--velocity-limit", "1,2,3"], "--velocity-limit: expected one value or 2"),
    (["--position-limit", "1:-1"], "--position-limit: expected X > 0 or LO:HI"),
    ([], "--position-limit: the model has no joint limits"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, args, words):
    out = tmp_path / "out"
    extra = [] if args == [] or args[0] == "--position-limit" else ["--position-limit", "1"]
    assert main(["excite", "example-6.3.1", *extra, *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err
    assert not out.exists()
