"""The MuJoCo plant (issue 18): MuJoCo's dynamics equal the models' at random states, and the closed loop stepped by
MuJoCo equals the one stepped by the project's own sampled-data loop (Example 6.3.1; the Panda against Pinocchio).

Independent checks: M from MuJoCo's `mj_fullM` and the bias force from `qfrc_bias` (MuJoCo's own algorithms on a
model built by `MjSpec` or by MuJoCo's URDF parser) against the closed forms of the book's arms and against the
kinematic tree; the closed loops run by two engines that share only the controller.
"""

from __future__ import annotations

import builtins
import re
from typing import Any

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.plant.mujoco import POINT_INERTIA, MujocoPlant, load_mujoco, with_options
from robotadapt.robots import OneLinkArm, PolarArm, TwoLinkArm
from robotadapt.robots.kinematic_tree import KinematicTree
from robotadapt.studies.scenarios import load
from robotadapt.validation import ConfigError

try:
    mujoco = load_mujoco()  # imports mujoco with no GL backend: only --video picks one (report/video.py)
except ConfigError:  # pragma: no cover - `make test` installs the extra
    pytest.skip("the mujoco extra is not installed", allow_module_level=True)
RNG = np.random.default_rng(18)


def dynamics(plant: MujocoPlant, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, the bias force C q̇ + G + damping q̇) from MuJoCo at (q, q̇), in the model's joint order."""
    model, data, qadr, vadr = plant.engine
    data.qpos[qadr], data.qvel[vadr] = q, dq
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    return M[np.ix_(vadr, vadr)], (data.qfrc_bias - data.qfrc_passive)[vadr]


@pytest.mark.parametrize(("arm", "phi", "bound"), [
    (TwoLinkArm(l1=1.2, l2=0.7, g=9.81, friction_terms=True), [0.8, 2.3, 0.5, 0.2], 3.0),
    (PolarArm(), [1.7], 3.0),
    (OneLinkArm(), [0.6, 0.3], 3.0),
    (OneLinkArm(stiffness=True), [0.6, 0.3, 2.0], 3.0),
])
def test_book_arms_match_their_closed_forms(arm: Any, phi: list[float], bound: float) -> None:
    """MjSpec's point masses: M equals the closed form up to the point inertia, the bias force (with damping = φ's
    viscous column, the one-link arm's spring as MuJoCo's joint stiffness) equals V_m q̇ + G + F."""
    plant = MujocoPlant(arm, phi)
    for _ in range(5):
        q, dq = RNG.uniform(-bound, bound, arm.n), RNG.uniform(-2, 2, arm.n)
        if isinstance(arm, PolarArm):
            q[1] = RNG.uniform(0.3, 1.5)  # r > 0
        M, bias = dynamics(plant, q, dq)
        np.testing.assert_allclose(M, arm.mass_matrix(q, np.array(phi)), rtol=0, atol=4 * POINT_INERTIA)
        np.testing.assert_allclose(bias, arm.inverse_dynamics(q, dq, 0 * dq, np.array(phi)), rtol=1e-12, atol=1e-11)


def test_a_dh_arm_matches_its_kinematic_tree() -> None:
    """MjSpec from the tree's placements (DH link frames rotated against the joint frames, a prismatic joint, a
    massless first link holding only its rotor's inertia, as the PUMA 560's) against the tree's own M and bias."""
    links = [{"a": 0.0, "alpha": np.pi / 2, "d": 0.5, "m": 0.0, "inertia": [0.0, 0.0, 0.35], "viscous": 0.3},
             {"a": 0.6, "alpha": 0.0, "m": 4.0, "com": [-0.3, 0.0, 0.05], "inertia": [0.02, 0.15, 0.14],
              "rotor_inertia": 0.2},
             {"joint": "P", "alpha": -np.pi / 2, "theta": 0.3, "m": 1.5, "com": [0.0, 0.1, -0.1],
              "inertia": [0.01, 0.012, 0.015]},
             {"a": 0.1, "alpha": np.pi / 2, "m": 0.5, "com": [0.02, 0.0, 0.0], "inertia": [0.001, 0.002, 0.0025]}]
    tree = KinematicTree.from_dh(links)
    plant = MujocoPlant(tree, tree.default_phi)
    assert np.any(plant._options["armature"] > 0) and np.any(plant._options["damping"] > 0)
    for _ in range(5):
        q, dq = RNG.uniform(-2, 2, 4), RNG.uniform(-1, 1, 4)
        M, bias = dynamics(plant, q, dq)
        np.testing.assert_allclose(M, tree.mass_matrix(q, tree.default_phi), rtol=0, atol=1e-11)
        np.testing.assert_allclose(bias, tree.inverse_dynamics(q, dq, 0 * dq, tree.default_phi), rtol=0, atol=1e-10)


def test_the_puma_560s_published_inertia_is_refused() -> None:
    """Link 3's principal moments break A + B ≥ C: no rigid body has them, and MuJoCo takes only rigid bodies."""
    with pytest.raises(ConfigError, match=r"^plant\.phi: link 3: MuJoCo needs .* A \+ B ≥ C"):
        load("puma560-slotine-li", ["plant.engine=mujoco"])


def test_panda_from_its_urdf_matches_the_kinematic_tree() -> None:
    """MuJoCo's URDF parser (fingers fixed and fused) with armature and damping against the tree with rotor-inertia and
    viscous columns; MuJoCo's own reading of the URDF's inertials equals the tree's φ."""
    setup = load("panda-mujoco").setup
    plant, tree = setup.plant, setup.plant.model
    assert isinstance(plant, MujocoPlant)
    phi = plant.phi
    np.testing.assert_allclose(phi[70:], [0.1] * 7 + [1.0] * 7)  # the scenario's armature and damping, in φ
    for _ in range(3):
        q, dq = RNG.uniform(-1.5, 1.5, 7), RNG.uniform(-1, 1, 7)
        M, bias = dynamics(plant, q, dq)
        np.testing.assert_allclose(M, tree.mass_matrix(q, phi), rtol=0, atol=1e-12)
        np.testing.assert_allclose(bias, tree.inverse_dynamics(q, dq, 0 * dq, phi), rtol=0, atol=1e-11)
    parsed = plant._urdf_spec(load_mujoco())[0].compile()  # the URDF's inertials as MuJoCo reads them
    model = plant.engine[0]
    bodies = model.jnt_bodyid[[model.joint(name).id for name in tree.joint_names]]
    for field in ("body_mass", "body_ipos"):
        np.testing.assert_allclose(getattr(parsed, field)[bodies], getattr(model, field)[bodies], atol=1e-9)


def states(result: Any) -> np.ndarray:
    return np.concatenate([result.q, result.dq, result.x], axis=1)


def relative_gap(a: Any, b: Any) -> float:
    assert a.status == b.status == "ok"
    return float(np.abs(states(a) - states(b)).max() / np.abs(states(b)).max())


def test_example_6_3_1_stepped_by_mujoco_equals_the_sampled_data_loop() -> None:
    """Example 6.3.1 over 10 s: MuJoCo's RK4 at Ts = 1 ms against our sampled-data RK4 at the same period, the torque
    held over the step in both; the gap is the point inertia's (≈ POINT_INERTIA relative) and round-off."""
    own = load("digital-6.3.1", ["simulation.backend=numpy"]).run()
    for actuation in ("motor", "qfrc_applied"):
        stepped = load("example-6.3.1", ["plant.engine=mujoco", f"plant.actuation={actuation}"]).run()
        assert stepped.info["backend"] == "numpy" and stepped.info["plant"]["mujoco"]["actuation"] == actuation
        assert relative_gap(stepped, own) < 1e-6
        assert relative_gap(stepped, own) < 10 * POINT_INERTIA + 1e-13


def test_a_disturbance_is_subtracted_at_each_mujoco_step() -> None:
    """Problem 6.7-1's constant T_d = [2, 1] on Example 6.3.1 (2 s): held over each step, it is exact; with both
    actuations."""
    common = ["simulation.t_final=2", "plant.disturbance={bias = [2.0, 1.0]}"]
    own = load("digital-6.3.1", [*common, "simulation.backend=numpy"]).run()
    for actuation in ("motor", "qfrc_applied"):
        stepped = load("example-6.3.1", [*common, "plant.engine=mujoco", f"plant.actuation={actuation}"]).run()
        assert relative_gap(stepped, own) < 1e-9


def test_panda_stepped_by_mujoco_equals_the_pinocchio_plant() -> None:
    """The Panda under Slotine–Li over 10 s at 1 kHz: MuJoCo (URDF) against Pinocchio's ABA in our loop. K_v = 5 on
    the wrist: with panda-slotine-li's K_v7 = 1 the loop amplifies round-off (two of our own engines part by 1e-6
    there too)."""
    common = ["robot.model=pinocchio", "simulation.control_period=1e-3", "simulation.t_final=10",
              "simulation.log_every=100", "controller.Kv=[50, 50, 50, 50, 5, 5, 5]"]
    own = load("panda-slotine-li", common).run()
    stepped = load("panda-slotine-li", [*common, "plant.engine=mujoco"]).run()
    assert relative_gap(stepped, own) < 1e-6


def test_the_controller_runs_at_every_mujoco_step_of_a_continuous_scenario() -> None:
    """A continuous-time scenario (RK4, dt) with a MuJoCo plant: the controller at every step, MuJoCo's own steps of
    plant.timestep between; a timestep that does not divide the period is refused."""
    fine = load("example-6.3.1", ["plant.engine=mujoco", "simulation.t_final=0.5", "plant.timestep=2.5e-4"]).run()
    assert fine.info["sampling"] == {"control_period": 1e-3, "dt": 2.5e-4, "substeps": 4, "discretization": "euler"}
    with pytest.raises(ConfigError, match=r"^plant\.timestep: "):
        load("example-6.3.1", ["plant.engine=mujoco", "plant.timestep=3e-4"]).run()


@pytest.mark.parametrize(("overrides", "field"), [
    (["plant.damping=0.1"], "plant.damping"),  # a MuJoCo option without the engine
    (["plant.engine=bullet"], "plant.engine"),
    (["plant.engine=mujoco", "plant.integrator=RK45"], "plant.integrator"),
    (["plant.engine=mujoco", "plant.actuation=position"], "plant.actuation"),
    (["plant.engine=mujoco", "plant.joint_limits=true"], "plant.joint_limits"),  # the book's arms have none
    (["plant.engine=mujoco", "plant.payload=1.0", "plant.payload_time=1.0"], "plant.payload_time"),
    (["plant.engine=mujoco", "simulation.backend=jax"], "simulation.backend"),
    (["plant.engine=mujoco", "simulation.method=RK45"], "simulation.method"),
    (["plant.engine=mujoco", "robot.friction_terms=true", "plant.phi=[0.8, 2.3, 0.5, 0.5]", "plant.damping=0.2"],
     "plant.damping"),  # MuJoCo's option and φ's column disagree
])
def test_bad_input_names_the_field(overrides: list[str], field: str) -> None:
    with pytest.raises(ConfigError, match=rf"^{re.escape(field)}: "):
        load("example-6.3.1", overrides).run()


def test_a_urdf_mujoco_cannot_compile_is_a_config_error(tmp_path: Any, capsys: Any) -> None:
    """A URDF Pinocchio reads but MuJoCo refuses (a moving link without mass or inertia): exit 2, one line."""
    urdf = tmp_path / "massless.urdf"
    urdf.write_text('<robot name="r"><link name="base"/><link name="arm"/><joint name="j" type="revolute">'
                    '<parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>'
                    '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'[robot]\nkind = "urdf"\npath = "{urdf}"\n[plant]\nengine = "mujoco"\n'
                        '[trajectory]\nkind = "sinusoid"\n[controller]\nkind = "pd"\nKp = 1.0\nKv = 1.0\n'
                        '[simulation]\nt_final = 0.1\n')
    assert main(["run", str(scenario), "--no-plots", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("robotadapt: error: robot.path: MuJoCo cannot compile")


def test_the_extra_not_installed_is_a_config_error(monkeypatch: Any) -> None:
    real = builtins.__import__

    def no_mujoco(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "mujoco":
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_mujoco)
    with pytest.raises(ConfigError, match=r"^plant\.engine: .*pip install 'robotadapt\[mujoco\]'"):
        MujocoPlant(TwoLinkArm(), [0.8, 2.3])


def test_options_fill_the_matching_columns_of_phi() -> None:
    """φ's Ia/fv/fc columns take MuJoCo's armature/damping/frictionloss; columns the model lacks are left alone."""
    arm = TwoLinkArm(friction_terms=True)
    np.testing.assert_allclose(with_options(arm, [0.8, 2.3, 0, 0], {"damping": [0.5, 0.25], "armature": 1.0}),
                               [0.8, 2.3, 0.5, 0.25])


def test_run_video_draws_the_arm_and_its_ghost(tmp_path: Any, capsys: Any) -> None:
    """`robotadapt run --video` on the book's arm (stepped by our own engine, drawn by MuJoCo): an MP4 of one frame
    per 1/30 s; the first frame shows the arm (blue links) and, apart from it, the desired pose (green ghost)."""
    from robotadapt.report.video import frames

    out = tmp_path / "run"
    try:
        code = main(["run", "example-6.3.1", "--t-final", "0.3", "--no-plots", "--video", "--out", str(out)])
    except ConfigError as exc:  # pragma: no cover - a machine without OSMesa
        pytest.skip(str(exc))
    if code == 2 and "--video" in capsys.readouterr().err:  # pragma: no cover
        pytest.skip("no off-screen OpenGL here")
    assert code == 0 and (out / "motion.mp4").stat().st_size > 1000
    scenario = load("example-6.3.1", ["plant.engine=mujoco", "plant.q0=[-0.6, 0.0]", "simulation.t_final=0.1"])
    image = frames(scenario.run(), scenario.setup.plant, [0.0])[0].astype(int)
    blue = (image[..., 2] > image[..., 0] + 60) & (image[..., 2] > image[..., 1] + 30)
    green = (image[..., 1] > image[..., 0] + 30) & (image[..., 1] > image[..., 2] + 10)
    assert blue.sum() > 500 and green.sum() > 500
    rows_blue, rows_green = np.nonzero(blue)[0], np.nonzero(green)[0]
    assert rows_green.min() < rows_blue.min()  # the ghost (q_des(0) = 0: horizontal) above the arm at q1 = −0.6


def test_a_batch_refuses_the_mujoco_plant_and_a_sweep_runs_it_one_by_one() -> None:
    """simulate_batch would integrate the project's dynamics: it is refused (a ConfigError the sweep catches)."""
    from robotadapt.sim.batch import simulate_batch

    setup = load("example-6.3.1", ["plant.engine=mujoco"]).setup
    with pytest.raises(ConfigError, match=r"^plant\.engine: a MuJoCo plant is stepped by MuJoCo"):
        simulate_batch([setup.plant], setup.controller, setup.trajectory, t_final=0.01)
