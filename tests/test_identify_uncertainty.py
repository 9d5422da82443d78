"""Honest standard deviations on filtered data (docs/identification.md#estimation): the low-pass correlates neighbouring
samples, the default decimation keeps 2.5 samples per cutoff period and the Newey–West covariance accounts for what
correlation remains. Checked by Monte Carlo: with per-joint torque noise σ_i (and position noise, no logged velocities,
the default preprocessing), the mean z² of the base parameters, z = (φ̂_b − φ_b)/std, is about 1; and the weights are
1/σ_i², so the joint with the quieter torque sensor sets the parameters it sees."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from robotadapt.analysis.identification import DECIMATED_RATE, Preprocessing, hac_covariance, identify, lowpass
from robotadapt.analysis.joint_data import JointData
from robotadapt.robots.catalog import planar
from robotadapt.trajectories import fourier


def planar_arm():
    """A two-link planar arm of rods with viscous and Coulomb friction: 10 base parameters."""
    return planar(2, lengths=[0.5, 0.4], masses=[2.0, 1.5], rods=True, viscous=[0.3, 0.2], coulomb=[0.4, 0.2])


def monte_carlo(model, phi, trajectory, T: float, rate: float, sigma_tau, sigma_q: float, draws: int,
                pre: Preprocessing | None = None):
    """`draws` logs of `trajectory` (q with noise σ_q and no velocities, τ = Y φ + noise σ_tau per joint), each
    identified with `pre` (default: the default preprocessing): the WLS and OLS errors (draws, b), the WLS standard
    deviations (draws, b), the textbook ones (draws, b; (WᵀΣ⁻¹W)⁻¹ with σ_i from OLS, as if the kept samples were
    independent), and the last result."""
    t = np.arange(0.0, T, 1.0 / rate)
    ref = trajectory(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ phi
    wls, ols, std, textbook = [], [], [], []
    for k in range(draws):
        rng = np.random.default_rng(k)
        data = JointData(t, ref.q_des + sigma_q * rng.standard_normal(ref.q_des.shape), None,
                         tau + np.asarray(sigma_tau) * rng.standard_normal(tau.shape), f"draw {k}")
        res = identify(model, data, pre or Preprocessing(), holdout=0.0, consistent=False)
        truth = res.basis.K @ phi
        wls.append(res.base["wls"] - truth)
        ols.append(res.base["ols"] - truth)
        std.append(np.sqrt(np.diag(res.covariance)))
        textbook.append(std[-1] / res.inflation)
    return np.array(wls), np.array(ols), np.array(std), np.array(textbook), res


def test_the_standard_deviations_hold_on_filtered_data_and_the_quiet_joint_weighs_more():
    """40 draws, 40 s at 500 Hz, σ_τ = (0.3, 0.01) N·m, σ_q = 1e-5 rad, no logged q̇: the default low-pass (5 × the
    band) and decimation (to 2.5 × the cutoff): mean z² within [0.7, 1.4] (measured 1.12; the textbook (WᵀΣ⁻¹W)⁻¹,
    as if the kept samples were independent, reads 1.16 on the same draws); and for every parameter joint 2's torque
    sees, WLS's mean square error under half OLS's (weights 1/σ_i²; weights σ_i² make it worse than OLS and the
    reported std too small, failing both)."""
    model = planar_arm()
    a, b = np.random.default_rng(3).uniform(-1.0, 1.0, (2, 2, 4))
    wls, ols, std, textbook, res = monte_carlo(model, model.default_phi, fourier(2, 4.0, a, b, [0.3, 0.5]), 40.0,
                                               500.0, [0.3, 0.01], 1e-5, 40)
    z2, z2_textbook = np.mean((wls / std) ** 2), np.mean((wls / textbook) ** 2)
    seen = np.flatnonzero(_joint_rows(res, 1) > 0)
    ratio = np.mean(wls[:, seen] ** 2, axis=0) / np.mean(ols[:, seen] ** 2, axis=0)
    print(f"mean z² {z2:.3g} (textbook covariance: {z2_textbook:.3g}); WLS/OLS mean square error of the parameters "
          f"joint 2 sees {np.round(ratio, 3)}")
    assert 0.7 < z2 < 1.4, z2
    pre = res.preprocessing
    assert pre.cutoff_source == "spectrum" and pre.cutoff == pytest.approx(5.0, rel=0.05)
    assert pre.decimate == int(500.0 / (2.5 * pre.cutoff) * (1 + 1e-9))
    assert seen.size >= 4
    assert np.max(ratio) < 0.5, ratio


def test_the_standard_deviations_hold_undecimated():
    """The same arm and noise, 20 draws, every filtered sample kept (`--decimate 1`): the Newey–West covariance, over
    300 lags here, still gives a mean z² within [0.7, 1.4] (measured 1.00), where the textbook covariance reads about
    40 (its standard deviations 6.5 × too small)."""
    model = planar_arm()
    a, b = np.random.default_rng(3).uniform(-1.0, 1.0, (2, 2, 4))
    wls, _, std, textbook, res = monte_carlo(model, model.default_phi, fourier(2, 4.0, a, b, [0.3, 0.5]), 40.0, 500.0,
                                             [0.3, 0.01], 1e-5, 20, Preprocessing(decimate=1))
    z2, z2_textbook = np.mean((wls / std) ** 2), np.mean((wls / textbook) ** 2)
    print(f"mean z² {z2:.3g} (textbook covariance: {z2_textbook:.3g}, Newey–West lags {res.settings['covariance']['lags']})")
    assert res.preprocessing.decimate == 1 and res.settings["covariance"]["lags"] == 300
    assert 0.7 < z2 < 1.4 and z2_textbook > 10, (z2, z2_textbook)


def _joint_rows(res, joint: int) -> np.ndarray:
    """How much each base parameter enters joint `joint`'s torque at a few random states (0: not at all)."""
    rng = np.random.default_rng(0)
    x = [rng.uniform(-1.0, 1.0, (20, 2)) for _ in range(4)]
    Y = np.asarray(res.basis.model.regressor(*x))[:, joint][:, list(res.basis.independent)]
    return np.max(np.abs(Y), axis=0)


def test_the_newey_west_covariance_is_the_textbook_one_on_white_residuals():
    """L = 0 and σ_i² the residuals' own variance: C = (WᵀΣ⁻¹W)⁻¹ · Nn/(Nn − b); lags add the autocovariances, and a
    positive correlation of neighbouring samples makes C larger."""
    rng = np.random.default_rng(1)
    W = rng.normal(size=(200, 2, 3))
    rho = rng.normal(size=(200, 2)) * [0.5, 2.0]
    sigma = np.sqrt(np.mean(rho**2, axis=0))
    A = np.einsum("tjb,j,tjc->bc", W, 1 / sigma**2, W)
    assert np.allclose(hac_covariance(W, rho, sigma, 0), np.linalg.inv(A) * 400 / 397, rtol=1e-12)
    smooth = np.cumsum(rho, axis=0)  # a random walk: strongly correlated
    smooth -= smooth.mean(axis=0)
    slow = np.repeat(rng.normal(size=(20, 2, 3)), 10, axis=0)  # regressors that vary slowly too
    s = np.sqrt(np.mean(smooth**2, axis=0))
    assert np.all(np.diag(hac_covariance(slow, smooth, s, 10)) > 2 * np.diag(hac_covariance(slow, smooth, s, 0)))


def test_the_default_decimation_leaves_little_correlation_for_the_covariance_to_absorb():
    """White noise through the zero-phase low-pass, kept at r samples per cutoff period: the correlation of neighbours
    and the variance factor κ = 1 + 2 Σ_k corr(k) by which the textbook covariance of a slowly varying W reads low.
    At the default r = 2.5 (the cutoff at 0.8 × the kept Nyquist, Gautier's rule): 0.32 and 1.39; at r = 5, 0.78 and
    2.8; at r = 2, 0.10 and 1.11."""
    rate, cutoff = 1000.0, 5.0
    impulse = np.zeros(8001)
    impulse[4000] = 1.0
    h = lowpass(impulse[:, None], cutoff, rate)[:, 0]
    r = scipy.signal.fftconvolve(h, h[::-1])[h.size - 1:]
    r /= r[0]
    found = {}
    for kept in (2.0, DECIMATED_RATE, 5.0):
        lag = r[:: int(rate / (kept * cutoff))]
        found[kept] = (lag[1], 1 + 2 * np.sum(lag[1:]))
        print(f"{kept:g} samples per cutoff period: neighbour correlation {lag[1]:.2f}, κ = {found[kept][1]:.3g}")
    assert DECIMATED_RATE == 2.5
    assert found[2.5][0] == pytest.approx(0.32, abs=0.01) and found[2.5][1] == pytest.approx(1.39, abs=0.01)
    assert found[5.0][1] == pytest.approx(2.79, abs=0.02) and found[2.0][1] == pytest.approx(1.11, abs=0.01)


@pytest.mark.slow
def test_the_standard_deviations_hold_on_a_filtered_panda_log():
    """The Panda with friction (57 base parameters), 20 draws of 20 s at 500 Hz, σ_τ 0.1 N·m on joints 1–4 and 0.02
    on 5–7, σ_q = 1e-5 rad, no logged q̇, default preprocessing: mean z² within [0.7, 1.4] (measured 1.21; the textbook
    covariance 1.42)."""
    from robotadapt.studies.scenarios import load

    model = load("panda-slotine-li", ["robot.viscous=true", "robot.coulomb=true"]).setup.controller.model
    phi = np.array(model.default_phi, dtype=float)
    names = model.param_names
    for prefix, values in (("fv", [0.6] * 4 + [0.2] * 3), ("fc", [0.5] * 4 + [0.2] * 3)):
        phi[[i for i, name in enumerate(names) if name.startswith(prefix)]] = values
    a, b = np.random.default_rng(27).uniform(-0.4, 0.4, (2, 7, 4))
    trajectory = fourier(7, 4.0, a, b, [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    wls, _, std, textbook, _ = monte_carlo(model, phi, trajectory, 20.0, 500.0, [0.1] * 4 + [0.02] * 3, 1e-5, 20)
    z2 = np.mean((wls / std) ** 2)
    print(f"mean z² {z2:.3g} (textbook covariance: {np.mean((wls / textbook) ** 2):.3g})")
    assert 0.7 < z2 < 1.4, z2
