"""A newcomer's complaints about figures and output (issue 43, item 11): the per-round figure's title and ticks, the
tuning figure's units, wording and shape, the run summary's units and width, the saved scenario's arrays, and the
names of the columns of the controller's state in result.npz."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tomli_w

from robotadapt.cli import main
from robotadapt.studies.scenarios import load

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

WIDTH = 100  # the widest line the summary may print

SEVEN_LINKS = """
description = "a 7-link planar arm"
[robot]
kind = "planar"
n_links = 7
[trajectory]
kind = "sinusoid"
amplitude = 0.5
omega = 1.0
[controller]
kind = "slotine_li"
Lam = 5.0
Kv = 20.0
Gamma = 5.0
[simulation]
t_final = 0.05
"""

#: a mass and a length whose shortest decimal forms are 17 digits long
THREE_LINKS = f"""
description = "a 3-link planar arm"
[robot]
kind = "planar"
n_links = 3
masses = [{7 / 3!r}, 1.5, 1.1]
lengths = [1.0, 0.8, {2 / 3!r}]
[trajectory]
kind = "sinusoid"
amplitude = 0.5
omega = 1.0
[controller]
kind = "slotine_li"
Lam = 5.0
Kv = 20.0
Gamma = 5.0
phi_hat0 = {{scale = 0.7}}
[simulation]
t_final = 0.05
"""


# ---------------------------------------------------------------------------------------------------------------------
# a. the per-round figure (rounds.png of examples/natural_study.py)


def test_the_rounds_figure_has_whole_rounds_and_its_whole_title():
    from robotadapt.report.figures import rounds_figure

    rms = {"no adaptation": [9.9, 9.5, 9.2, 9.0, 8.8], "Euclidean (Γ)": [2.9, 2.5, 2.2, 2.0, 1.9],
           "natural (γ)": [2.0, 1.0, 0.7, 0.45, 0.32]}
    fig = rounds_figure(rms, "Panda, 2 kg payload, 1 kHz: adaptation from the payload-free estimate",
                        "mean RMS tracking error (deg)", "round (5 s each)")
    fig.canvas.draw()
    (ax,) = fig.axes
    low, high = ax.get_xlim()
    shown = [(tick, label.get_text()) for tick, label in zip(ax.get_xticks(), ax.get_xticklabels(), strict=True)
             if low <= tick <= high]
    assert [text for _, text in shown] == ["1", "2", "3", "4", "5"]
    title = ax.title.get_window_extent()
    assert ax.title.get_text().startswith("Panda") and title.width > 0
    assert fig.bbox.x0 <= title.x0 and title.x1 <= fig.bbox.x1 and fig.bbox.y0 <= title.y0 and title.y1 <= fig.bbox.y1


# ---------------------------------------------------------------------------------------------------------------------
# b. tune.png


@pytest.fixture(scope="module")
def one_iteration() -> Any:
    """A tuning of one gain that stops after one iteration (two differentiated runs)."""
    from robotadapt.studies.tune import tune

    tuned = tune(load("example-6.3.1", ["simulation.t_final=0.2"]), ["controller.Kv"], "rms_error", max_torque=1e4,
                 max_runs=2, screen=2)
    assert len(tuned.search.iterations) == 1
    return tuned


def _texts(fig: Any) -> list[str]:
    return [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text"))]


def test_the_tuning_figure_has_units_a_readable_shape_and_counts_in_words(one_iteration):
    from robotadapt.report.tune_figures import tuning_figure

    fig = tuning_figure(one_iteration)
    texts = _texts(fig)
    assert not [t for t in texts if "1 iterations" in t or "1 differentiated runs" in t]
    assert any(t.startswith("1 iteration, 2 differentiated runs") for t in texts)
    labels = {ax.get_ylabel() for ax in fig.axes}
    assert "‖e(t)‖ (rad)" in labels and "max_i |τ_i(t)| (N·m)" in labels
    assert any("peak |τ| (N·m)" in label for label in labels)  # the budget's axis
    width, height = fig.get_size_inches()
    assert 0.5 <= width / height <= 2.0
    assert all(abs(tick - round(tick)) < 1e-12 for tick in fig.axes[0].get_xticks()
               if fig.axes[0].get_xlim()[0] <= tick <= fig.axes[0].get_xlim()[1])


def test_tune_figure_writes_the_figure(one_iteration, tmp_path):
    from robotadapt.report.tune_figures import tune_figure

    path = tune_figure(one_iteration, tmp_path / "tune.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------------------------------------------------------------
# c. the summary of `robotadapt run`


def test_the_summary_of_a_seven_joint_run_is_narrow_and_says_its_units(tmp_path, capsys):
    path = tmp_path / "seven.toml"
    path.write_text(SEVEN_LINKS)
    assert main(["run", str(path), "--no-plots", "--out", str(tmp_path / "out")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert max(map(len, lines)) <= WIDTH, "\n".join(lines)
    assert lines[0] == "seven: ok; t = 0.05 s"
    by_label = {line.split("=")[0].strip(): line for line in lines if "=" in line}
    for label, unit in (("final |e|", "] rad"), ("RMS e", "] rad"), ("max |τ|", "] N·m")):
        assert by_label[label].endswith(unit) and by_label[label].count(",") == 6, by_label[label]


def test_the_summary_gives_each_joint_and_parameter_its_unit():
    """The polar arm: a revolute joint (rad, N·m) and a prismatic one (m, N); its one parameter is a mass (kg)."""
    from robotadapt.analysis.metrics import metrics
    from robotadapt.cli.common import summary

    scenario = load("problem-6.3-1", ["simulation.t_final=0.05"])
    model = scenario.setup.controller.model
    lines = summary("polar", metrics(scenario.run(), model), model).splitlines()
    assert lines[1].startswith("  final |e| = [") and lines[1].endswith(" m]") and " rad, " in lines[1]
    assert lines[3].startswith("  max |τ|   = [") and lines[3].endswith(" N]") and " N·m, " in lines[3]
    assert lines[4].startswith("  final m = ") and lines[4].endswith(" kg")


# ---------------------------------------------------------------------------------------------------------------------
# d. the saved scenario.toml


def test_the_saved_scenario_writes_phi_on_one_line_and_reproduces_the_run(tmp_path, capsys):
    path = tmp_path / "three.toml"
    path.write_text(THREE_LINKS)
    first, second = tmp_path / "first", tmp_path / "second"
    assert main(["run", str(path), "--no-plots", "--out", str(first)]) == 0
    saved = (first / "scenario.toml").read_text()
    phi = [line for line in saved.splitlines() if line.startswith("phi = ")]
    assert len(phi) == 1 and phi[0].endswith("]") and len(saved.splitlines()) < 50
    data = load(str(path)).setup.data
    read = tomllib.loads(saved)
    assert read == tomllib.loads(tomli_w.dumps(data))  # what the former writer read back
    assert [v.hex() for v in read["plant"]["phi"]] == [float(v).hex() for v in data["plant"]["phi"]]
    assert read["plant"]["phi"][0] == 7 / 3 and read["robot"]["lengths"][2] == 2 / 3
    assert main(["run", str(first / "scenario.toml"), "--no-plots", "--out", str(second)]) == 0
    capsys.readouterr()
    assert (second / "scenario.toml").read_text() == saved
    with np.load(first / "result.npz") as a, np.load(second / "result.npz") as b:
        assert a.files == b.files
        for key in a.files:
            assert np.array_equal(a[key], b[key]), key


def test_every_packaged_scenario_reads_back_as_written():
    """Matrices (a Lyapunov pair's P, a composite law's P0), inline tables and long strings included."""
    from robotadapt.studies.scenarios.loader import needs

    for name, extras in needs().items():
        if extras:
            continue
        scenario = load(name)
        data = scenario.setup.data or scenario.data
        assert tomllib.loads(scenario.text) == tomllib.loads(tomli_w.dumps(data)), name


# ---------------------------------------------------------------------------------------------------------------------
# e. the names of the columns of x in result.npz


def _saved(tmp_path: Path, name: str) -> dict[str, np.ndarray]:
    from robotadapt.report.files import save_result

    scenario = load(name, ["simulation.t_final=0.05"])
    out = save_result(scenario.run(), tmp_path / name)
    with np.load(out / "result.npz") as npz:  # strings: no pickle needed
        return {key: npz[key] for key in npz.files}


def test_result_npz_names_the_columns_of_the_repetitive_laws_state(tmp_path):
    npz = _saved(tmp_path, "example-7.2.2")
    names = [str(name) for name in npz["x_names"]]
    assert len(names) == npz["x"].shape[-1] == 8
    assert names == ["u_hat_past1", "u_hat_past2", "w_Ydu_m1", "w_Ydu_m2", "w_uu", "step_w_Ydu_m1", "step_w_Ydu_m2",
                     "step_w_uu"]


def test_result_npz_names_the_estimate_columns_of_x(tmp_path):
    npz = _saved(tmp_path, "example-6.3.1")
    assert [str(name) for name in npz["x_names"]] == ["m1_hat", "m2_hat"]
    np.testing.assert_array_equal(npz["x"], npz["phi_hat"])
    fixed = _saved(tmp_path, "example-6.2.1")  # computed torque with fixed estimates: no state, no names
    assert fixed["x_names"].shape == (0,) == fixed["x"].shape[1:]
