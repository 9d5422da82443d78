"""Scenario files: every packaged scenario loads, builds and runs a few steps; and no mutation of a valid scenario makes
`robotadapt run` raise — it either runs (exit 0 or 1) or says in one line which field is wrong (exit 2)."""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robotadapt.cli import main
from robotadapt.studies.scenarios import available, load
from robotadapt.validation import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

NAMES = sorted(available())
BOOK = ["example-6.2.1", "example-6.3.1", "example-6.5.1", "example-6.5.2a", "example-6.5.2b", "problem-6.3-1"]
# Example 6.2.2 as the book ran it (no projection) loses a positive definite M̂ in its first step (spec §2.3)
DIVERGES_ON_PURPOSE = {"example-6.2.2"}


def test_the_books_examples_are_packaged_with_descriptions():
    scenarios = available()
    for name in BOOK:
        assert name in scenarios
    for name, description in scenarios.items():
        assert description.strip(), name
        assert "\n" not in description, name  # `robotadapt list` shows one line each


@pytest.mark.parametrize("name", NAMES)
def test_every_packaged_scenario_loads_builds_and_runs(name):
    scenario = load(name)
    s = scenario.setup
    n = s.plant.model.n
    assert s.controller.model.n == n
    assert s.trajectory.n == s.controller.error_size  # n joints, or a task-space law's m coordinates
    assert s.q0.shape == (n,) and s.dq0.shape == (n,)
    assert s.t_final > 0
    assert np.all(np.isfinite(s.plant.phi))
    s.plant.check_state(s.q0)  # a physical plant at the initial configuration
    # The resolved text holds every value given (and the defaults used besides), and loads.
    written = tomllib.loads(scenario.text)
    assert _contains(written, tomllib.loads(tomli_w.dumps(scenario.data)))
    # A few steps run cleanly (but where a scenario shows a divergence on purpose), and what is kept is finite.
    res = load(name, ["simulation.t_final=0.02"]).run()
    if name in DIVERGES_ON_PURPOSE:
        assert res.status.startswith("diverged "), res.status  # "at t=…" or "within the step from 0 to dt s"
    else:
        assert res.status == "ok", res.status
    assert res.t.shape[0] == res.q.shape[0] == res.tau.shape[0] >= 1
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.tau))


# ---------------------------------------------------------------------------------------------------------------------
# Mutations of valid scenarios through the CLI

BAD_VALUES = [
    math.nan, math.inf, -math.inf, -1.0, 0.0, 1e300, -1e300, 3, -7, "abc", "", "rk4", [], [1.0], [1.0, 2.0, 3.0],
    [[1.0, 2.0], [2.0, 1.0]], [math.nan, 1.0], ["a", "b"], True, False, {}, {"kind": "nonsense"}, {"x": 1.0},
]
SECTIONS = ("robot", "plant", "trajectory", "controller", "simulation")
UNKNOWN_KEYS = ["unknown", "Kw", "gamma", "kind_", "mass"]
FIELD = re.compile(r"^robotadapt: error: (\S+?): ")


def _contains(big: dict, small: dict) -> bool:
    """Every value of `small` is in `big` at the same place (nested tables compared key by key)."""
    return all(key in big and (_contains(big[key], value) if isinstance(value, dict) and isinstance(big[key], dict)
                               else big[key] == value) for key, value in small.items())


def _paths(data: dict, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every key path in the scenario (sections, their keys, nested tables)."""
    out = []
    for key, value in data.items():
        out.append(prefix + (key,))
        if isinstance(value, dict):
            out.extend(_paths(value, prefix + (key,)))
    return out


def _tables(data: dict, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    out = [prefix]
    for key, value in data.items():
        if isinstance(value, dict):
            out.extend(_tables(value, prefix + (key,)))
    return out


def _node(data: dict, path: tuple[str, ...]) -> dict:
    for key in path:
        data = data[key]
    return data


@st.composite
def mutated(draw):
    """(mutated scenario dict, the path that was mutated, what was done)."""
    name = draw(st.sampled_from(NAMES))
    data = copy.deepcopy(load(name).data)
    data.pop("study", None)  # a [study] multiplies the runs; it is checked by the loader on its own
    op = draw(st.sampled_from(["drop", "replace", "replace", "add"]))
    if op == "add":
        table = draw(st.sampled_from(_tables(data)))
        key = draw(st.sampled_from(UNKNOWN_KEYS))
        _node(data, table)[key] = draw(st.sampled_from(BAD_VALUES[:10]))
        return name, data, table + (key,), op
    path = draw(st.sampled_from(_paths(data)))
    parent = _node(data, path[:-1])
    if op == "drop":
        del parent[path[-1]]
    else:
        parent[path[-1]] = draw(st.sampled_from(BAD_VALUES))
    return name, data, path, op


@settings(max_examples=60, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_scenarios_run_or_fail_with_one_clear_line(case):
    name, data, path, op = case
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp) / "mutated.toml"
        file.write_text(tomli_w.dumps(data))
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(["run", str(file), "--out", str(Path(tmp) / "out"), "--t-final", "0.05", "--no-plots"])
    stderr = err.getvalue()
    assert code in (0, 1, 2), (code, stderr)
    assert "Traceback" not in stderr
    if code == 2:
        lines = stderr.splitlines()
        assert len(lines) == 1, stderr
        match = FIELD.match(lines[0])
        assert match, lines[0]
        # The named field is a place in the scenario: a section (usually the mutated one; a check across sections may
        # name the other side, e.g. a repetitive controller's period when the trajectory stops being periodic) or the
        # unknown top-level key that was added.
        assert match.group(1).split(".")[0] in (*SECTIONS, path[0]), (path, op, lines[0])
    else:
        assert "wrote" in out.getvalue()


# ---------------------------------------------------------------------------------------------------------------------
# Inputs the property test found, pinned (the property test skips exactly these until they are fixed)


def _run_quietly(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, err.getvalue()


def test_a_simulation_value_that_is_not_a_table_is_a_clear_error(tmp_path):
    """`simulation = nan` instead of a [simulation] table, then --t-final (an override of simulation.t_final): a clear
    error naming `simulation`, exit 2 — not a TypeError from the override."""
    data = copy.deepcopy(load("example-6.3.1").data)
    data["simulation"] = math.nan
    file = tmp_path / "s.toml"
    file.write_text(tomli_w.dumps(data))
    code, err = _run_quietly(["run", str(file), "--out", str(tmp_path / "out"), "--t-final", "0.05", "--no-plots"])
    assert code == 2
    assert FIELD.match(err).group(1).split(".")[0] == "simulation"


def test_a_huge_link_length_is_not_a_traceback(tmp_path):
    """robot.l1 = 1e300 is finite and positive, so it passes validation; the run must then either stop as diverged
    (exit 1) or be refused naming robot.l1 (exit 2), not raise OverflowError."""
    code, err = _run_quietly(["run", "example-6.3.1", "--set", "robot.l1=1e300", "--out", str(tmp_path / "out"),
                              "--t-final", "0.05", "--no-plots"])
    assert code in (1, 2)
    if code == 2:
        assert FIELD.match(err).group(1) == "robot.l1"


def test_an_estimate_given_as_a_scale_of_the_truth(tmp_path):
    """phi_hat0 = {scale = s} starts at s × plant.phi, matched by parameter name; errors name the field."""
    data = {"robot": {"kind": "two_link"}, "plant": {"phi": [0.8, 2.3]}, "trajectory": {"kind": "sinusoid"},
            "controller": {"kind": "slotine_li", "Lam": 5.0, "Kv": 10.0, "Gamma": 1.0, "phi_hat0": {"scale": 0.5}},
            "simulation": {"t_final": 0.01}}
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(data))
    np.testing.assert_allclose(load(path).run().phi_hat[0], [0.4, 1.15])
    with pytest.raises(ConfigError, match=r"^controller\.phi_hat0: unknown key gain; missing key scale; known keys "
                       r"here: scale$"):
        load(path, ["controller.phi_hat0={gain = 2}"])
    with pytest.raises(ConfigError, match=r"^controller\.phi_hat0: .*lacks m: "):  # a polar-arm controller
        load(path, ["robot={kind = 'polar'}", "plant.robot={kind = 'two_link'}"])


def test_a_relative_urdf_path_is_relative_to_the_scenario_file(tmp_path):
    pytest.importorskip("pinocchio")
    import importlib.metadata

    robots = importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data")
    (tmp_path / "arms").mkdir()
    urdf = Path(str(robots)) / "robots/ur_description/urdf/ur5_robot.urdf"
    (tmp_path / "arms" / "ur5.urdf").write_text(urdf.read_text())
    data = {"robot": {"kind": "urdf", "path": "arms/ur5.urdf"}, "plant": {},
            "trajectory": {"kind": "constant", "value": 0.0},
            "controller": {"kind": "pd_gravity", "Kp": 50.0, "Kv": 10.0}, "simulation": {"t_final": 0.002}}
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(data))
    assert load(path).setup.plant.model.n == 6



def test_a_robot_is_built_once_per_section_and_again_when_its_file_changes(tmp_path):
    """The runs of a sweep share one model object per [robot] section (a URDF arm takes tens of ms to build); another
    section builds another model, and a URDF file written again is read again."""
    from robotadapt.studies.scenarios.build import robot

    data = load("example-6.3.1", []).data
    assert robot(copy.deepcopy(data["robot"])) is robot(copy.deepcopy(data["robot"]))
    assert robot({**data["robot"], "l1": 0.5}).mass_matrix(np.zeros(2), np.ones(2))[0, 0] != \
        robot(data["robot"]).mass_matrix(np.zeros(2), np.ones(2))[0, 0]
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(URDF_ARM.format(mass=1.0))
    section = {"kind": "urdf", "path": str(urdf)}
    first = robot(section)
    assert robot(dict(section)) is first
    urdf.write_text(URDF_ARM.format(mass=2.0))
    os.utime(urdf, ns=(urdf.stat().st_atime_ns, urdf.stat().st_mtime_ns + 10**9))
    again = robot(section)
    assert again is not first and again.default_phi[0] == 2.0 and first.default_phi[0] == 1.0


URDF_ARM = """<robot name="r">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0 0 0.1"/><mass value="{mass}"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="first" type="revolute"><parent link="base"/><child link="a"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
</robot>
"""
