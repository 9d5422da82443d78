"""Exciting trajectories (issue 27, docs/identification.md#excitation): the parametrisation starts and ends at rest, the
JAX gradient of the objective equals central differences (and its value the SVD's), the optimiser keeps every limit
between its samples (checked on a grid of our own), lowers cond W below its start's and the scenario's own trajectory's,
reads a URDF's limits, and `robotadapt excite` writes a trajectory a scenario runs; each compiled program is traced once
a run; `--max-iter` and `--time-budget` stop the search and say so (issue 43); the figure has units and its legends
cover no data; bad input is one line."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

import robotadapt.studies.excite as excite_module
from robotadapt.cli import main
from robotadapt.report.identification_figures import excitation_plot
from robotadapt.robots import TwoLinkArm
from robotadapt.robots.identifiability import base_parameters
from robotadapt.robots.kinematic_tree import KinematicTree
from robotadapt.studies.excite import Design, Programs, before, excite, resolve_limits, spectrum_scores, stacked_regressor
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


def svd_objective(model, independent: np.ndarray, design: Design, t: np.ndarray, objective: str, x: np.ndarray) -> float:
    """The objective as defined, by numpy: log cond W or −log det WᵀW from the SVD of W."""
    log_cond, log_det = spectrum_scores(stacked_regressor(model, independent, *design.motion(x, t)))
    return float(log_cond if objective == "cond" else -log_det)


def two_link_scenario(tmp_path, arm):
    """A scenario of the two-link URDF arm (its limits: |q| ≤ 1 rad, |q̇| ≤ 1 rad/s, |τ| ≤ 10 N·m)."""
    scenario = tmp_path / "arm.toml"
    scenario.write_text(f'[robot]\nkind = "urdf"\npath = "{arm}"\n[plant]\nq0 = 0.0\n[trajectory]\nkind = "sinusoid"\n'
                        'amplitude = 0.5\nomega = 1.0\n[controller]\nkind = "slotine_li"\nLam = 5.0\nKv = 2.0\n'
                        'Gamma = 1.0\nphi_hat0 = {scale = 0.7}\n[simulation]\nt_final = 4.0\ndt = 1e-3\n')
    return scenario


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
        fd = np.array([(svd_objective(model, independent, design, design.grid(40), objective, x + h * e)
                        - svd_objective(model, independent, design, design.grid(40), objective, x - h * e)) / (2 * h)
                       for e in np.eye(design.size)])
        assert np.max(np.abs(g - fd)) < 1e-6 * max(1.0, np.max(np.abs(g)))
    J = np.asarray(programs.jacobian(x))
    fd = np.stack([(np.asarray(programs.constraints(x + h * e)) - np.asarray(programs.constraints(x - h * e))) / (2 * h)
                   for e in np.eye(design.size)], axis=1)
    assert np.max(np.abs(J - fd)) < 1e-6 * max(1.0, np.max(np.abs(J)))


@float64
def test_on_the_books_two_link_arm_the_jax_gradient_equals_finite_differences_and_the_value_the_svds():
    """The two-link arm of the book (l1 = l2 = 1 m, masses m1, m2), 3 harmonics: the compiled value and gradient of each
    objective against its definition, log cond W or −log det WᵀW by numpy's SVD of W, and that definition's central
    differences (relative 1e-6); and the constant Jacobian of the position, velocity and acceleration rows against central
    differences of the constraints."""
    model = TwoLinkArm()
    design = Design(2, 3, 2.0)
    limits = resolve_limits(model, {"position": np.array([[-2.0, 2.0], [-1.5, 2.5]]), "velocity": np.array([3.0, 4.0]),
                                    "acceleration": np.array([10.0, 12.0])})
    independent = np.array(base_parameters(model).independent)
    t = design.grid(24)
    x = 0.3 * np.random.default_rng(2).normal(size=design.size)
    h = 1e-6
    for objective in ("cond", "logdet"):
        programs = Programs(model, design, independent, limits, t, objective)
        f, g = programs.objective(x)
        assert f == pytest.approx(svd_objective(model, independent, design, t, objective, x), rel=1e-10)
        fd = np.array([(svd_objective(model, independent, design, t, objective, x + h * e)
                        - svd_objective(model, independent, design, t, objective, x - h * e)) / (2 * h)
                       for e in np.eye(design.size)])
        assert np.max(np.abs(g - fd)) <= 1e-6 * np.max(np.abs(g))
    J = programs.jacobian(x)
    fd = np.stack([(np.asarray(programs.constraints(x + h * e)) - np.asarray(programs.constraints(x - h * e))) / (2 * h)
                   for e in np.eye(design.size)], axis=1)
    assert J.shape == (2 * 3 * t.size * 2, design.size)
    assert np.max(np.abs(J - fd)) <= 1e-6 * np.max(np.abs(J))


def test_each_compiled_program_is_traced_once_a_run(arm, monkeypatch):
    """Two starts of several SLSQP iterations each: the objective (the stacked regressor) is traced once, the inverse
    dynamics twice (the constraints and τ's Jacobian): no program is traced again per iteration or per start."""
    model = KinematicTree.from_urdf(arm)
    traced = {"objective": 0, "torque": 0}

    def counting(name, fn):
        def wrapper(*args, **kwargs):
            traced[name] += any(isinstance(a, jax.core.Tracer) for a in args)
            return fn(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(excite_module, "stacked_regressor", counting("objective", stacked_regressor))
    monkeypatch.setattr(KinematicTree, "inverse_dynamics", counting("torque", KinematicTree.inverse_dynamics))
    result = excite(model, Design(2, 3, 4.0), resolve_limits(model, {}), samples=40, starts=2, max_iter=30)
    assert len(result.iterations) == 2 and sum(result.iterations) >= 10
    assert traced == {"objective": 1, "torque": 2}


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
    scenario = two_link_scenario(tmp_path, arm)
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


def test_max_iter_1_stops_every_start_after_one_iteration_and_says_so(tmp_path, arm, capsys):
    out = tmp_path / "ex"
    assert main(["excite", str(two_link_scenario(tmp_path, arm)), "--harmonics", "3", "--period", "4", "--starts", "2",
                 "--samples", "40", "--max-iter", "1", "--no-plots", "--out", str(out)]) == 0
    record = json.loads((out / "excite.json").read_text())
    assert record["iterations"] == [1, 1] and record["max_iter"] == 1
    assert record["stopped"] == "iteration cap 1" and record["exits"] == ["Iteration limit reached"] * 2
    assert record["limits_met"]
    printed = capsys.readouterr()
    assert "stopped: iteration cap 1" in printed.out
    assert printed.err == ""  # no progress bar when stderr is not a terminal


def test_the_time_budget_stops_the_search_at_its_best_feasible_point_and_says_so(tmp_path, arm, capsys):
    """A budget spent before the first iteration ends (the compilation alone takes longer): the first start's run
    stops after one iteration, no other start begins, and what is kept is feasible and no worse than the start."""
    out = tmp_path / "ex"
    assert main(["excite", str(two_link_scenario(tmp_path, arm)), "--harmonics", "3", "--period", "4", "--starts", "3",
                 "--samples", "40", "--time-budget", "0.001", "--no-plots", "--out", str(out)]) == 0
    record = json.loads((out / "excite.json").read_text())
    assert record["stopped"] == "time budget 0.001 s" and record["time_budget"] == 0.001
    assert record["iterations"] == [1] and record["starts_run"] == 1 and record["starts"] == 3
    assert record["exits"] == ["time budget"]
    assert record["final_objectives"][0] <= record["start_objectives"][0] and record["limits_met"]
    assert "stopped: time budget 0.001 s (1 of 3 starts, iterations 1)" in capsys.readouterr().out


@float64
def test_the_figure_gives_units_and_its_legends_cover_no_data(arm):
    """The unbounded acceleration of the URDF arm in rad/s², the bounds in rad, rad/s and N·m; each legend's box
    outside every axes' box."""
    model = KinematicTree.from_urdf(arm)
    limits = resolve_limits(model, {})
    design = Design(2, 3, 4.0)
    result = excite(model, design, limits, samples=40, starts=1, max_iter=5)
    from robotadapt.trajectories import sinusoid

    old = sinusoid(2)
    fig = excitation_plot(model, result, old, before(model, old, 4.0, design, 40, limits))
    axes = fig.axes
    assert axes[2].get_ylabel() == r"$\ddot q$ (rad/s²)"
    assert "rad" in axes[0].get_title() and "rad/s" in axes[1].get_title() and "N·m" in axes[3].get_title()
    renderer = fig.canvas.get_renderer()
    legends = [ax.get_legend() for ax in axes if ax.get_legend() is not None]
    assert len(legends) == 2
    for box in (lg.get_window_extent(renderer) for lg in legends):
        assert not any(box.overlaps(ax.get_window_extent(renderer)) for ax in axes)


@pytest.mark.parametrize("args, words", [
    (["--harmonics", "1"], "--harmonics: expected a whole number ≥ 2"),
    (["--velocity-limit", "1,2,3"], "--velocity-limit: expected one value or 2"),
    (["--position-limit", "1:-1"], "--position-limit: expected X > 0 or LO:HI"),
    ([], "--position-limit: the model has no joint limits"),
    *[(["--max-iter", bad], "--max-iter: expected a whole number of iterations ≥ 1, e.g. --max-iter 100")
      for bad in ("0", "-3", "2.5", "many")],
    *[(["--time-budget", bad], "--time-budget: expected a positive number of seconds, e.g. --time-budget 60")
      for bad in ("0", "-5", "soon", "inf", "nan")],
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, args, words):
    out = tmp_path / "out"
    extra = [] if args == [] or args[0] == "--position-limit" else ["--position-limit", "1"]
    assert main(["excite", "example-6.3.1", *extra, *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err
    assert not out.exists()
