"""A newcomer's first hour (issue "The first hour, again"): a run whose numbers are the actuator's says so, the torque
figure draws the limit, and each warning of the summary line is the rule written here by hand."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.analysis.metrics import LYAPUNOV_GROWTH, WINDUP_GROWTH, WINDUP_SATURATED, health_warnings, metrics
from robotadapt.cli.common import summary
from robotadapt.studies.scenarios import load

THREE_LINKS = """
description = "a 3-link planar arm with a 50 N·m limit"
[robot]
kind = "planar"
n_links = 3
masses = [2.0, 1.0, 0.5]
lengths = [1.0, 0.8, 0.5]
[plant]
torque_limit = 50.0
[trajectory]
kind = "sinusoid"
amplitude = 1.0
omega = 2.0
[controller]
kind = "slotine_li"
Lam = 5.0
Kv = 50.0
Gamma = 5.0
[simulation]
t_final = 2.0
dt = 1e-3
"""


def expected(m: dict) -> list[str]:
    """The rules, by hand: which warnings a run's metrics call for."""
    start = max(np.linalg.norm(m.get("initial_phi_hat", [0.0])), np.linalg.norm(m.get("phi_true", [0.0])), 1e-12)
    sat = m.get("saturated_fraction") or 0.0
    grew = (m.get("max_phi_hat_norm") or 0.0) > WINDUP_GROWTH * start  # at any time
    ends_far = np.linalg.norm(m.get("final_phi_hat", [0.0])) > WINDUP_GROWTH * start  # at the end
    out = ["wind-up"] if sat > WINDUP_SATURATED and grew else ["saturation"] if sat > WINDUP_SATURATED else \
        ["estimate drift"] if ends_far else []
    if "V_initial" in m and m["V_final"] > LYAPUNOV_GROWTH * m["V_initial"]:
        out.append("Lyapunov growth")
    return out


@pytest.mark.parametrize("m", [
    {"saturated_fraction": 0.9, "max_phi_hat_norm": 1.0, "initial_phi_hat": [1.0]},  # saturated alone
    {"saturated_fraction": 0.9, "max_phi_hat_norm": 50.0, "initial_phi_hat": [1.0]},  # wind-up
    {"saturated_fraction": 0.1, "max_phi_hat_norm": 50.0, "final_phi_hat": [45.0], "initial_phi_hat": [1.0],
     "phi_true": [2.0]},  # drift: it ends far out
    {"max_phi_hat_norm": 50.0, "final_phi_hat": [2.1], "initial_phi_hat": [1.0], "phi_true": [2.0]},  # a transient
    {"max_phi_hat_norm": 15.0, "initial_phi_hat": [0.0], "phi_true": [2.0]},  # within 10 × ‖φ‖: quiet
    {"max_phi_hat_norm": 1.0, "initial_phi_hat": [1.0], "V_initial": 1.0, "V_final": 11.0},  # V grew
    {"max_phi_hat_norm": 1.0, "initial_phi_hat": [1.0], "V_initial": 1.0, "V_final": 0.5},  # V fell: quiet
])
def test_each_warning_follows_its_rule(m):
    got = health_warnings(m)
    assert [w.split(":")[0] for w in got] == expected(m)
    assert all(" — " in w for w in got)  # each names its remedy or its cause after the dash


def test_a_saturated_three_link_arm_is_not_reported_as_fine(tmp_path):
    """The newcomer's arm: torque on its 50 N·m limit nearly all the time, V growing by orders of magnitude. The
    summary line says so (the shares written here from the logged torques), and the torque figure draws ±50."""
    from robotadapt.report.figures import torques_figure

    path = tmp_path / "three.toml"
    path.write_text(THREE_LINKS)
    res = load(str(path)).run()
    m = metrics(res)
    on_limit = np.any(np.abs(res.tau) >= 50.0 - 1e-12, axis=-1).mean()  # the applied torque sits on ±50
    assert m["saturated_fraction"] == pytest.approx(on_limit, abs=1e-3) and on_limit > WINDUP_SATURATED
    line = summary("three", m)
    assert res.status == "ok" and "warning:" in line
    assert [w.split(":")[0] for w in health_warnings(m)] == expected(m) and expected(m)
    fig = torques_figure(res, model=load(str(path)).setup.plant.model)
    levels = {round(float(y), 9) for ax in fig.axes for line2d in ax.get_lines()
              if len(set(np.asarray(line2d.get_ydata(), dtype=float))) == 1 for y in line2d.get_ydata()}
    assert {50.0, -50.0} <= levels


def test_the_pe_legend_says_one_parameter_only_for_one():
    """Example 6.5.2(a): q_d = sin t over windows of 2π excites m and b equally, λ_max = λ_min: two parameters, so the
    legend must not say "one parameter"; for a one-parameter model it may."""
    from robotadapt.analysis.excitation import excitation
    from robotadapt.report.html import coincidence_note

    s = load("example-6.5.2a").setup
    exc = excitation(s.controller.model, s.trajectory, s.t_final, 2 * np.pi)
    # by hand: Y_d = [q̈_d, q̇_d] = [−sin t, cos t]; over a window of 2π its Gram matrix is π I, both eigenvalues π
    assert len(exc.param_names) == 2
    np.testing.assert_allclose(exc.alpha, np.pi, rtol=1e-6)
    np.testing.assert_allclose(exc.beta, np.pi, rtol=1e-6)
    note = coincidence_note(exc.beta, exc.alpha, len(exc.param_names))
    assert "one parameter" not in note and "λ_max = λ_min" in note
    assert "one parameter" in coincidence_note(exc.beta, exc.beta, 1)
    assert coincidence_note(exc.beta, exc.beta / 2, 2) == ""


def test_the_gallery_says_a_run_stopped_early_and_counts_in_full():
    """Example 6.2.2 as the book ran it stops in its first step: the gallery's section says so, with the status, and
    counts like n_samples read in full (20001, not 2e+04)."""
    from robotadapt.report.html import GalleryEntry, gallery_html

    s = load("example-6.2.2", ["simulation.t_final=0.5"])
    res = s.run()
    assert res.status != "ok"
    m = metrics(res) | {"n_samples": 20001}
    page = gallery_html([GalleryEntry("example-6.2.2", s.description, "", {}, m, 0.5, 0.5, 0.1)])
    assert "This run stopped early, at t = 0 s of 0.5 s: diverged within the step from 0 to 0.001 s" in page
    assert ">20001<" in page and "2e+04" not in page
