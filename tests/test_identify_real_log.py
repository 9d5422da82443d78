"""A simulated Panda log made as hard as a real one (issue "Identification that holds on a real arm's log"): time stamps
jittered as the robot's controller writes them (mostly ~1 ms, now and then up to 9 ms), smooth (tanh) Coulomb and
viscous friction and a torque offset per joint, τ quantised to 16 bits, q to a 19-bit encoder, noise on τ and q̇;
identified by the default command and validated on a separate log: the validation torque's RMS error within 1.3× the
noise floor on every joint, every link's mass within a factor 2 of the truth, every pseudo-inertia's smallest eigenvalue
≥ 1e-6 or half the truth's own (the Panda URDF's link 2 has 8.57e-7), far from the bound ε = 1e-8."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robotadapt.analysis.consistent import bodies
from robotadapt.cli import main
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import fourier

FRICTION = ["robot.viscous=true", "robot.smooth_coulomb=true", "robot.offset=true"]
READY = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
SIGMA_TAU, SIGMA_DQ = 0.05, 1e-3  # N·m, rad/s
TAU_STEP = 2 * 87.0 / 2**16  # 16 bits over the Panda's ±87 N·m
Q_STEP = 2 * np.pi / 2**19  # a 19-bit encoder


@pytest.fixture(scope="module")
def arm():
    setup = load("panda-slotine-li", FRICTION).setup
    model = setup.controller.model
    phi = np.asarray(model.default_phi, dtype=float).copy()
    names = list(model.param_names)
    for group, values in (("fv", [0.6, 0.6, 0.5, 0.5, 0.3, 0.3, 0.2]), ("fs", [0.5, 0.5, 0.4, 0.4, 0.2, 0.2, 0.1]),
                          ("off", [0.1, -0.2, 0.05, 0.15, -0.05, 0.02, 0.03])):
        for j, v in enumerate(values):
            phi[names.index(f"{group}{j + 1}")] = v
    return model, phi


def robot_log(path: Path, model, phi: np.ndarray, seed: int, T: float = 12.0) -> Path:
    """A CSV as a Panda's controller logs it: jittered stamps, quantised q and τ, noisy q̇ and τ."""
    rng = np.random.default_rng(seed)
    periods = np.where(rng.random(int(T / 0.001)) < 0.03, rng.uniform(0.002, 0.009, int(T / 0.001)),
                       rng.uniform(0.0007, 0.0013, int(T / 0.001)))
    t = np.cumsum(np.r_[0.0, periods])
    t = t[t <= T]
    a, b = rng.uniform(-0.35, 0.35, (2, 7, 4))
    ref = fourier(7, 4.0, a, b, READY)(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ phi
    tau = np.round((tau + SIGMA_TAU * rng.standard_normal(tau.shape)) / TAU_STEP) * TAU_STEP
    q = np.round(np.asarray(ref.q_des) / Q_STEP) * Q_STEP
    dq = np.asarray(ref.dq_des) + SIGMA_DQ * rng.standard_normal(q.shape)
    header = ["t", *(f"q{i}" for i in range(1, 8)), *(f"dq{i}" for i in range(1, 8)), *(f"tau{i}" for i in range(1, 8))]
    np.savetxt(path, np.column_stack([t, q, dq, tau]), delimiter=",", header=",".join(header), comments="")
    return path


def test_a_robot_log_as_it_comes_is_identified_by_the_default_command(tmp_path, capsys, arm):
    model, phi = arm
    fit, other = robot_log(tmp_path / "fit.csv", model, phi, 1), robot_log(tmp_path / "other.csv", model, phi, 2)
    out = tmp_path / "id"
    args = ["identify", str(fit), "--robot", "panda-slotine-li", "--validate", str(other), "--out", str(out),
            "--no-plots", "--prior", "nominal"]
    assert main([*args, *(x for s in FRICTION for x in ("--set", s))]) == 0
    printed = capsys.readouterr().out
    assert "resampled to a uniform" in printed
    record = json.loads((out / "identified.json").read_text())
    floor = np.sqrt(SIGMA_TAU**2 + TAU_STEP**2 / 12)
    rms = np.asarray(record["validation_rms"][record["estimate"]])
    print("validation RMS / noise floor per joint:", np.round(rms / floor, 3))
    assert np.all(rms <= 1.3 * floor), rms / floor
    estimate, truth = bodies(np.asarray(record["phi"]), model.param_names), bodies(phi, model.param_names)
    ratio = np.array([e.mass / t.mass for e, t in zip(estimate, truth, strict=True)])
    print("link masses over the truth:", np.round(ratio, 3))
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio
    smallest = min(e.min_eigenvalue for e in estimate)
    own = min(t.min_eigenvalue for t in truth)  # the URDF's own link 2: 8.57e-7, below the 1e-6
    print(f"smallest pseudo-inertia eigenvalue {smallest:.3g} (the truth's {own:.3g}; the bound ε = 1e-8)")
    assert smallest >= min(1e-6, 0.5 * own) and smallest > 10 * 1e-8  # a body, not a point on the set's edge
