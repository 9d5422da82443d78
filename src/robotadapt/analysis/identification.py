"""Identification of the base parameters from logged joint data (docs/identification.md).

The inverse dynamics is linear in φ and, through the base parameters φ_b = K φ (:mod:`robotadapt.robots.identifiability`),
in a minimal set: τ(t_j) = Y_b(q_j, q̇_j, q̇_j, q̈_j) φ_b. Stacking the samples gives the overdetermined system
W φ_b = 𝛕 (Gautier & Khalil 1990; Swevers et al. 1997), solved here in the steps an identification engineer takes:

1. **Samples** (:func:`samples`): a zero-phase Butterworth low-pass (order 4, `scipy.signal.sosfiltfilt`) on q, q̇ and
   τ alike — the same filter on both sides of the equation ("parallel filtering") keeps them consistent without delay;
   q̇ (when not logged) and q̈ by Savitzky–Golay differentiation (`scipy.signal.savgol_filter`, exact on polynomials of
   its order); the filter's edges trimmed; then every D-th sample (decimation: the low-pass is its anti-alias filter).
2. **Ordinary least squares** φ_b = W⁺𝛕, and the residual ρ = 𝛕 − W φ_b.
3. **Weighted least squares** (Gautier & Poignet 2001): each joint's noise variance from its OLS residuals,
   σ_i² = ‖ρ_i‖² / N · Nn / (Nn − b), rows weighted by 1/σ_i, φ_b = (WᵀΣ⁻¹W)⁻¹ WᵀΣ⁻¹𝛕 with covariance
   C = (WᵀΣ⁻¹W)⁻¹ and relative standard deviations 100 √C_jj / |φ_b,j| %.
4. **A physically consistent estimate** (:func:`consistent_estimate`): the standard φ that fits the same weighted data
   with every link's pseudo-inertia J_i(φ) ⪰ ε𝟙 and every physical scalar ≥ ε (:mod:`robotadapt.robots.consistency`;
   Sousa & Cortesão 2014, Wensing, Kim & Slotine 2017), plus a weak pull toward the prior φ₀ (the model's nominal
   values) that fixes the directions no data sees. A semidefinite program, solved by cvxpy with Clarabel.
5. **Prediction** of held-out torque (the last part of the log, never used in the fit): RMS error per joint of each
   estimate and of the prior.

An ordinary or weighted estimate becomes a standard φ by the smallest change of the prior that has its base parameters,
φ = φ₀ + K⁺(φ_b − K φ₀): the same dynamics, and the unidentifiable directions left at the prior.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..robots.base import RobotModel
from ..robots.consistency import parts, smallest_eigenvalues
from ..robots.identifiability import BaseParameters, base_parameters
from ..validation import ConfigError, as_scalar
from .consistent import PRIOR_WEIGHT, consistent_estimate
from .joint_data import JointData

Array = np.ndarray
ESTIMATES = ("consistent", "wls", "ols")
FILTER_ORDER = 4
EDGE_TIME_CONSTANTS = 3.0  # the default trim: 3/cutoff s at each end, where the zero-phase filter has not settled


@dataclass(frozen=True)
class Preprocessing:
    """How logged data become samples (step 1 of the module docstring): `cutoff` Hz of the zero-phase low-pass (None:
    none), Savitzky–Golay `window` (odd, samples) and `polyorder`, `trim` s dropped at each end (None: 3/cutoff), keep
    every `decimate`-th sample."""

    cutoff: float | None = None
    window: int = 9
    polyorder: int = 6
    trim: float | None = None
    decimate: int = 1

    def __post_init__(self) -> None:
        if self.cutoff is not None:
            as_scalar(self.cutoff, "--cutoff", positive=True)
        for name, low in (("window", 3), ("polyorder", 1), ("decimate", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ConfigError(f"--{name}", f"expected a whole number ≥ {low}, got {value!r}")
        if self.window % 2 == 0 or self.polyorder >= self.window:
            raise ConfigError("--window", f"expected an odd window longer than --polyorder {self.polyorder}, got "
                              f"{self.window}")
        if self.trim is not None:
            as_scalar(self.trim, "--trim", nonnegative=True)

    def as_dict(self) -> dict[str, Any]:
        return {"cutoff_hz": self.cutoff, "savgol_window": self.window, "savgol_polyorder": self.polyorder,
                "trim_s": self.trim_time, "decimate": self.decimate, "filter_order": FILTER_ORDER}

    @property
    def trim_time(self) -> float:
        if self.trim is not None:
            return float(self.trim)
        return 0.0 if self.cutoff is None else EDGE_TIME_CONSTANTS / self.cutoff


@dataclass(frozen=True, eq=False)
class Samples:
    """Filtered samples: `t` (N,), `q, dq, ddq, tau` (N, n)."""

    t: Array
    q: Array
    dq: Array
    ddq: Array
    tau: Array

    def split(self, holdout: float) -> tuple[Samples, Samples]:
        """The first 1 − `holdout` of the time for the fit, the rest held out."""
        cut = int(np.searchsorted(self.t, self.t[0] + (1.0 - holdout) * (self.t[-1] - self.t[0])))
        return self._part(slice(None, cut)), self._part(slice(cut, None))

    def _part(self, keep: slice) -> Samples:
        return Samples(self.t[keep], self.q[keep], self.dq[keep], self.ddq[keep], self.tau[keep])


def samples(data: JointData, pre: Preprocessing) -> Samples:
    """Step 1 of the module docstring."""
    import scipy.signal

    dt, size = data.dt, data.t.size
    if size < pre.window:
        raise ConfigError("DATA", f"{data.source} has {size} samples, fewer than the derivative's window {pre.window}")
    filt = lambda x: x  # noqa: E731
    if pre.cutoff is not None:
        nyquist = 0.5 / dt
        if pre.cutoff >= nyquist:
            raise ConfigError("--cutoff", f"{pre.cutoff:g} Hz is not below the data's Nyquist frequency {nyquist:g} Hz")
        sos = scipy.signal.butter(FILTER_ORDER, pre.cutoff, fs=1.0 / dt, output="sos")
        if size <= 3 * 2 * len(sos):
            raise ConfigError("DATA", f"{data.source} has {size} samples, too few to filter")
        filt = lambda x: scipy.signal.sosfiltfilt(sos, x, axis=0)  # noqa: E731

    def deriv(x: Array, order: int) -> Array:
        return scipy.signal.savgol_filter(x, pre.window, pre.polyorder, deriv=order, delta=dt, axis=0)

    q = filt(data.q)
    dq, ddq = (deriv(q, 1), deriv(q, 2)) if data.dq is None else (filt(data.dq), deriv(filt(data.dq), 1))
    tau = filt(data.tau)
    edge = int(round(pre.trim_time / dt))
    keep = slice(edge, size - edge, pre.decimate)
    out = Samples(data.t[keep], q[keep], dq[keep], ddq[keep], tau[keep])
    if out.t.size < 2:
        raise ConfigError("--trim", f"trimming {pre.trim_time:g} s at each end leaves no data of {data.source}")
    return out


def stacked(basis: BaseParameters, s: Samples) -> tuple[Array, Array]:
    """W (N, n, b) = Y_b(q, q̇, q̇, q̈) at the samples, and 𝛕 (N, n)."""
    Y = basis.model.regressor(s.q, s.dq, s.dq, s.ddq)
    return np.asarray(Y)[..., list(basis.independent)], s.tau


def least_squares(W: Array, tau: Array, sigma: Array | None = None) -> Array:
    """argmin Σ_ji ((τ_ji − W_ji φ_b)/σ_i)² (σ = 1: ordinary least squares)."""
    w = np.ones(W.shape[1]) if sigma is None else 1.0 / sigma
    return np.linalg.lstsq((W * w[:, None]).reshape(-1, W.shape[-1]), (tau * w).reshape(-1), rcond=None)[0]


def joint_noise(W: Array, tau: Array, phi_b: Array) -> Array:
    """σ_i of step 3: each joint's residual standard deviation, corrected for the b fitted parameters."""
    rho = tau - W @ phi_b
    N, n = tau.shape
    return np.sqrt(np.sum(rho**2, axis=0) / N * (N * n) / (N * n - W.shape[-1]))


@dataclass(frozen=True, eq=False)
class Identification:
    """The result of :func:`identify`: base estimates (`ols`, `wls`, `consistent` as K φ_c), per-joint noise `sigma`,
    the WLS covariance and relative standard deviations (%), the standard vectors `standard[name]` (consistent: the
    program's φ; the others by the prior's smallest change), the held-out samples' times, torques and each estimate's
    (and the prior's) predicted torques, the condition number of the fit's W, and the sample counts."""

    basis: BaseParameters
    prior: Array
    base: dict[str, Array]
    standard: dict[str, Array]
    sigma: Array
    covariance: Array
    relative_std: Array
    holdout_t: Array
    holdout_tau: Array
    holdout_prediction: dict[str, Array]
    condition_number: float
    fit_samples: int
    settings: dict[str, Any] = field(default_factory=dict)

    def consistency(self, name: str) -> float:
        """The smallest pseudo-inertia eigenvalue (or physical scalar) of `standard[name]`."""
        return float(np.min(smallest_eigenvalues(self.standard[name], parts(self.basis.model.param_names))))

    @property
    def holdout_rms(self) -> dict[str, Array]:
        """RMS of the held-out torque's prediction error, per joint, of each estimate and the prior."""
        return {k: np.sqrt(np.mean((self.holdout_tau - v) ** 2, axis=0)) for k, v in self.holdout_prediction.items()}

    def as_dict(self) -> dict[str, Any]:
        names = self.basis.model.param_names
        return {
            "param_names": list(names), "prior": self.prior.tolist(),
            "standard": {k: v.tolist() for k, v in self.standard.items()},
            "base_names": list(self.basis.names), "base": {k: v.tolist() for k, v in self.base.items()},
            "relative_std_percent": self.relative_std.tolist(), "sigma": self.sigma.tolist(),
            "holdout_rms": {k: v.tolist() for k, v in self.holdout_rms.items()},
            "holdout_tau_rms": np.sqrt(np.mean(self.holdout_tau**2, axis=0)).tolist() if self.holdout_t.size else [],
            "min_pseudo_inertia_eigenvalue": {k: self.consistency(k) for k in self.standard},
            "condition_number": self.condition_number, "fit_samples": self.fit_samples,
            "holdout_samples": int(self.holdout_t.size), **self.settings,
        }


def identify(model: RobotModel, data: JointData, pre: Preprocessing, holdout: float = 0.25,
             consistent: bool = True, epsilon: float = 1e-8, prior: Array | None = None) -> Identification:
    """Steps 1–5 of the module docstring for `model` on `data`; the prior φ₀ defaults to `model.default_phi` (zeros for
    a model without nominal values)."""
    holdout = as_scalar(holdout, "--holdout", nonnegative=True, maximum=0.9)
    if data.n != model.n:
        raise ConfigError("DATA", f"{data.source} has {data.n} joints, the robot {model.n}")
    basis = base_parameters(model)
    prior = model.default_phi if prior is None else prior
    phi0 = np.zeros(model.p) if prior is None else np.asarray(prior, dtype=float)  # no nominal values: pull toward 0
    fit, held = samples(data, pre).split(holdout)
    W, tau = stacked(basis, fit)
    rows, b = W.shape[0] * W.shape[1], basis.count
    if rows < 2 * b or W.shape[0] < 2:
        raise ConfigError("DATA", f"{data.source} gives {W.shape[0]} fit samples × {model.n} joints = {rows} equations "
                          f"for {b} base parameters: at least {2 * b} are needed (log longer, decimate less, or "
                          "hold out less)")
    cond = float(np.linalg.cond(W.reshape(rows, b)))
    if not np.isfinite(cond) or cond > 1e12:
        raise ConfigError("DATA", f"{data.source} does not excite the {b} base parameters (condition number of W "
                          f"{cond:.3g}): log an exciting trajectory (`robotadapt excite`)")
    ols = least_squares(W, tau)
    sigma = joint_noise(W, tau, ols)
    floor = 1e-12 * max(float(np.sqrt(np.mean(tau**2))), 1e-300)  # noise-free data: weights stay finite
    sigma_w = np.maximum(sigma, floor)
    wls = least_squares(W, tau, sigma_w)
    Ww = (W / sigma_w[:, None]).reshape(rows, b)
    covariance = np.linalg.inv(Ww.T @ Ww)
    with np.errstate(divide="ignore"):
        relative_std = 100.0 * np.sqrt(np.diag(covariance)) / np.abs(wls)
    K = basis.K
    pinv = np.linalg.pinv(K)
    base = {"ols": ols, "wls": wls}
    standard = {k: phi0 + pinv @ (v - K @ phi0) for k, v in base.items()}
    status = None
    if consistent:
        standard["consistent"], status = consistent_estimate(basis, W, tau, sigma_w, phi0, epsilon)
        base["consistent"] = K @ standard["consistent"]
    Wh, tau_h = stacked(basis, held) if held.t.size else (np.zeros((0, model.n, b)), np.zeros((0, model.n)))
    prediction = {k: Wh @ v for k, v in {**base, "prior": K @ phi0}.items()} if held.t.size else {}
    return Identification(basis, phi0, base, standard, sigma, covariance, relative_std, held.t, tau_h, prediction, cond,
                          int(W.shape[0]), {"preprocessing": pre.as_dict(), "holdout_fraction": holdout,
                                            "epsilon": epsilon, "prior_weight": PRIOR_WEIGHT,
                                            "solver_status": status})
