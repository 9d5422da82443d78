"""Tuning through every driver (issue 25): a URDF arm and a DH arm on their traced kinematic trees, robust tuning with
the plants of `--over` batched in one differentiated program, and the plants that stay refused (Pinocchio, MuJoCo),
each with one line. Sampled-data runs: tests/test_tune.py."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.studies.gain_space import draw_over, locate
from robotadapt.studies.scenarios import load
from test_kinematic_tree import URDF  # a two-link arm, its first joint of the kind given
from tuning_checks import assert_gradient_is_central_differences

REST = """[plant]
q0 = [0.0, 0.0]
dq0 = [0.0, 0.0]
[trajectory]
kind = "sinusoid"
amplitude = 0.5
omega = 2.0
[controller]
kind = "slotine_li"
Lam = 5.0
Kv = 8.0
Gamma = 2.0
[simulation]
t_final = 0.5
dt = 1e-3
backend = "jax"
"""
GAINS = ("controller.Kv", "controller.Lam", "controller.Gamma")


@pytest.fixture
def urdf_scenario(tmp_path):
    (tmp_path / "two_link.urdf").write_text(URDF.format(kind="revolute"))
    path = tmp_path / "urdf-arm.toml"
    path.write_text(f'[robot]\nkind = "urdf"\npath = "{tmp_path / "two_link.urdf"}"\n' + REST)
    return path


def test_a_urdf_arm_tunes_on_its_kinematic_tree(urdf_scenario):
    scenario = load(str(urdf_scenario))
    assert type(scenario.setup.plant.model).__name__ == "KinematicTree"
    assert_gradient_is_central_differences(scenario, [locate(scenario, f) for f in GAINS])


def test_a_dh_arm_tunes_on_its_kinematic_tree(tmp_path):
    path = tmp_path / "planar.toml"
    path.write_text('[robot]\nkind = "planar"\nn_links = 2\nlengths = [0.5, 0.4]\nmasses = [3.0, 2.0]\n' + REST)
    scenario = load(str(path))
    assert type(scenario.setup.plant.model).__name__ == "KinematicTree"
    assert_gradient_is_central_differences(scenario, [locate(scenario, f) for f in GAINS])


def test_robust_tuning_batches_the_drawn_plants_and_its_gradient_is_their_mean(urdf_scenario):
    """`--over`: 3 true-parameter sets of the URDF arm drawn in ±20 % of the URDF's, run in one vmapped program; its
    gradient against central differences of the mean of 3 forward runs."""
    scenario = load(str(urdf_scenario))
    phi = scenario.setup.plant.phi
    lo, hi = np.minimum(0.8 * phi, 1.2 * phi), np.maximum(0.8 * phi, 1.2 * phi)
    _, phis = draw_over(scenario, f"plant.phi={lo.tolist()}:{hi.tolist()}", 3, 0)
    assert phis.shape == (3, phi.size) and not np.allclose(phis[0], phis[1])
    assert_gradient_is_central_differences(scenario, [locate(scenario, f) for f in GAINS], phis=phis)


@pytest.mark.parametrize(("sets", "message"), [
    (["robot.model='pinocchio'"], "controller: InertiaRelated on PinocchioArm: the model cannot be traced by JAX, so the "
                                  "run cannot be differentiated; tune on a DH/URDF kinematic tree model"),
    (["plant.engine='mujoco'"], "plant.engine: MuJoCo steps its plant on the host, outside JAX: tune with plant.engine = "
                                "'robotadapt', then check the gains on MuJoCo"),
])
def test_plants_outside_jax_are_refused_with_one_line_naming_the_model_to_use(urdf_scenario, tmp_path, capsys, sets,
                                                                               message):
    args = [a for s in sets for a in ("--set", s)]
    assert main(["tune", str(urdf_scenario), *args, "--vary", "controller.Kv", "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [f"robotadapt: error: {message}"], err
