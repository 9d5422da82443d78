"""Parallel filtering, decimation and the cutoff (docs/identification.md#estimation): the same zero-phase Butterworth on
every column of W and on τ leaves Coulomb and viscous friction unbiased; the filter is of order 4; the default cutoff
comes from the data (q's spectrum, or the trajectory of the run that wrote the log) and is named in identified.json; a
log without velocities identified without a low-pass is warned about; bad options are one line each."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robotadapt.analysis.identification import (
    CUTOFF_FACTOR,
    DECIMATED_RATE,
    ROWS_PER_PARAMETER,
    Preprocessing,
    excitation_band,
    identify,
    lowpass,
    samples,
)
from robotadapt.analysis.joint_data import JointData
from robotadapt.cli import main
from robotadapt.robots.identifiability import base_parameters
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import fourier

VISCOUS = [0.6] * 4 + [0.2] * 3  # N·m·s/rad, the order Gaz et al. (RA-L 2019) fit on a real Panda
COULOMB = [0.5] * 4 + [0.2] * 3  # N·m


@pytest.fixture(scope="module")
def panda_friction():
    """The Panda with viscous and Coulomb friction columns, and φ with the friction above."""
    model = load("panda-slotine-li", ["robot.viscous=true", "robot.coulomb=true"]).setup.controller.model
    phi = np.array(model.default_phi, dtype=float)
    fv = [i for i, name in enumerate(model.param_names) if name.startswith("fv")]
    fc = [i for i, name in enumerate(model.param_names) if name.startswith("fc")]
    phi[fv], phi[fc] = VISCOUS, COULOMB
    return model, phi, fv, fc


def exciting(n: int, period: float = 4.0, seed: int = 27):
    a, b = np.random.default_rng(seed).uniform(-0.4, 0.4, (2, n, 4))
    return fourier(n, period, a, b, [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785][:n])


def test_parallel_filtering_leaves_friction_unbiased(panda_friction):
    """Noise-free Panda, 8 s at 500 Hz, a 10-Hz low-pass: every fc and fv within 0.5 % (measured 1e-7). Rebuilding W
    from low-passed q, q̇ instead (the step of sign(q̇) kept while τ's is rounded) is off by 10 % or more."""
    model, phi, fv, fc = panda_friction
    t = np.arange(0.0, 8.0, 2e-3)
    ref = exciting(7)(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ phi
    data = JointData(t, ref.q_des, ref.dq_des, tau, "panda")
    res = identify(model, data, Preprocessing(cutoff=10.0), consistent=False)
    for name in ("ols", "wls"):
        phi_hat = res.standard[name]
        err = np.abs(phi_hat[fc + fv] / phi[fc + fv] - 1)
        print(f"{name}: largest relative friction error {np.max(err):.2g}")
        assert np.max(err) < 5e-3, (name, err)
    # the filter-then-build variant on the same data, for contrast
    basis = base_parameters(model)
    f = lambda x: lowpass(x, 10.0, 500.0)[150:-150]  # noqa: E731
    W = np.asarray(model.regressor(f(ref.q_des), f(ref.dq_des), f(ref.dq_des), f(ref.ddq_des)))
    base = np.linalg.lstsq(W[..., list(basis.independent)].reshape(-1, basis.count), f(tau).reshape(-1),
                           rcond=None)[0]
    standard = phi + np.linalg.pinv(basis.K) @ (base - basis.K @ phi)
    print(f"filter-then-build: largest relative Coulomb error {np.max(np.abs(standard[fc] / phi[fc] - 1)):.2g}")
    assert np.max(np.abs(standard[fc] / phi[fc] - 1)) > 0.1


def test_the_low_pass_is_of_order_4():
    """A zero-phase Butterworth of order N passes a sine at f as 1/(1 + (f/f_c)^{2N}): 1/2 at f_c and 1/257 at 2 f_c
    for N = 4 (order 2 would pass 1/17) — measured on τ through :func:`samples`, the path identification takes."""
    model = load("example-6.3.1").setup.controller.model
    rate, cutoff = 1000.0, 10.0
    t = np.arange(0.0, 20.0, 1.0 / rate)
    q = np.column_stack([np.sin(t), np.cos(t)])
    for f, gain in ((cutoff, 0.5), (2 * cutoff, 1 / 257)):
        tau = np.column_stack([np.sin(2 * np.pi * f * t), np.zeros_like(t)])
        pre = Preprocessing(cutoff=cutoff, decimate=1).resolve(JointData(t, q, None, tau, "sine"))
        s = samples(base_parameters(model), JointData(t, q, None, tau, "sine"), pre)
        amplitude = np.sqrt(2 * np.mean(s.tau[:, 0] ** 2))
        assert amplitude == pytest.approx(gain, rel=0.02), (f, amplitude)


def test_the_default_cutoff_and_decimation_come_from_the_excitation():
    """q with harmonics at 0.25 and 0.5 Hz: 99 % of its spectral energy lies below 0.5 Hz, so the cutoff is 5 × 0.5 Hz,
    the decimation keeps 2.5 samples per cutoff period and the trim is 3 cutoff periods; a known band (a trajectory's)
    is used instead when given; without motion there is no band."""
    rate = 200.0
    t = np.arange(0.0, 40.0, 1.0 / rate)
    q = np.column_stack([np.sin(2 * np.pi * 0.25 * t) + 0.3 * np.sin(2 * np.pi * 0.5 * t), 0.5 * np.cos(np.pi * t)])
    assert excitation_band(q, 1 / rate) == pytest.approx(0.5, abs=0.03)
    data = JointData(t, q, None, 0 * q, "sines")
    s = Preprocessing().resolve(data)
    assert s.cutoff_source == "spectrum" and s.cutoff == pytest.approx(CUTOFF_FACTOR * 0.5, abs=0.15)
    assert s.decimate == int(rate / (DECIMATED_RATE * s.cutoff)) and s.trim == pytest.approx(3.0 / s.cutoff)
    known = Preprocessing(band=0.6, band_source="test").resolve(data)
    assert (known.cutoff, known.cutoff_source) == (pytest.approx(3.0), "trajectory")
    assert Preprocessing(cutoff=7.0, decimate=3).resolve(data).decimate == 3
    assert Preprocessing(cutoff=None).resolve(data).decimate == 1
    assert excitation_band(np.zeros((100, 2)), 0.01) is None
    # a short log is not thinned below ROWS_PER_PARAMETER equations per base parameter (3 s of the Panda's 100 Hz log
    # kept 4 samples for 43 parameters): the cap binds, and it keeps that many rows after the trim
    short = JointData(t[:600], q[:600], None, 0 * q[:600], "short")
    free, capped = Preprocessing().resolve(short), Preprocessing().resolve(short, parameters=20)
    kept = np.count_nonzero((short.t >= short.t[0] + capped.trim) & (short.t <= short.t[-1] - capped.trim))
    assert capped.decimate < free.decimate and capped.decimate == kept * 2 // (ROWS_PER_PARAMETER * 20)
    assert Preprocessing().resolve(data, parameters=2).decimate == s.decimate  # a long log: the cap does not bind


def test_a_log_without_velocities_needs_the_low_pass():
    """The Panda, 8 s at 1 kHz, q with 2e-5 rad of noise and no q̇, τ with 0.1 N·m: without a low-pass the twice
    differentiated noise (q̈'s noise ≈ 10 × its signal) biases every estimate (base error 0.52) while the standard
    deviations look small (median 6.3 %; z² in the thousands) and a warning says so; the default cutoff (5 Hz, from q's
    spectrum) brings the base error to 0.0035 with standard deviations that cover it."""
    setup = load("panda-slotine-li").setup
    model, phi = setup.controller.model, setup.plant.phi
    t = np.arange(0.0, 8.0, 1e-3)
    ref = exciting(7)(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ phi
    rng = np.random.default_rng(0)
    data = JointData(t, ref.q_des + 2e-5 * rng.standard_normal(ref.q_des.shape), None,
                     tau + 0.1 * rng.standard_normal(tau.shape), "log.csv")
    found = {}
    for cutoff in (None, "auto"):
        res = identify(model, data, Preprocessing(cutoff=cutoff), consistent=False)
        e = res.base["wls"] - res.basis.K @ phi
        found[cutoff] = (np.linalg.norm(e) / np.linalg.norm(res.basis.K @ phi), np.mean(e**2 / np.diag(res.covariance)),
                         float(np.median(res.relative_std)), res.warnings)
        print(f"cutoff {cutoff}: base error {found[cutoff][0]:.2g}, mean z² {found[cutoff][1]:.3g}, median relative "
              f"std {found[cutoff][2]:.2g} %")
    assert found[None][0] > 0.3 and found[None][1] > 100 and found[None][3][0].startswith("--cutoff: none")
    assert found["auto"][0] < 0.01 and found["auto"][1] < 3 and not found["auto"][3]


def _csv(path: Path, velocities: bool = True, T: float = 8.0, dt: float = 0.01, seed: int = 27, noise: float = 0.0,
         joints: int = 2) -> Path:
    """A CSV log of Example 6.3.1's two-link arm on an exciting path (τ = Y φ, + noise)."""
    setup = load("example-6.3.1").setup
    model = setup.controller.model
    t = np.arange(0.0, T, dt)
    a, b = np.random.default_rng(seed).uniform(-0.4, 0.4, (2, 2, 4))
    ref = fourier(2, 4.0, a, b, [0.3, 0.5])(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ setup.plant.phi
    tau = tau + noise * np.random.default_rng(seed + 1).standard_normal(tau.shape)
    q = np.column_stack([ref.q_des] + ([ref.q_des[:, :1]] if joints == 3 else []))
    cols = {"t": t, **{f"q{i + 1}": q[:, i] for i in range(q.shape[1])}, **{f"tau{i + 1}": tau[:, i] for i in range(2)}}
    if velocities:
        cols.update({f"dq{i + 1}": ref.dq_des[:, i] for i in range(2)})
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    return path


def test_a_log_without_velocities_and_without_a_cutoff_is_warned_about(tmp_path, capsys):
    """`--cutoff none` on a CSV without dq: one warning line naming --cutoff (and recorded in identified.json); with
    velocities, or with the default cutoff, none."""
    bare = _csv(tmp_path / "bare.csv", velocities=False)
    assert main(["identify", str(bare), "--robot", "example-6.3.1", "--cutoff", "none", "--out", str(tmp_path / "a"),
                 "--no-plots", "--holdout", "0"]) == 0
    err = capsys.readouterr().err.strip()
    assert err.startswith("robotadapt: warning: --cutoff") and "\n" not in err and "--cutoff auto" in err
    record = json.loads((tmp_path / "a" / "identified.json").read_text())
    assert record["preprocessing"]["cutoff"] is None and record["preprocessing"]["cutoff_source"] == "none"
    assert len(record["warnings"]) == 1 and "Warning: --cutoff" in (tmp_path / "a" / "identified.md").read_text()
    for args in (["--cutoff", "none"], []):
        log = _csv(tmp_path / "full.csv") if args else bare
        assert main(["identify", str(log), "--robot", "example-6.3.1", *args, "--out", str(tmp_path / "b"),
                     "--no-plots", "--holdout", "0"]) == 0
        assert "warning" not in capsys.readouterr().err


def test_the_cutoff_and_decimation_are_named_in_the_output(tmp_path, capsys):
    """A run of a sum of sines (Example 6.3.1, q_d = sin t): the cutoff is 5 × its frequency 1/(2π) Hz, its source the
    scenario.toml beside result.npz; identified.json and identified.md say the cutoff, its source and the decimation."""
    assert main(["run", "example-6.3.1", "--t-final", "20", "--no-plots", "--out", str(tmp_path / "run")]) == 0
    out = tmp_path / "id"
    assert main(["identify", str(tmp_path / "run" / "result.npz"), "--robot", "example-6.3.1", "--out", str(out),
                 "--no-plots", "--holdout", "0"]) == 0
    pre = json.loads((out / "identified.json").read_text())["preprocessing"]
    assert pre["cutoff_source"] == "trajectory" and pre["band_hz"] == pytest.approx(1 / (2 * np.pi))
    assert pre["cutoff"] == pytest.approx(CUTOFF_FACTOR / (2 * np.pi)) and "scenario.toml" in pre["band_source"]
    assert pre["decimate"] == int(1000 / (DECIMATED_RATE * pre["cutoff"]) * (1 + 1e-9)) and pre["decimate_source"] == "auto"
    assert pre["decimated_rate_hz"] == pytest.approx(1000 / pre["decimate"])
    md = (out / "identified.md").read_text()
    assert f"1 sample in {pre['decimate']} kept" in md and "0.796 Hz" in md
    assert f"1 sample in {pre['decimate']} kept" in capsys.readouterr().out


@pytest.mark.parametrize("args, words", [
    (["--cutoff", "fast"], "--cutoff: expected a frequency in Hz, 'auto' or 'none', got 'fast'"),
    (["--cutoff", "-2"], "--cutoff: must be positive"),
    (["--cutoff", "80"], "--cutoff: 80 Hz is not below the Nyquist frequency 50 Hz"),
    (["--decimate", "0"], "--decimate: expected a whole number ≥ 1 or 'auto', got 0"),
    (["--decimate", "often"], "--decimate: expected a whole number ≥ 1 or 'auto', got 'often'"),
])
def test_bad_filter_options_are_one_line(tmp_path, capsys, args, words):
    log = _csv(tmp_path / "log.csv")
    assert main(["identify", str(log), "--robot", "example-6.3.1", *args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err and err.startswith("robotadapt: error: ")
    assert not (tmp_path / "o").exists()
