"""Figures a control-paper reader accepts, read back from the matplotlib Figure objects: titles, axis labels with units
per joint type (the polar arm has a revolute and a prismatic joint), mathtext symbols, coinciding curves that stay
visible, distinguishable styles for the twelve laws of `robotadapt compare`, log axes where they belong, and tables that
align when names carry combining accents.
"""

from __future__ import annotations

import re

import matplotlib.pyplot as plt
import numpy as np
import pytest

from robotadapt.analysis.excitation import excitation
from robotadapt.analysis.metrics import metrics
from robotadapt.report import figures
from robotadapt.report.figures import joint_types, parameter_unit, parameter_units, tex_name
from robotadapt.report.html import display_width, excitation_plot, overlay_figure, table_text
from robotadapt.report.sweep_figures import log_spaced, summary_plot
from robotadapt.robots.one_link import OneLinkArm
from robotadapt.robots.polar import PolarArm
from robotadapt.robots.two_link import TwoLinkArm
from robotadapt.studies.compare import compare, contenders
from robotadapt.studies.scenarios import load
from robotadapt.studies.study import StudyRun


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def polar():
    """Problem 6.2-1: the polar arm (θ revolute, r prismatic), adaptive computed torque estimating m, 0.3 s."""
    scenario = load("problem-6.2-1", ["simulation.t_final=0.3"])
    return scenario, scenario.run()


@pytest.fixture(scope="module")
def comparison():
    """Every law of the lineup on Example 6.3.1's arm, 0.05 s."""
    rows, skipped = compare(load("example-6.3.1", ["simulation.t_final=0.05"]))
    assert not skipped
    return rows


def texts(fig) -> dict[str, list[str]]:
    """Every title, axis label and legend entry of a figure."""
    axes = [ax for ax in fig.axes if ax.get_visible()]
    legends = [t.get_text() for ax in axes if ax.get_legend() for t in ax.get_legend().get_texts()]
    return {"suptitle": [fig._suptitle.get_text() if fig._suptitle else ""],
            "titles": [ax.get_title() for ax in axes], "ylabels": [ax.get_ylabel() for ax in axes],
            "xlabels": [ax.get_xlabel() for ax in axes], "legends": legends}


# ---------------------------------------------------------------------------------------------------------------------
# units


def test_joint_types_and_parameter_units_come_from_the_model():
    assert joint_types(PolarArm()) == "RP" and joint_types(TwoLinkArm()) == "RR" and joint_types(OneLinkArm()) == "R"
    assert joint_types(object()) is None
    assert parameter_units(TwoLinkArm(friction_terms=True), ["m1", "m2", "fv1", "fv2"]) == \
        ["kg", "kg", "N·m·s/rad", "N·m·s/rad"]
    assert parameter_units(PolarArm(friction_terms=True), ["m", "fv1", "fv2"]) == ["kg", "N·m·s/rad", "N·s/m"]
    assert parameter_units(OneLinkArm(), ["m", "b"]) == ["kg·m²", "N·m·s/rad"]  # its m is the joint's inertia
    assert [parameter_unit(n, "RP") for n in ("mx1", "Izz2", "Ia2", "fc2", "Izz1 + m2")] == \
        ["kg·m", "kg·m²", "kg", "N", None]
    assert parameter_unit("fv3") == "N·m·s/rad or N·s/m"  # joint type unknown: both
    assert tex_name("m2") == "$m_{2}$" and tex_name("fv1", hat=True) == r"$\hat{f}_{v1}$" and tex_name("m") == "$m$"


def test_tracking_error_and_torques_have_units_per_joint_type(polar):
    scenario, res = polar
    model = scenario.setup.controller.model
    t = texts(figures.tracking_error_figure(res, "problem-6.2-1", model))
    assert "problem-6.2-1" in t["suptitle"][0] and "$e = q_d - q$" in t["suptitle"][0]
    # per joint type e on a linear axis, then |e| on a log one (a convergence to round-off shows there)
    assert [label.rsplit("(", 1)[1] for label in t["ylabels"]] == ["rad)", "rad), log scale", "m)", "m), log scale"]
    assert t["titles"] == ["revolute joint", "", "prismatic joint", ""]  # the log panel sits under its type's
    fig = figures.tracking_error_figure(res, "problem-6.2-1", model)
    assert [ax.get_yscale() for ax in fig.axes] == ["linear", "log", "linear", "log"]
    logged = fig.axes[1].get_lines()[0].get_ydata()
    np.testing.assert_array_equal(logged, np.where(np.abs(res.e[:, 0]) > 0, np.abs(res.e[:, 0]), np.nan))
    assert {"$e_{1}$", "$e_{2}$"} <= set(t["legends"]) and t["xlabels"][-1] == "time $t$ (s)"
    t = texts(figures.torques_figure(res, "problem-6.2-1", model))
    assert [label.rsplit("(", 1)[1] for label in t["ylabels"]] == ["N·m)", "N)"]
    assert t["ylabels"][0].startswith("torque") and t["ylabels"][1].startswith("force")
    assert {r"$\tau_{1}$", r"$\tau_{2}$"} <= set(t["legends"]) and r"$\tau$" in t["suptitle"][0]


def test_without_a_model_the_axes_say_rad_or_m(polar):
    _, res = polar
    assert texts(figures.tracking_error_figure(res))["ylabels"] == ["tracking error $e_i$ (rad or m)",
                                                                   "$|e_i|$ (rad or m), log scale"]
    assert texts(figures.torques_figure(res))["ylabels"] == [r"torque or force $\tau_i$ (N·m or N)"]


def test_parameter_axes_carry_units_and_estimate_and_truth_both_show(polar):
    scenario, res = polar
    fig = figures.parameters_figure(res, "problem-6.2-1", scenario.setup.controller.model)
    t = texts(fig)
    assert t["ylabels"] == [r"$\hat{\varphi}_i$, $\varphi_i$ (kg)"]
    assert r"$\hat{\varphi}$" in t["suptitle"][0] and r"$\varphi$" in t["suptitle"][0]
    assert set(t["legends"]) == {r"$\hat{m}$", "$m$ true"}
    estimate, truth = fig.axes[0].get_lines()
    assert estimate.get_color() == truth.get_color()
    assert (estimate.get_linestyle(), estimate.get_marker()) != (truth.get_linestyle(), truth.get_marker())


def test_parameters_split_into_one_panel_per_unit():
    res = load("example-6.3.1", ["simulation.t_final=0.05", "robot.friction_terms=true", "plant.phi=[0.8, 2.3, 1, 1]",
                                 "controller.phi_hat0=[0, 0, 0, 0]"]).run()
    t = texts(figures.parameters_figure(res, model=TwoLinkArm(friction_terms=True)))
    assert [label.rsplit("(", 1)[1] for label in t["ylabels"]] == ["kg)", "N·m·s/rad)"]


def test_study_overlay_has_units_and_starts_at_the_first_nonzero_error():
    scenario = load("example-6.3.1", ["simulation.t_final=0.1"])
    runs = [StudyRun("controller.Kv", kv, scenario.variant(f"controller.Kv={kv}").run()) for kv in (5.0, 20.0)]
    fig = figures.study_figure("controller.Kv", runs, "example-6.3.1", scenario.setup.controller.model)
    t = texts(fig)
    assert t["ylabels"][0] == r"$\Vert e(t)\Vert$ (rad)" and "effect of controller.Kv" in t["suptitle"][0]
    for line in fig.axes[0].get_lines():
        y = np.asarray(line.get_ydata(), dtype=float)
        assert np.isnan(y[0]) and np.all(np.isnan(y) | (y > 1e-15))  # e(0) = 0 is left out, not drawn at 1e-16
    assert [line.get_label() for line in fig.axes[0].get_lines()] == ["Kv = 5", "Kv = 20"]  # the key is in the title


def test_a_study_over_numbers_takes_an_ordered_colour_scale():
    """Values given out of order (20, 0.0001, 5): colours follow the values' order along viridis, not the list's."""
    from types import SimpleNamespace

    from matplotlib.colors import to_rgba

    runs = [SimpleNamespace(value=v) for v in (20.0, 1e-4, 5.0)]
    colours = [to_rgba(figures.study_style(runs, i)["color"]) for i in range(3)]
    viridis = plt.get_cmap("viridis")
    assert colours == [viridis(0.9), viridis(0.0), viridis(0.45)]
    words = [SimpleNamespace(value=v) for v in ("euler", "hold")]
    assert [figures.study_style(words, i)["color"] for i in range(2)] == [figures.style(i)["color"] for i in range(2)]


# ---------------------------------------------------------------------------------------------------------------------
# persistency of excitation


def test_pe_figure_renders_its_mathematics_and_keeps_coinciding_curves_visible():
    """Problem 6.2-1 estimates one parameter: α = β, λ_min = λ_max; both curves must stay visible."""
    s = load("problem-6.2-1").setup
    fig = excitation_plot(excitation(s.controller.model, s.trajectory, s.t_final), "problem-6.2-1")
    t = texts(fig)
    everything = " ".join(sum(t.values(), []))
    assert "∫_0^t" not in everything and "Y_dᵀ" not in everything  # no raw pseudo-TeX
    assert r"$\lambda_{\min} \int_0^t Y_d^T Y_d\,d\sigma$" in t["titles"][1]
    assert r"\int_{t_0}^{t_0+\rho}" in t["ylabels"][0] and r"$\rho$" in t["titles"][0]
    for ax in fig.axes:
        beta, alpha = ax.get_lines()[:2]
        np.testing.assert_allclose(alpha.get_ydata(), beta.get_ydata(), rtol=1e-6)  # they do coincide
        assert alpha.get_linestyle() != beta.get_linestyle() and alpha.get_marker() not in ("None", "", None)
        assert alpha.get_linewidth() < beta.get_linewidth()
    assert any("coincide" in text for text in t["legends"])


# ---------------------------------------------------------------------------------------------------------------------
# the comparison


def test_compare_figure_gives_every_law_its_own_colour_and_dash(comparison):
    fig = overlay_figure(comparison, "e")
    labels = {r.entry.label for r in comparison}
    styles = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            if line.get_label() in labels:
                styles.setdefault(line.get_label(), set()).add((line.get_color(), line.get_linestyle()))
    assert set(styles) == labels and all(len(s) == 1 for s in styles.values())
    pairs = [next(iter(s)) for s in styles.values()]
    assert len(set(pairs)) == len(comparison) == len(contenders("joint")) == 12
    assert len({color for color, _ in pairs}) >= 10 and len({dash for _, dash in pairs}) >= 3
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) >= 3 and all(len(ax.get_lines()) <= 6 for ax in visible)  # small multiples, not 12 on one
    assert all(r"$\Vert e(t)\Vert$ (rad)" == ax.get_ylabel() for ax in visible if ax.get_ylabel())


def test_compare_error_axis_starts_at_the_first_nonzero_error(comparison):
    assert all(float(np.linalg.norm(r.result.e[0])) == 0.0 for r in comparison)  # every run starts on the trajectory
    fig = overlay_figure(comparison, "e")
    smallest = min(float(np.min(np.linalg.norm(r.result.e[1:], axis=-1))) for r in comparison)
    for ax in fig.axes:
        for line in ax.get_lines():
            y = np.asarray(line.get_ydata(), dtype=float)
            assert np.isnan(y[0]) and np.all(np.isnan(y) | (y > 0))
        if ax.get_visible():
            assert ax.get_ylim()[0] >= smallest / 2.01


def test_rms_error_norm_is_one_definition(comparison):
    for row in comparison:
        m = metrics(row.result)
        e = row.result.e
        assert m["rms_error_norm"] == pytest.approx(float(np.sqrt(np.mean(np.sum(e**2, axis=-1)))), rel=1e-12)
        assert m["rms_error_norm"] == pytest.approx(float(np.linalg.norm(m["rms_error"])), rel=1e-12)
        assert row.metrics["rms_error_norm"] == m["rms_error_norm"] and "rms_error" not in row.metrics


def test_table_aligns_with_combining_accents(comparison):
    assert display_width("φ̂") == 1 and display_width("‖φ̃‖") == 3 and len("φ̂") == 2
    lines = table_text(comparison).splitlines()
    assert any("φ̂" in line for line in lines)
    assert len({display_width(line.rstrip()) for line in lines}) == 1, lines
    header = lines[0]
    for line in lines[1:]:  # the columns end where the header's do
        assert display_width(line) == display_width(header)


# ---------------------------------------------------------------------------------------------------------------------
# sweeps


def _rows(gammas: list[float], per_value: int) -> list[dict]:
    rng = np.random.default_rng(0)
    rows = []
    for g in gammas:
        for _ in range(per_value):
            phi = [float(rng.uniform(0.6, 1)), float(rng.uniform(2, 2.6))]
            rows.append({"run": len(rows), "controller.Gamma": g, "plant.phi": phi, "status": "ok",
                         "rms_error": [0.1 / g**0.3 + 0.01 * phi[0], 0.05], "param_names": ["m1", "m2"]})
    return rows


def test_log_spaced_grids_are_recognised():
    assert log_spaced(np.array([1.0, 10, 100])) and log_spaced(np.array([5.0, 10, 20, 40]))
    assert not log_spaced(np.array([1.0, 2, 3])) and not log_spaced(np.array([0.0, 10, 100]))
    assert not log_spaced(np.array([1.0, 1.0]))


def test_sweep_figure_log_axis_names_and_colours_by_grid_value():
    rows = _rows([1.0, 10.0, 100.0], 5)
    fig = summary_plot(rows, ["controller.Gamma", "plant.phi"], "rms_error", "example-6.3.1",
                       grid=["controller.Gamma"])
    gamma, m1, m2 = fig.axes
    assert gamma.get_xscale() == "log" and m1.get_xscale() == "linear"
    assert "$m_{1}$ (kg)" in m1.get_xlabel() and "$m_{2}$ (kg)" in m2.get_xlabel()
    assert "plant.phi[" not in m1.get_xlabel() + m2.get_xlabel()
    for ax in (gamma, m1, m2):  # the same three colours, one per grid value, in every panel
        dots = [line for line in ax.get_lines() if line.get_marker() == "o"]
        assert [line.get_label() for line in dots] == ["Gamma = 1", "Gamma = 10", "Gamma = 100"]
        assert len({line.get_color() for line in dots}) == 3
    assert any("median" in line.get_label() for line in gamma.get_lines())  # 5 runs per value


def test_sweep_figure_draws_no_median_through_single_samples():
    rows = _rows([1.0, 10.0, 100.0], 1)
    fig = summary_plot(rows, ["controller.Gamma"], "rms_error", grid=["controller.Gamma"])
    assert not any("median" in line.get_label() for line in fig.axes[0].get_lines())
    assert fig.axes[0].get_xscale() == "log"


def test_sweep_summary_prints_four_significant_digits(tmp_path, capsys):
    from robotadapt.cli import main

    code = main(["sweep", "example-6.3.1", "--t-final", "0.05", "--random", "plant.phi=[0.6,2]:[1,2.6]", "--n", "2",
                 "--workers", "1", "--out", str(tmp_path / "sw"), "--no-plots"])
    assert code == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if "best" in line)
    best = re.search(r"plant\.phi=\[([^\]]*)\]", line)
    assert best is not None, line
    for value in best.group(1).split(", "):
        assert len(value.replace(".", "").replace("-", "").lstrip("0")) <= 4, line


def test_parameters_figure_of_a_three_link_planar_arm_shows_base_parameters():
    """Issue 16, item 4: the figure plots what the dynamics see, ‖K(φ − φ̂)‖/‖Kφ‖, and counts the hidden directions."""
    scenario = load("example-6.3.1", ["robot={kind='planar', n_links=3}", "plant={q0=[0.0, 0.0, 0.0], dq0=[0.0, 0.0, 0.0]}",
                                      "controller.phi_hat0={scale=0.7}", "simulation.t_final=0.1",
                                      "simulation.backend='numpy'"])
    model = scenario.setup.controller.model
    res = scenario.run()
    fig = figures.parameters_figure(res, "planar3", model)
    assert "21 of 30 directions unidentifiable" in fig._suptitle.get_text()
    (ax,) = fig.axes
    (line,) = ax.get_lines()
    assert line.get_label() == "9 base parameters"
    from robotadapt.robots import base_parameters

    K = base_parameters(model).K
    expected = np.linalg.norm((res.phi - res.phi_hat) @ K.T, axis=-1) / np.linalg.norm(K @ res.phi)
    np.testing.assert_allclose(line.get_ydata(), np.maximum(expected, line.get_ydata().min()), rtol=1e-12)
    plain = figures.parameters_figure(res, "planar3")  # without the model: the standard relative error, as before
    assert "unidentifiable" not in plain._suptitle.get_text()
