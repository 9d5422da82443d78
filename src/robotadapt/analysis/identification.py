"""Identification of the base parameters from logged joint data (docs/identification.md).

The inverse dynamics is linear in φ and, through the base parameters φ_b = K φ (:mod:`robotadapt.robots.identifiability`),
in a minimal set: τ(t_j) = Y_b(q_j, q̇_j, q̇_j, q̈_j) φ_b. Stacking the samples gives the overdetermined system
W φ_b = 𝛕 (Gautier & Khalil 1990; Swevers et al. 1997), solved here in the steps an identification engineer takes:

0. **Split before filtering**: the last part of the log is held out as raw data (:func:`split`), and the fit part, the
   held-out part and a second log (`validation`) are each filtered on their own, each with its own edges trimmed, so
   nothing of the held-out data reaches the fit, not even through the filter's memory.
1. **Samples** (:func:`samples`): q̇ (when not logged) and q̈ by Savitzky–Golay differentiation
   (`scipy.signal.savgol_filter`, exact on polynomials of its order) of q lightly low-passed at
   :data:`DERIVATIVE_CUTOFF_FACTOR` × the cutoff (:func:`derivatives`); W built from them at every sample; then the same
   zero-phase Butterworth low-pass (order :data:`FILTER_ORDER`, `scipy.signal.sosfiltfilt`) on every column of W and on
   τ — Gautier's *parallel filtering*: a linear filter F gives F(τ) = F(W) φ_b exactly, whatever W holds (a Coulomb
   step sign(q̇) is rounded in its column as it is in τ); the filter's edges trimmed; then every D-th sample
   (decimation, the low-pass its anti-alias filter), by default down to :data:`DECIMATED_RATE` × the cutoff.
   The cutoff, when not given, comes from the data (:func:`excitation_band`): :data:`CUTOFF_FACTOR` × the excitation's
   band — the trajectory's highest frequency when it is known, else the frequency below which
   :data:`ENERGY_FRACTION` of q's spectral energy lies.
2. **Ordinary least squares** φ_b = W⁺𝛕, and the residual ρ = 𝛕 − W φ_b.
3. **Weighted least squares** (Gautier & Poignet 2001): each joint's noise variance from its OLS residuals,
   σ_i² = ‖ρ_i‖² / N · Nn / (Nn − b), rows weighted by 1/σ_i, φ_b = (WᵀΣ⁻¹W)⁻¹ WᵀΣ⁻¹𝛕. The filter correlates
   neighbouring samples, which (WᵀΣ⁻¹W)⁻¹ ignores; the covariance is a Newey–West (1987) one instead
   (:func:`hac_covariance`), C = A⁻¹ B A⁻¹ with A = WᵀΣ⁻¹W and B built from each joint's residual autocovariances
   (Bartlett-weighted, over the lags where the filter correlates the kept samples), so the standard deviations
   100 √C_jj / |φ_b,j| % hold on filtered data.
4. **A physically consistent estimate** (:func:`consistent_estimate`): the standard φ that fits the same weighted data
   with every link's pseudo-inertia J_i(φ) ⪰ ε𝟙 and every physical scalar ≥ ε (:mod:`robotadapt.robots.consistency`;
   Sousa & Cortesão 2014, Wensing, Kim & Slotine 2017), plus a weak pull toward the prior φ₀ (the model's nominal
   values) that fixes the directions no data sees. A semidefinite program, solved by cvxpy with Clarabel.
5. **Prediction** of the held-out torque and of a second log's: RMS error per joint of each estimate and of the prior
   (and of the model's nominal values where they differ from the prior).

An ordinary or weighted estimate becomes a standard φ by the smallest change of the prior that has its base parameters,
φ = φ₀ + K⁺(φ_b − K φ₀): the same dynamics, and the unidentifiable directions left at the prior.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..robots.base import RobotModel
from ..robots.consistency import parts, smallest_eigenvalues
from ..robots.identifiability import BaseParameters, base_parameters
from ..validation import ConfigError, as_scalar
from .consistent import DIVERGENCE_WEIGHT, PRIOR_WEIGHT, consistent_estimate
from .joint_data import JointData

Array = np.ndarray
ESTIMATES = ("consistent", "wls", "ols")
AUTO = "auto"
FILTER_ORDER = 4  # a zero-phase filter of order N passes f as 1/(1 + (f/f_c)^{2N}): 1/257 at 2 f_c
EDGE_TIME_CONSTANTS = 3.0  # the default trim: 3/cutoff s at each end, where the zero-phase filter has not settled
EDGE_SHARE = 0.25  # ... at most this share of the fit part at each end: the parallel filter is exact at its edges (W and
# τ filtered alike), so a low cutoff on a short log trims only the light pre-filter's settling, not the log
ENERGY_FRACTION = 0.99  # the excitation's band from the data: below it lies this share of q's spectral energy
CUTOFF_FACTOR = 5.0  # the default cutoff: this many times the excitation's band (W holds products of its harmonics)
DECIMATED_RATE = 2.5  # the default decimation keeps a sample rate of 2.5 × the cutoff (cutoff = 0.8 × new Nyquist)
ROWS_PER_PARAMETER = 10  # ... but keeps at least 10 equations per base parameter: a short log is not thinned away
DERIVATIVE_CUTOFF_FACTOR = 2.0  # q (and a logged q̇) low-passed at 2 × the cutoff before differentiation (10 × the band)
HAC_CUTOFF_PERIODS = 3.0  # Newey–West lags: the samples of 3 periods of the cutoff, where the filter's correlation dies


def lowpass(x: Array, cutoff: float, rate: float) -> Array:
    """The zero-phase Butterworth low-pass of step 1 along axis 0 of `x` sampled at `rate` Hz: order
    :data:`FILTER_ORDER` run forward and backward (`scipy.signal.sosfiltfilt`), so the gain is
    1/(1 + (f/cutoff)^{2·order}) and there is no lag. The ends are padded by the signal's point reflection over
    :data:`EDGE_TIME_CONSTANTS` / cutoff s (scipy's default, 15 samples, leaves a 10× larger transient 3/cutoff s in)."""
    import scipy.signal

    sos = scipy.signal.butter(FILTER_ORDER, cutoff, fs=rate, output="sos")
    pad = min(x.shape[0] - 1, max(15, math.ceil(EDGE_TIME_CONSTANTS * rate / cutoff)))
    return np.asarray(scipy.signal.sosfiltfilt(sos, x, axis=0, padlen=pad))


def excitation_band(q: Array, dt: float, fraction: float = ENERGY_FRACTION) -> float | None:
    """The frequency (Hz) below which `fraction` of the positions' spectral energy lies: each joint detrended
    (linearly) and Hann-windowed, the joints' periodograms summed. None when the positions do not move."""
    import scipy.signal

    x = scipy.signal.detrend(np.asarray(q, dtype=float), axis=0)
    scale = float(np.max(np.abs(q))) if q.size else 0.0
    if x.shape[0] < 4 or not np.sqrt(np.mean(x**2)) > 1e-10 * scale:
        return None
    power = np.sum(np.abs(np.fft.rfft(x * np.hanning(x.shape[0])[:, None], axis=0)) ** 2, axis=1)
    k = int(np.searchsorted(np.cumsum(power), fraction * np.sum(power)))
    return float(np.fft.rfftfreq(x.shape[0], dt)[min(k, power.size - 1)])


@dataclass(frozen=True)
class Settings:
    """Preprocessing as applied to one log (:meth:`Preprocessing.resolve`): the `cutoff` (Hz, None: no filter) and
    where it came from (`cutoff_source`: "option", "trajectory", "spectrum", "none"), the excitation `band` (Hz) it
    was derived from, the sample `rate` (Hz), the Savitzky–Golay `window` and `polyorder`, `trim` s at each end, the
    decimation `decimate` and its source ("option", "auto")."""

    cutoff: float | None
    cutoff_source: str
    band: float | None
    band_source: str
    rate: float
    window: int
    polyorder: int
    trim: float
    decimate: int
    decimate_source: str

    @property
    def hac_lags(self) -> int:
        """The Newey–West truncation lag of the fit (in kept samples): :data:`HAC_CUTOFF_PERIODS` periods of the cutoff,
        at least 1; without a filter, Newey & West's (1994) rule ⌊4 (N/100)^{2/9}⌋ is used instead (:func:`identify`)."""
        if self.cutoff is None:
            return 0
        return max(1, math.ceil(HAC_CUTOFF_PERIODS * self.rate / (self.decimate * self.cutoff)))

    def describe(self) -> str:
        """One sentence of what was done, for identified.md and the summary."""
        if self.cutoff is None:
            return ("no low-pass (--cutoff none): W from unfiltered signals" if self.cutoff_source == "none" else
                    "no low-pass (q does not move: no band to set a cutoff from)")
        why = "--cutoff"
        if self.band is not None:
            what = (self.band_source if self.cutoff_source == "trajectory" else
                    f"below which {100 * ENERGY_FRACTION:g} % of q's spectral energy lies")
            why = f"{CUTOFF_FACTOR:g} × {self.band:.3g} Hz, {what}"
            if self.cutoff < CUTOFF_FACTOR * self.band * (1 - 1e-9):
                why += ", capped at a quarter of the sample rate"
        kept = self.rate / self.decimate
        return (f"zero-phase Butterworth order {FILTER_ORDER} at {self.cutoff:.3g} Hz ({why}) on every column of W and "
                f"on τ; {self.trim:.3g} s trimmed at each end; 1 sample in {self.decimate} kept "
                f"({self.rate:.4g} → {kept:.4g} Hz, {kept / self.cutoff:.2g} × the cutoff; "
                f"{'--decimate' if self.decimate_source == 'option' else 'auto'})")

    def as_dict(self) -> dict[str, Any]:
        return {"cutoff": self.cutoff, "cutoff_source": self.cutoff_source, "band_hz": self.band,
                "band_source": self.band_source, "cutoff_factor": CUTOFF_FACTOR, "energy_fraction": ENERGY_FRACTION,
                "filter": "zero-phase Butterworth (sosfiltfilt) on every column of W and on tau (parallel filtering)",
                "filter_order": FILTER_ORDER, "sample_rate_hz": self.rate, "decimate": self.decimate,
                "decimate_source": self.decimate_source, "decimated_rate_hz": self.rate / self.decimate,
                "savgol_window": self.window, "savgol_polyorder": self.polyorder, "trim_s": self.trim,
                "description": self.describe()}


@dataclass(frozen=True)
class Preprocessing:
    """How logged data become samples (step 1 of the module docstring): `cutoff` Hz of the zero-phase low-pass
    ("auto": from the data, :meth:`resolve`; None: none), Savitzky–Golay `window` (odd, samples) and `polyorder`,
    `trim` s dropped at each end (None: 3/cutoff), keep every `decimate`-th sample ("auto": down to
    :data:`DECIMATED_RATE` × the cutoff). `band` (Hz), when given, is the excitation's highest frequency (the
    trajectory's top harmonic, described by `band_source`), which "auto" then uses instead of q's spectrum."""

    cutoff: float | str | None = AUTO
    window: int = 9
    polyorder: int = 6
    trim: float | None = None
    decimate: int | str = AUTO
    band: float | None = None
    band_source: str = "the trajectory's highest frequency"

    def __post_init__(self) -> None:
        if self.cutoff is not None and self.cutoff != AUTO:
            if isinstance(self.cutoff, str):
                raise ConfigError("--cutoff", f"expected a frequency in Hz, 'auto' or 'none', got {self.cutoff!r}")
            as_scalar(self.cutoff, "--cutoff", positive=True)
        if self.band is not None:
            as_scalar(self.band, "--cutoff", positive=True)
        lows = (("window", 3), ("polyorder", 1)) + ((("decimate", 1),) if self.decimate != AUTO else ())
        for name, low in lows:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                extra = " or 'auto'" if name == "decimate" else ""
                raise ConfigError(f"--{name}", f"expected a whole number ≥ {low}{extra}, got {value!r}")
        if self.window % 2 == 0 or self.polyorder >= self.window:
            raise ConfigError("--window", f"expected an odd window longer than --polyorder {self.polyorder}, got "
                              f"{self.window}")
        if self.trim is not None:
            as_scalar(self.trim, "--trim", nonnegative=True)

    def resolve(self, data: JointData, parameters: int = 0) -> Settings:
        """The cutoff, trim and decimation for `data` (the fit part of a log): "auto" cutoff = :data:`CUTOFF_FACTOR` ×
        the band (`band` if given, else :func:`excitation_band` of q), at most a quarter of the sample rate; "auto"
        decimation D = ⌊rate / (:data:`DECIMATED_RATE` × cutoff)⌋ (1 without a cutoff), at most what keeps
        :data:`ROWS_PER_PARAMETER` equations per base parameter (`parameters` of them) after the trim."""
        rate = 1.0 / data.dt
        band, band_source = None, ""
        if self.cutoff == AUTO:
            if self.band is not None:
                band, band_source, source = float(self.band), self.band_source, "trajectory"
            else:
                band = excitation_band(data.q, data.dt)
                band_source, source = "q's spectrum", "spectrum"
            cutoff = None if band is None else min(CUTOFF_FACTOR * band, 0.25 * rate)
        elif self.cutoff is None:
            cutoff, source = None, "none"
        else:
            cutoff, source = float(self.cutoff), "option"
        if self.decimate == AUTO:
            decimate = 1 if cutoff is None else max(1, int(rate / (DECIMATED_RATE * cutoff) * (1 + 1e-9)))
            decimate_source = "auto"
        else:
            decimate, decimate_source = int(self.decimate), "option"
        trim = float(self.trim) if self.trim is not None else 0.0 if cutoff is None else min(
            EDGE_TIME_CONSTANTS / cutoff, EDGE_SHARE * float(data.t[-1] - data.t[0]))  # a short log keeps its middle
        if decimate_source == "auto" and parameters:
            kept = int(np.count_nonzero((data.t >= data.t[0] + trim) & (data.t <= data.t[-1] - trim)))
            decimate = max(1, min(decimate, kept * data.n // (ROWS_PER_PARAMETER * parameters)))
        return Settings(cutoff, source, band, band_source, rate, self.window, self.polyorder, trim, decimate,
                        decimate_source)


@dataclass(frozen=True, eq=False)
class Samples:
    """Filtered samples: `t` (N,), `W` (N, n, b) the base regressor and `tau` (N, n)."""

    t: Array
    W: Array
    tau: Array


def split(data: JointData, holdout: float) -> tuple[JointData, JointData]:
    """The first 1 − `holdout` of the time for the fit, the rest held out — of the raw log, before any filtering."""
    cut = int(np.searchsorted(data.t, data.t[0] + (1.0 - holdout) * (data.t[-1] - data.t[0]), side="right"))
    return data.slice(slice(None, cut)), data.slice(slice(cut, None))


def derivatives(data: JointData, window: int, polyorder: int, smooth: float | None = None) -> tuple[Array, Array, Array]:
    """q, q̇, q̈ of the log: q̇ as logged or by Savitzky–Golay differentiation of q, q̈ by differentiating q̇'s source
    once more (q twice, or the logged q̇ once). `smooth` (Hz), when given and below 0.4 × the sample rate, low-passes
    q and a logged q̇ first (the light filter of step 1, far above the excitation's band): without it the noise n of q
    and the noise of its second derivative, D₂n, are correlated (E[n D₂n] ≈ σ_q² D₂[0] ∝ −σ_q²/dt²), and a product
    such as M(q) q̈ turns that into a bias no later linear filter removes."""
    import scipy.signal

    def deriv(x: Array, order: int) -> Array:
        return np.asarray(scipy.signal.savgol_filter(x, window, polyorder, deriv=order, delta=data.dt, axis=0))

    rate = 1.0 / data.dt
    q, dq = data.q, data.dq
    if smooth is not None and smooth < 0.4 * rate:
        q, dq = lowpass(q, smooth, rate), None if dq is None else lowpass(dq, smooth, rate)
    if dq is None:
        return q, deriv(q, 1), deriv(q, 2)
    return q, dq, deriv(dq, 1)


def samples(basis: BaseParameters, data: JointData, settings: Settings, field_name: str = "DATA") -> Samples:
    """Step 1 of the module docstring on one log (or one part of it): W from :func:`derivatives` (q lightly low-passed
    at :data:`DERIVATIVE_CUTOFF_FACTOR` × the cutoff), then the same low-pass on every column of W and on τ, the edges
    trimmed, every `settings.decimate`-th sample kept. Errors name `field_name`."""
    size = data.t.size
    if size < settings.window:
        raise ConfigError(field_name, f"{data.source} has {size} samples, fewer than the derivative's window "
                          f"{settings.window}")
    if settings.cutoff is not None:
        nyquist = 0.5 * settings.rate
        if settings.cutoff >= nyquist:
            raise ConfigError("--cutoff", f"{settings.cutoff:g} Hz is not below the Nyquist frequency {nyquist:g} Hz "
                              f"of {data.source}: give a lower one, or auto")
    smooth = None if settings.cutoff is None else DERIVATIVE_CUTOFF_FACTOR * settings.cutoff
    q, dq, ddq = derivatives(data, settings.window, settings.polyorder, smooth)
    edge = int(round(settings.trim * settings.rate))
    # the light filter's own edges go first (its settling, within the trim): the parallel filter, exact at its edges
    # (F(τ) = F(W)φ whatever the padding), would otherwise spread their error inward
    first = 0 if smooth is None else min(edge, int(round(EDGE_TIME_CONSTANTS / smooth * settings.rate)))
    inner = slice(first, max(size - first, first))
    t, tau = data.t[inner], data.tau[inner]
    if settings.cutoff is not None and t.size <= 3 * (2 * (FILTER_ORDER // 2) + 1):
        raise ConfigError(field_name, f"{data.source} has {size} samples, too few to filter and trim "
                          f"{settings.trim:g} s at each end: give a longer log, or a shorter --trim")
    W = np.asarray(basis.model.regressor(q[inner], dq[inner], dq[inner], ddq[inner]))[..., list(basis.independent)]
    if settings.cutoff is not None:
        W, tau = lowpass(W, settings.cutoff, settings.rate), lowpass(tau, settings.cutoff, settings.rate)
    keep = slice(edge - first, t.size - (edge - first), settings.decimate)
    out = Samples(t[keep], W[keep], tau[keep])
    if out.t.size < 2:
        raise ConfigError("--trim" if field_name == "DATA" else field_name,
                          f"trimming {settings.trim:g} s at each end leaves no data of {data.source}: give a shorter "
                          "--trim, or a longer log")
    return out


def least_squares(W: Array, tau: Array, sigma: Array | None = None) -> Array:
    """argmin Σ_ji ((τ_ji − W_ji φ_b)/σ_i)² (σ = 1: ordinary least squares)."""
    w = np.ones(W.shape[1]) if sigma is None else 1.0 / sigma
    return np.linalg.lstsq((W * w[:, None]).reshape(-1, W.shape[-1]), (tau * w).reshape(-1), rcond=None)[0]


def joint_noise(W: Array, tau: Array, phi_b: Array) -> Array:
    """σ_i of step 3: each joint's residual standard deviation, corrected for the b fitted parameters."""
    rho = tau - W @ phi_b
    N, n = tau.shape
    return np.sqrt(np.sum(rho**2, axis=0) / N * (N * n) / (N * n - W.shape[-1]))


def hac_covariance(W: Array, rho: Array, sigma: Array, lags: int) -> Array:
    """The covariance of the weighted estimate argmin Σ ((τ − Wφ_b)/σ)² on correlated samples, from the residuals'
    autocorrelation (Newey & West 1987, Bartlett weights): C = A⁻¹ B A⁻¹ · Nn/(Nn − b) with A = Σ_t W_tᵀ Σ⁻¹ W_t and

        B = Σ_i σ_i⁻⁴ Σ_{|l| ≤ L} (1 − |l|/(L + 1)) γ_i(l) Σ_t W_{t,i}ᵀ W_{t−l,i},   γ_i(l) = Σ_t ρ_{t,i} ρ_{t−l,i} / N,

    each joint's noise stationary, independent of W and of the other joints' (what a filtered white noise is); the
    Bartlett weights keep B ⪰ 0. With L = 0 and σ_i² = γ_i(0) it is the textbook (WᵀΣ⁻¹W)⁻¹."""
    N, n, b = W.shape
    v = 1.0 / sigma**2

    def gram(X: Array, weight: Array, Y: Array) -> Array:  # Σ_t Σ_j weight_j X_tjᵀ Y_tj
        return (X * weight[:, None]).reshape(-1, b).T @ Y.reshape(-1, b)

    A = gram(W, v, W)
    B = gram(W, v**2 * np.sum(rho**2, axis=0) / N, W)
    for lag in range(1, min(lags, N - 1) + 1):
        M = gram(W[lag:], v**2 * np.sum(rho[lag:] * rho[:-lag], axis=0) / N, W[:-lag])
        B += (1.0 - lag / (lags + 1.0)) * (M + M.T)
    Ainv = np.linalg.inv(A)
    return Ainv @ B @ Ainv * (N * n) / max(N * n - b, 1)


@dataclass(frozen=True, eq=False)
class Prediction:
    """Torques of one log (held-out part or a second log) after its own filtering: `t`, the measured `tau` and each
    model's predicted torque `predicted[name]`, (N, n)."""

    t: Array
    tau: Array
    predicted: dict[str, Array]
    source: str = ""

    @property
    def rms(self) -> dict[str, Array]:
        """RMS of the prediction error, per joint, of each model."""
        return {k: np.sqrt(np.mean((self.tau - v) ** 2, axis=0)) for k, v in self.predicted.items()}

    @property
    def tau_rms(self) -> Array:
        return np.sqrt(np.mean(self.tau**2, axis=0))

    @staticmethod
    def empty(n: int) -> Prediction:
        return Prediction(np.zeros(0), np.zeros((0, n)), {})


@dataclass(frozen=True, eq=False)
class Identification:
    """The result of :func:`identify`: base estimates (`ols`, `wls`, `consistent` as K φ_c), per-joint noise `sigma`,
    the WLS covariance (Newey–West) and relative standard deviations (%), the standard vectors `standard[name]`
    (consistent: the program's φ; the others by the prior's smallest change), the held-out part's and the validation
    log's torques and predictions, the condition number of the fit's W, the sample counts, the preprocessing as applied,
    the warnings, and each standard deviation over the textbook one (`inflation`: how much the filter's correlation
    of the kept samples widens it)."""

    basis: BaseParameters
    prior: Array
    base: dict[str, Array]
    standard: dict[str, Array]
    sigma: Array
    covariance: Array
    relative_std: Array
    holdout: Prediction
    condition_number: float
    fit_samples: int
    preprocessing: Settings
    validation: Prediction | None = None
    warnings: tuple[str, ...] = ()
    settings: dict[str, Any] = field(default_factory=dict)
    inflation: Array | None = None  # each base parameter's std over the textbook √((WᵀΣ⁻¹W)⁻¹)_jj (white samples)

    def consistency(self, name: str) -> float:
        """The smallest pseudo-inertia eigenvalue (or physical scalar) of `standard[name]`."""
        return float(np.min(smallest_eigenvalues(self.standard[name], parts(self.basis.model.param_names))))

    @property
    def holdout_t(self) -> Array:
        return self.holdout.t

    @property
    def holdout_tau(self) -> Array:
        return self.holdout.tau

    @property
    def holdout_prediction(self) -> dict[str, Array]:
        return self.holdout.predicted

    @property
    def holdout_rms(self) -> dict[str, Array]:
        """RMS of the held-out torque's prediction error, per joint, of each estimate and the prior."""
        return self.holdout.rms

    @property
    def validation_rms(self) -> dict[str, Array]:
        """RMS of the validation log's prediction error, per joint, of each estimate and the prior ({} without one)."""
        return {} if self.validation is None else self.validation.rms

    def as_dict(self) -> dict[str, Any]:
        names = self.basis.model.param_names
        out = {
            "param_names": list(names), "prior": self.prior.tolist(),
            "standard": {k: v.tolist() for k, v in self.standard.items()},
            "base_names": list(self.basis.names), "base": {k: v.tolist() for k, v in self.base.items()},
            "relative_std_percent": self.relative_std.tolist(), "sigma": self.sigma.tolist(),
            "holdout_rms": {k: v.tolist() for k, v in self.holdout_rms.items()},
            "holdout_tau_rms": self.holdout.tau_rms.tolist() if self.holdout.t.size else [],
            "min_pseudo_inertia_eigenvalue": {k: self.consistency(k) for k in self.standard},
            "condition_number": self.condition_number, "fit_samples": self.fit_samples,
            "holdout_samples": int(self.holdout.t.size), "preprocessing": self.preprocessing.as_dict(),
            "warnings": list(self.warnings), **self.settings,
        }
        if self.validation is not None:
            out.update({"validation": self.validation.source,
                        "validation_rms": {k: v.tolist() for k, v in self.validation.rms.items()},
                        "validation_tau_rms": self.validation.tau_rms.tolist(),
                        "validation_samples": int(self.validation.t.size)})
        return out


def _too_few(source: str, samples: int, n: int, b: int) -> ConfigError:
    return ConfigError("DATA", f"{source} gives {samples} fit samples × {n} joints = {samples * n} equations for {b} "
                       f"base parameters: at least {2 * b} are needed (log longer, decimate less, or hold out less)")


def no_cutoff_warning(data: JointData, settings: Settings) -> str | None:
    """The warning of a log without velocities identified without a low-pass (None when there is nothing to say)."""
    if settings.cutoff_source != "none" or data.dq is not None:
        return None
    return (f"--cutoff: none, and {data.source} has no velocities: q̇ and q̈ are Savitzky–Golay derivatives of unfiltered "
            "positions, so position noise enters W amplified (q̈ ∝ noise/dt²) and biases the estimate while the "
            "standard deviations look small; give --cutoff auto (the default) or --cutoff HZ")


def identify(model: RobotModel, data: JointData, pre: Preprocessing | None = None, holdout: float = 0.25,
             consistent: bool = True, epsilon: float = 1e-8, prior: Array | None = None,
             validation: JointData | None = None, divergence_weight: float = DIVERGENCE_WEIGHT) -> Identification:
    """Steps 0–5 of the module docstring for `model` on `data` (and, if given, a second log `validation` scored
    only); the prior φ₀ defaults to `model.default_phi` (zeros for a model without nominal values)."""
    pre = Preprocessing() if pre is None else pre
    holdout = as_scalar(holdout, "--holdout", nonnegative=True, maximum=0.9)
    if data.n != model.n:
        raise ConfigError("DATA", f"{data.source} has {data.n} joints, the robot {model.n}")
    if validation is not None and validation.n != model.n:
        raise ConfigError("--validate", f"{validation.source} has {validation.n} joints, the robot {model.n}")
    basis = base_parameters(model)
    prior = model.default_phi if prior is None else prior
    phi0 = np.zeros(model.p) if prior is None else np.asarray(prior, dtype=float)  # no nominal values: pull toward 0
    b = basis.count
    fit_raw, held_raw = split(data, holdout)
    if fit_raw.t.size * model.n < 2 * b or fit_raw.t.size < 2:
        raise _too_few(data.source, fit_raw.t.size, model.n, b)
    settings = pre.resolve(fit_raw, b)
    warnings = [w for w in (no_cutoff_warning(data, settings),) if w]
    fit = samples(basis, fit_raw, settings)
    W, tau = fit.W, fit.tau
    rows = W.shape[0] * W.shape[1]
    if rows < 2 * b or W.shape[0] < 2:
        raise _too_few(data.source, W.shape[0], model.n, b)
    cond = float(np.linalg.cond(W.reshape(rows, b)))
    if not np.isfinite(cond) or cond > 1e12:
        raise ConfigError("DATA", f"{data.source} does not excite the {b} base parameters (condition number of W "
                          f"{cond:.3g}): log an exciting trajectory (`robotadapt excite`)")
    ols = least_squares(W, tau)
    sigma = joint_noise(W, tau, ols)
    floor = 1e-12 * max(float(np.sqrt(np.mean(tau**2))), 1e-300)  # noise-free data: weights stay finite
    sigma_w = np.maximum(sigma, floor)
    wls = least_squares(W, tau, sigma_w)
    lags = settings.hac_lags if settings.cutoff is not None else int(4 * (W.shape[0] / 100) ** (2 / 9))
    covariance = hac_covariance(W, tau - W @ wls, sigma_w, lags)
    Ww = (W / sigma_w[:, None]).reshape(rows, b)
    textbook = np.linalg.inv(Ww.T @ Ww) * rows / max(rows - b, 1)
    inflation = np.sqrt(np.diag(covariance) / np.diag(textbook))
    with np.errstate(divide="ignore", invalid="ignore"):
        relative_std = 100.0 * np.sqrt(np.diag(covariance)) / np.abs(wls)
    K = basis.K
    pinv = np.linalg.pinv(K)
    base = {"ols": ols, "wls": wls}
    standard = {k: phi0 + pinv @ (v - K @ phi0) for k, v in base.items()}
    status = None
    if consistent:
        standard["consistent"], status = consistent_estimate(basis, W, tau, sigma_w, phi0, epsilon,
                                                             divergence_weight=divergence_weight)
        base["consistent"] = K @ standard["consistent"]
        if status != "optimal":
            warnings.append(f"--estimate: the semidefinite program ended {status} (Clarabel stopped short of its "
                            "tolerances); the consistent estimate is less precise")
    models = {**base, "prior": K @ phi0}
    nominal = model.default_phi
    if nominal is not None and not np.allclose(K @ nominal, K @ phi0, rtol=1e-12, atol=0.0):
        models["nominal"] = K @ np.asarray(nominal, dtype=float)
    held = Prediction.empty(model.n)
    if held_raw.t.size:
        try:
            part = samples(basis, held_raw, dataclasses.replace(settings, decimate=1), "--holdout")
            held = Prediction(part.t, part.tau, {k: part.W @ v for k, v in models.items()}, data.source)
        except ConfigError:
            warnings.append(f"--holdout: the held-out {held_raw.t[-1] - held_raw.t[0]:.3g} s of {data.source} are too "
                            f"short to score once filtered and trimmed by {settings.trim:.3g} s at each end; hold out "
                            "more, trim less (--trim) or score a second log (--validate)")
    scored = None
    if validation is not None:
        own = dataclasses.replace(settings, rate=1.0 / validation.dt, decimate=1)
        part = samples(basis, validation, own, "--validate")
        scored = Prediction(part.t, part.tau, {k: part.W @ v for k, v in models.items()}, validation.source)
    return Identification(basis, phi0, base, standard, sigma, covariance, relative_std, held, cond, int(W.shape[0]),
                          settings, scored, tuple(warnings),
                          {"holdout_fraction": holdout, "epsilon": epsilon, "prior_weight": PRIOR_WEIGHT,
                           "divergence_weight": divergence_weight,
                           "solver_status": status,
                           "covariance": {"method": "Newey-West (Bartlett weights)", "lags": lags,
                                          "std_over_textbook_median": float(np.median(inflation))}},
                          inflation)
