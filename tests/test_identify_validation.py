"""Validation as practised (docs/identification.md#estimation): the log is split before filtering, each part filtered
on its own with its own edges trimmed, so the fit never sees the held-out data; `--validate OTHER` scores the estimate
on a second log, per joint, beside the prior, in identified.json, identified.md and validation.png."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robotadapt.analysis.identification import Preprocessing, identify, split
from robotadapt.analysis.joint_data import JointData
from robotadapt.cli import main
from robotadapt.robots.catalog import planar
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import fourier


def planar_log(T: float = 30.0, rate: float = 500.0, seed: int = 3, noise=(0.1, 0.02)) -> tuple[object, JointData]:
    """A two-link planar arm with friction on an exciting path: q (no velocities), τ = Y φ + noise per joint."""
    model = planar(2, lengths=[0.5, 0.4], masses=[2.0, 1.5], rods=True, viscous=[0.3, 0.2], coulomb=[0.4, 0.2])
    t = np.arange(0.0, T, 1.0 / rate)
    a, b = np.random.default_rng(seed).uniform(-1.0, 1.0, (2, 2, 4))
    ref = fourier(2, 4.0, a, b, [0.3, 0.5])(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ model.default_phi
    tau = tau + np.asarray(noise) * np.random.default_rng(seed + 100).standard_normal(tau.shape)
    return model, JointData(t, ref.q_des, None, tau, f"planar-{seed}")


@pytest.mark.parametrize("pre", [Preprocessing(), Preprocessing(cutoff=5.0)], ids=["auto", "5 Hz"])
def test_the_fit_does_not_see_the_held_out_part(pre):
    """The held-out quarter replaced by other data (its torque shifted and noisier, its positions moved): the fit's
    estimates, covariance and preprocessing are unchanged to rounding — the split comes before any filtering, and the
    automatic cutoff is set from the fit part alone."""
    model, data = planar_log()
    res = identify(model, data, pre, holdout=0.25, consistent=False)
    fit, held = split(data, 0.25)
    late = data.t > fit.t[-1]
    assert np.array_equal(late, data.t >= held.t[0])
    rng = np.random.default_rng(7)
    other = JointData(data.t, np.where(late[:, None], data.q + 0.3 * np.sin(7 * data.t)[:, None], data.q), None,
                      np.where(late[:, None], 3.0 * data.tau + rng.standard_normal(data.tau.shape), data.tau), "other")
    changed = identify(model, other, pre, holdout=0.25, consistent=False)
    for name in ("ols", "wls"):
        assert np.allclose(changed.base[name], res.base[name], rtol=1e-12, atol=1e-12), name
    assert np.allclose(changed.covariance, res.covariance, rtol=1e-10, atol=0.0)
    assert changed.preprocessing == res.preprocessing
    assert not np.allclose(changed.holdout_rms["wls"], res.holdout_rms["wls"])  # the held-out part did change


def test_each_part_is_filtered_on_its_own_with_its_own_edges_trimmed():
    """The held-out part starts one trim after the split and ends one trim before the log's end; it is scored at the
    full rate; the estimate predicts it far better than the prior (a 30 % low model)."""
    model, data = planar_log()
    res = identify(model, data, Preprocessing(), holdout=0.25, consistent=False, prior=0.7 * model.default_phi)
    trim = res.preprocessing.trim
    fit, held = split(data, 0.25)
    dt = data.dt
    assert res.holdout_t[0] == pytest.approx(held.t[0] + trim, abs=1.5 * dt)
    assert res.holdout_t[-1] == pytest.approx(held.t[-1] - trim, abs=1.5 * dt)
    assert np.allclose(np.diff(res.holdout_t), dt)
    rms = res.holdout_rms
    assert np.all(rms["wls"] < 0.2 * rms["prior"])


def _csv(path: Path, seed: int, T: float = 12.0, joints: int = 2) -> Path:
    """A CSV of Example 6.3.1's two-link arm (t, q, dq, tau) on the exciting path of `seed`, τ with 0.05 N·m noise."""
    setup = load("example-6.3.1").setup
    model = setup.controller.model
    t = np.arange(0.0, T, 0.005)
    a, b = np.random.default_rng(seed).uniform(-0.5, 0.5, (2, 2, 4))
    ref = fourier(2, 4.0, a, b, [0.3, 0.5])(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ setup.plant.phi
    tau = tau + 0.05 * np.random.default_rng(seed).standard_normal(tau.shape)
    q = ref.q_des if joints == 2 else np.column_stack([ref.q_des, ref.q_des[:, :1]])
    cols = {"t": t, **{f"q{i + 1}": q[:, i] for i in range(joints)},
            **{f"dq{i + 1}": ref.dq_des[:, i] for i in range(2)}, **{f"tau{i + 1}": tau[:, i] for i in range(2)}}
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    return path


def test_validate_scores_the_estimate_on_a_second_log(tmp_path, capsys):
    """`--validate OTHER`: identified.json has validation_rms per estimate and the prior, per joint, the estimate's far
    below the prior's (φ̂(0) = 0 in Example 6.3.1) and near the noise after filtering; identified.md has the table and
    validation.png is drawn; the summary line names it."""
    log, other = _csv(tmp_path / "log.csv", 1), _csv(tmp_path / "other.csv", 2)
    out = tmp_path / "id"
    assert main(["identify", str(log), "--robot", "example-6.3.1", "--validate", str(other), "--out", str(out)]) == 0
    record = json.loads((out / "identified.json").read_text())
    rms = record["validation_rms"]
    assert set(rms) == {"ols", "wls", "consistent", "prior"} and all(len(v) == 2 for v in rms.values())
    assert record["validation"] == "other.csv" and record["validation_samples"] > 0
    assert np.all(np.array(rms["consistent"]) < 0.01 * np.array(rms["prior"]))
    assert np.all(np.array(rms["wls"]) < 0.05)  # 0.05 N·m white noise, low-passed
    assert "Torque of the validation log other.csv" in (out / "identified.md").read_text()
    assert (out / "validation.png").stat().st_size > 0 and (out / "holdout.png").stat().st_size > 0
    assert "validation torque RMS error consistent" in capsys.readouterr().out


@pytest.mark.parametrize("make, words", [
    (lambda tmp: tmp / "nowhere.csv", "--validate: no such file"),
    (lambda tmp: _csv(tmp / "three.csv", 2, joints=3), "--validate: three.csv has position columns q1…q3"),
    (lambda tmp: _csv(tmp / "short.csv", 2, T=0.03), "--validate: short.csv has 6 samples"),
])
def test_a_bad_validation_log_is_one_line(tmp_path, capsys, make, words):
    log = _csv(tmp_path / "log.csv", 1)
    out = tmp_path / "o"
    assert main(["identify", str(log), "--robot", "example-6.3.1", "--validate", str(make(tmp_path)),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err and err.startswith("robotadapt: error: ")
    assert not out.exists()
