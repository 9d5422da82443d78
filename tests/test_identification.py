"""Identification from logged joint data (issue 27, docs/identification.md): the derivatives, the least squares against
the truth and against Pinocchio's regressor, the covariance, the consistent estimate, `robotadapt identify` and the
`phi_hat0 = {file = …}` it feeds, and the bad input it refuses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import tomllib

from robotadapt.analysis.identification import Preprocessing, derivatives, identify, lowpass, split
from robotadapt.analysis.joint_data import JointData, read
from robotadapt.cli import main
from robotadapt.robots.consistency import parts, smallest_eigenvalues
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import fourier


@pytest.fixture(scope="module")
def panda():
    return load("panda-slotine-li").setup


def exciting(n: int, period: float = 4.0) -> object:
    """A Fourier trajectory of 4 harmonics with random coefficients (one fixed draw) about the Panda's ready pose."""
    a, b = np.random.default_rng(27).uniform(-0.4, 0.4, (2, n, 4))
    return fourier(n, period, a, b, [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785][:n])


def inverse_dynamics_data(setup, T: float = 8.0, dt: float = 2e-3, noise: float = 0.0, phi=None,
                          seed: int = 0) -> JointData:
    """q, q̇ of an exciting trajectory and τ = Y φ (+ noise of standard deviation `noise`, drawn with `seed`), as a log
    would hold them."""
    model = setup.controller.model
    t = np.arange(0.0, T, dt)
    ref = exciting(model.n)(t)
    phi = setup.plant.phi if phi is None else phi
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ phi
    tau = tau + noise * np.random.default_rng(seed).standard_normal(tau.shape)
    return JointData(t, ref.q_des, ref.dq_des, tau, "test")


def base_error(estimate, basis, phi) -> float:
    return float(np.linalg.norm(estimate - basis.K @ phi) / np.linalg.norm(basis.K @ phi))


def test_savitzky_golay_derivatives_are_exact_on_a_polynomial_of_their_order():
    """q(t) a degree-6 polynomial per joint: q̇ and q̈ from q alone equal the written-out derivatives."""
    t = np.linspace(0.0, 1.0, 201)
    c = np.random.default_rng(1).normal(size=(7, 2))
    q = sum(c[k] * t[:, None] ** k for k in range(7))
    dq = sum(k * c[k] * t[:, None] ** (k - 1) for k in range(1, 7))
    ddq = sum(k * (k - 1) * c[k] * t[:, None] ** (k - 2) for k in range(2, 7))
    _, dq_sg, ddq_sg = derivatives(JointData(t, q, None, 0 * q, "poly"), 9, 6)
    assert np.max(np.abs(dq_sg - dq)) < 1e-8 * np.max(np.abs(dq))
    assert np.max(np.abs(ddq_sg - ddq)) < 1e-7 * np.max(np.abs(ddq))


def test_the_zero_phase_filter_passes_a_slow_sine_without_lag_and_removes_a_fast_one():
    t = np.arange(0.0, 10.0, 1e-3)
    slow, fast = np.sin(2 * np.pi * 0.5 * t), 0.3 * np.sin(2 * np.pi * 80 * t)
    y = lowpass((slow + fast)[:, None], 10.0, 1e3)[:, 0]
    inner = (t > 0.3) & (t < 9.7)  # 3/cutoff from each end
    assert np.max(np.abs(y - slow)[inner]) < 2e-3  # no lag: a causal filter would be off by ~0.1 here


def test_noise_free_data_give_the_base_parameters_and_pinocchio_agrees(panda):
    """τ = Y φ exactly: OLS and WLS give K φ to 1e-8; an independent least squares on Pinocchio's
    `computeJointTorqueRegressor` at the same samples has the same base parameters."""
    import pinocchio as pin

    from robotadapt.robots.pinocchio import example_urdf, urdf_model

    data = inverse_dynamics_data(panda)
    model, phi = panda.controller.model, panda.plant.phi
    res = identify(model, data, Preprocessing(cutoff=None), holdout=0.25)
    for name in ("ols", "wls", "consistent"):
        assert base_error(res.base[name], res.basis, phi) < 1e-8, name
    assert max(np.max(v) for k, v in res.holdout_rms.items() if k != "prior") < 1e-6
    path, locked = example_urdf("panda")
    pmodel = urdf_model(path, locked, None, "robot.path", "robot.locked_joints")
    pdata = pmodel.createData()
    fit, _ = split(data, 0.25)
    q, dq, ddq = derivatives(fit, 9, 6)
    rows = [pin.computeJointTorqueRegressor(pmodel, pdata, *x).copy() for x in zip(q, dq, ddq, strict=True)]
    phi_pin = np.linalg.lstsq(np.concatenate(rows), fit.tau.reshape(-1), rcond=None)[0]  # minimum-norm standard φ
    assert base_error(res.base["ols"], res.basis, phi_pin) < 1e-9
    assert base_error(res.basis.K @ phi_pin, res.basis, phi) < 1e-8


def test_noise_free_simulated_run_gives_the_base_parameters(tmp_path, panda):
    """The whole path: a simulated Slotine–Li run (RK4 at 0.25 ms, logged at 1 ms) read back from its result.npz; the
    first 0.1 s (the adaptive transient, faster than the derivative's window) trimmed."""
    assert main(["run", "panda-slotine-li", "--out", str(tmp_path), "--no-plots", "--dt", "2.5e-4", "--t-final", "8",
                 "--set", "simulation.log_every=4"]) == 0
    data = read(tmp_path / "result.npz", 7)
    res = identify(panda.controller.model, data, Preprocessing(cutoff=None, trim=0.1), consistent=False)
    for name in ("ols", "wls"):
        assert base_error(res.base[name], res.basis, panda.plant.phi) < 1e-8, name


def test_the_covariance_is_honest_under_white_torque_noise(panda):
    """Noise of known σ on τ, unfiltered (independent samples): each WLS error is within 5 of its own standard
    deviations, their mean square ≈ 1, the estimated σ_i match, and the error's expected size √tr C grows tenfold with
    the noise. Filtered data: tests/test_identify_uncertainty.py."""
    model, phi = panda.controller.model, panda.plant.phi
    spread = []
    for noise in (0.01, 0.1):
        res = identify(model, inverse_dynamics_data(panda, noise=noise, seed=int(1000 * noise)),
                       Preprocessing(cutoff=None), consistent=False)
        z = (res.base["wls"] - res.basis.K @ phi) / np.sqrt(np.diag(res.covariance))
        assert np.max(np.abs(z)) < 5.0
        assert 0.3 < np.mean(z**2) < 3.0
        assert np.allclose(res.sigma, noise, rtol=0.1)
        spread.append(np.sqrt(np.trace(res.covariance)))
    assert 9.0 < spread[1] / spread[0] < 11.0


def test_the_consistent_estimate_stays_physical_where_least_squares_does_not(panda):
    """Data from a last link of negative mass (no body): least squares reproduces it, the consistent estimate keeps
    every J_i ⪰ ε𝟙 with the bound active, and fits the data worse than least squares but better than the prior."""
    model = panda.controller.model
    bad = panda.plant.phi.copy()
    bad[60] = -0.3  # m7
    data = inverse_dynamics_data(panda, phi=bad, noise=0.01)
    eps = 1e-6
    res = identify(model, data, Preprocessing(cutoff=None), epsilon=eps)
    layout = parts(model.param_names)
    assert np.min(smallest_eigenvalues(res.standard["wls"], layout)) < -0.01
    eigs = smallest_eigenvalues(res.standard["consistent"], layout)
    assert np.min(eigs) > eps * (1 - 1e-3)
    assert np.min(eigs) < 1e-4  # on the boundary: the data pull it out of the set
    held = res.holdout_rms
    assert np.sum(held["wls"] ** 2) < np.sum(held["consistent"] ** 2) < np.sum(held["prior"] ** 2)


def _two_link_csv(path: Path, rows: int = 400, **changes: object) -> Path:
    """A CSV of Example 6.3.1's arm: t, q1, q2, dq1, dq2, tau1, tau2 from the inverse dynamics of an exciting path."""
    setup = load("example-6.3.1").setup
    data = inverse_dynamics_data(setup, T=rows * 0.01, dt=0.01)
    cols = {"t": data.t, **{f"q{i + 1}": data.q[:, i] for i in range(2)}, **{f"dq{i + 1}": data.dq[:, i] for i in
                                                                            range(2)},
            **{f"tau{i + 1}": data.tau[:, i] for i in range(2)}}
    for key, value in changes.items():
        if value is None:
            cols.pop(key)
        else:
            cols[key] = value
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    return path


def test_identify_writes_an_estimate_a_scenario_starts_from(tmp_path, capsys):
    csv = _two_link_csv(tmp_path / "log.csv")
    out = tmp_path / "id"
    assert main(["identify", str(csv), "--robot", "example-6.3.1", "--out", str(out), "--no-plots"]) == 0
    record = json.loads((out / "identified.json").read_text())
    truth = load("example-6.3.1").setup.plant.phi
    assert np.allclose(record["phi"], truth, rtol=1e-6)  # the default low-pass: W and τ alike, so no bias
    assert record["preprocessing"]["cutoff_source"] == "spectrum" and record["preprocessing"]["decimate"] > 1
    assert record["estimate"] == "consistent" and (out / "identified.md").exists()
    assert "wrote" in capsys.readouterr().out
    scenario = tmp_path / "start.toml"
    data = tomllib.loads(load("example-6.3.1").text)
    data["controller"]["phi_hat0"] = {"file": "id/identified.json"}
    scenario.write_text(tomli_w.dumps(data))
    sc = load(scenario)  # relative to the scenario file's folder
    assert np.allclose(sc.setup.controller.phi_hat0, truth, rtol=1e-6)


@pytest.mark.parametrize("change, words", [
    ({"tau2": None}, "lacks the column tau2"),
    ({"q2": np.where(np.arange(400) == 7, np.nan, 0.1)}, "not finite at sample 7"),
    ({"t": np.r_[0.0, 0.02, 0.01, 0.01 * np.arange(3, 400)]}, "time does not increase at sample 2"),
    ({"q3": np.zeros(400)}, "q1…q3 (3 joints), the robot has 2"),
])
def test_bad_csv_is_one_line_and_writes_nothing(tmp_path, capsys, change, words):
    csv = _two_link_csv(tmp_path / "log.csv", **change)
    out = tmp_path / "out"
    assert main(["identify", str(csv), "--robot", "example-6.3.1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err and err.startswith("robotadapt: error: DATA")
    assert not out.exists()


def test_too_few_samples_for_the_base_parameters_is_refused(tmp_path, capsys, panda):
    data = inverse_dynamics_data(panda, T=0.03, dt=2e-3)
    path = tmp_path / "short.csv"
    header = ["t", *(f"q{i}" for i in range(1, 8)), *(f"tau{i}" for i in range(1, 8))]
    np.savetxt(path, np.column_stack([data.t, data.q, data.tau]), delimiter=",", header=",".join(header), comments="")
    assert main(["identify", str(path), "--robot", "panda-slotine-li", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "at least" in err and "base parameters" in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_phi_hat0_file_errors_name_the_field(tmp_path, capsys):
    assert main(["run", "example-6.3.1", "--set", 'controller.phi_hat0={file="nowhere.json"}', "--no-plots",
                 "--out", str(tmp_path)]) == 2
    assert "controller.phi_hat0.file: no such file" in capsys.readouterr().err
    (tmp_path / "other.json").write_text(json.dumps({"param_names": ["a"], "phi": [1.0], "base_names": ["a"],
                                                     "base": {"wls": [1.0]}, "estimate": "wls"}))
    assert main(["run", "example-6.3.1", "--set", f'controller.phi_hat0={{file="{tmp_path / "other.json"}"}}',
                 "--no-plots", "--out", str(tmp_path)]) == 2
    assert "no value for the controller's parameters m1, m2" in capsys.readouterr().err


def test_the_identified_urdf_reads_back_as_the_parameters_written(tmp_path, panda):
    """A consistent change of every link (each scaled, link 7 carrying a 1.5 kg point 0.1 m out) written into a copy of
    the Panda's URDF: the copy, read with the same locked joints, has exactly those parameters (our tree and Pinocchio);
    a row that is no body is refused, naming it."""
    import pinocchio as pin

    from robotadapt.robots.kinematic_tree import KinematicTree
    from robotadapt.robots.pinocchio import example_urdf
    from robotadapt.robots.urdf_export import write_identified_urdf
    from robotadapt.validation import ConfigError

    path, locked = example_urdf("panda")
    rows = KinematicTree.from_urdf(path, locked).link_params * np.random.default_rng(2).uniform(0.8, 1.2, (7, 1))
    c = np.array([0.0, 0.0, 0.1])  # the point mass: m, m c, m(‖c‖²𝟙 − c cᵀ) in Ixx, Ixy, Iyy, Ixz, Iyz, Izz order
    rows[6] += 1.5 * np.array([1.0, *c, c[2] ** 2, 0.0, c[2] ** 2, 0.0, 0.0, 0.0])
    out = tmp_path / "identified.urdf"
    write_identified_urdf(path, locked, rows, out)
    assert np.allclose(KinematicTree.from_urdf(out, locked).link_params, rows, rtol=1e-12, atol=1e-15)
    model = pin.buildReducedModel(pin.buildModelFromUrdf(str(out)), [pin.buildModelFromUrdf(str(out)).getJointId(j)
                                                                     for j in locked], np.zeros(9))
    pin_rows = np.array([model.inertias[j].toDynamicParameters() for j in range(1, 8)])
    assert np.allclose(pin_rows, rows, rtol=1e-12, atol=1e-15)
    bad = rows.copy()
    bad[2, 0] = -1.0
    with pytest.raises(ConfigError, match="row 2 .*mass must be positive"):
        write_identified_urdf(path, locked, bad, tmp_path / "bad.urdf")
    assert not (tmp_path / "bad.urdf").exists()


@pytest.mark.slow
def test_the_identification_study_closes_the_loop(tmp_path):
    """examples/identification_study.py end to end (about 140 s): the optimised trajectory is better conditioned than the
    packaged one by two orders; the log of an arm with unmodelled friction, quantisation and noise identifies the base
    parameters within 0.5 % with friction columns, 3× worse without (measured 0.0019 and 0.0097); under the natural law
    and a payload, the identified start keeps a smaller base error and tracking error before the payload than the
    30 % low one."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("identification_study",
                                                  Path(__file__).parents[1] / "examples" / "identification_study.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    study = module.run(tmp_path)
    ex = study["excitation"]["cond"]
    assert ex["cond"] < ex["cond_packaged"] / 100
    ident = study["closed_loop"]["identify"]
    assert ident["friction columns"]["base_error"] < min(0.005, ident["friction-free model"]["base_error"] / 3)
    runs = study["closed_loop"]["payload"]
    good, low = runs["natural, γ = 0.1 | identified"], runs["natural, γ = 0.1 | 30 % low"]
    assert good["base_error_at_10"] < low["base_error_at_10"] / 2 and good["rms_deg_0_10"] < low["rms_deg_0_10"]
    assert (tmp_path / "study.md").exists()
