"""Persistency of excitation of a desired trajectory for a robot model (docs/laws.md#persistency-of-excitation,
(6.5.2); (6.6.18)).

Along the desired trajectory the regressor is Y_d(t) = Y(q_d, q̇_d, q̇_d, q̈_d) (`model.regressor`, shape `(n, p)`). The
trajectory is persistently exciting (PE) when every window of length ρ sweeps all p parameter directions:

    α I_p ≤ ∫_{t0}^{t0+ρ} Y_dᵀ Y_d dt ≤ β I_p   for all t0 ≥ 0,  α, β, ρ > 0                      (6.5.2)

:func:`excitation` evaluates the windowed Gram matrix on a grid of t0 over a finite horizon: α(t0) = λ_min and
β(t0) = λ_max of each window, and the eigenvector of the smallest eigenvalue in the weakest window (the parameter
combination the trajectory cannot identify). Verdict: PE iff min over t0 of α(t0) ≥ `rtol` · max over t0 of β(t0)
(`rtol` = 1e-6 by default: anything smaller is round-off or excitation that has died out).

It also evaluates the infinite-integral condition of composite adaptation (6.6.18), λ_min ∫_0^t Y_dᵀ Y_d dσ → ∞,
along the desired trajectory (W_f → f * Y_d as e → 0): the exponent k of λ_min ∝ t^k over the second half of the
horizon (k = 1 under PE; k = 0 when the integral levels off). It counts as growing when k ≥ 0.1.

For a model whose dynamics see fewer combinations than its p standard parameters (an n-DOF arm, p_b < p: see
:mod:`robotadapt.robots.identifiability`), no trajectory excites the p − p_b directions that no state does, so the
analysis is made in the base parameters φ_b = K φ (Y_b, the independent columns of Y): the rank is stated against p_b,
the names and the weakest direction are the base parameters', and `unidentifiable` counts the p − p_b directions lost
by construction (`base=False` keeps the standard parameters).

Quadrature: composite Simpson on a uniform grid of `INTERVALS_PER_WINDOW` sub-intervals per window, summed over blocks
of ρ/`WINDOWS_PER_PERIOD` (the t0 step), so each window is a sum of positive semidefinite block integrals: no
cancellation, and a rank-deficient window keeps λ_min at round-off relative to its own λ_max.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..robots.base import RobotModel
from ..trajectories import Trajectory
from ..validation import ConfigError, as_scalar

Array = np.ndarray
RTOL = 1e-6
INTERVALS_PER_WINDOW = 2048
WINDOWS_PER_PERIOD = 32  # t0 grid step = ρ / 32
GROWTH_EXPONENT = 0.1


def desired_regressor(model: RobotModel, trajectory: Trajectory, t: Array) -> Array:
    """Y_d(t) = Y(q_d, q̇_d, q̇_d, q̈_d) of (6.5.2), shape `t.shape + (n, p)`."""
    ref = trajectory(np.asarray(t, dtype=float))
    return model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)


def block_grams(model: RobotModel, trajectory: Trajectory, block: float, n_blocks: int, intervals: int) -> Array:
    """∫ Y_dᵀ Y_d dt over each of the consecutive intervals [j·block, (j+1)·block], j < `n_blocks`, by composite Simpson
    with `intervals` (even) sub-intervals each; shape `(n_blocks, p, p)`, each positive semidefinite."""
    h = block / intervals
    Y = desired_regressor(model, trajectory, h * np.arange(n_blocks * intervals + 1))
    w = np.ones(intervals + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    idx = intervals * np.arange(n_blocks)[:, None] + np.arange(intervals + 1)
    Yb = Y[idx]
    return np.einsum("jsni,s,jsnk->jik", Yb, (h / 3.0) * w, Yb, optimize=True)


@dataclass(frozen=True, eq=False)
class Excitation:
    """The windowed Gram analysis of one model and trajectory (see the module docstring).

    `t0, alpha, beta`: the window starts and λ_min, λ_max of each window (λ_min clipped at 0: a Gram matrix is positive
    semidefinite, negative values are round-off). `eigenvalues`, `weakest`: the spectrum and the unit eigenvector of
    λ_min in the weakest window, sign chosen so its largest entry is positive. `t_cum, lambda_min_cum, lambda_max_cum`:
    the extreme eigenvalues of ∫_0^t Y_dᵀ Y_d at the block ends. `standard_parameters` is the model's p and
    `param_names` the analysed parameters: its base parameters when it has fewer (then `unidentifiable` = p − p_b > 0).
    """

    param_names: tuple[str, ...]
    window: float
    window_source: str
    horizon: float
    rtol: float
    t0: Array
    alpha: Array
    beta: Array
    eigenvalues: Array
    weakest: Array
    t_cum: Array
    lambda_min_cum: Array
    lambda_max_cum: Array
    standard_parameters: int | None = None

    @property
    def unidentifiable(self) -> int:
        """p − p_b: the standard directions no trajectory can excite (0 when analysed in the standard parameters)."""
        return 0 if self.standard_parameters is None else self.standard_parameters - len(self.param_names)

    @property
    def alpha_min(self) -> float:
        """α = min over t0 of λ_min (the book's α of (6.5.2) over this horizon)."""
        return float(self.alpha.min())

    @property
    def beta_max(self) -> float:
        """β = max over t0 of λ_max."""
        return float(self.beta.max())

    @property
    def t0_worst(self) -> float:
        return float(self.t0[int(np.argmin(self.alpha))])

    @property
    def persistently_exciting(self) -> bool:
        return bool(self.beta_max > 0 and self.alpha_min >= self.rtol * self.beta_max)

    @property
    def rank(self) -> int:
        """Numerical rank of the weakest window: eigenvalues above `rtol` times the largest."""
        return int(np.sum(self.eigenvalues > self.rtol * max(float(self.eigenvalues[-1]), 0.0)))

    @property
    def weakest_direction(self) -> dict[str, float]:
        return {name: float(v) for name, v in zip(self.param_names, self.weakest, strict=True)}

    @property
    def growth_exponent(self) -> float:
        """k in λ_min ∫_0^t Y_dᵀY_d ∝ t^k between half the horizon and the horizon (0 when the integral is rank
        deficient at the end)."""
        last, top = float(self.lambda_min_cum[-1]), float(self.lambda_max_cum[-1])
        if not last > self.rtol * top:
            return 0.0
        half = int(np.searchsorted(self.t_cum, 0.5 * self.t_cum[-1]))
        first = float(self.lambda_min_cum[half])
        return float(np.log(last / first) / np.log(self.t_cum[-1] / self.t_cum[half]))

    @property
    def integral_grows(self) -> bool:
        """The infinite-integral condition (6.6.18) as far as the horizon shows: growth exponent ≥ 0.1."""
        return self.growth_exponent >= GROWTH_EXPONENT

    def as_dict(self) -> dict[str, Any]:
        """The verdict and its numbers, JSON-ready (no time series)."""
        return {
            "persistently_exciting": self.persistently_exciting,
            "alpha": self.alpha_min,
            "beta": self.beta_max,
            "window": self.window,
            "weakest_direction": self.weakest_direction,
            "window_source": self.window_source,
            "horizon": self.horizon,
            "t0_worst": self.t0_worst,
            "eigenvalues_worst": self.eigenvalues.tolist(),
            "rank_worst": self.rank,
            "threshold": self.rtol * self.beta_max,
            "rtol": self.rtol,
            "param_names": list(self.param_names),
            "parameters": "base" if self.unidentifiable else "standard",
            "standard_parameters": len(self.param_names) + self.unidentifiable,
            "unidentifiable_directions": self.unidentifiable,
            "infinite_integral": {"lambda_min_final": float(self.lambda_min_cum[-1]),
                                  "lambda_max_final": float(self.lambda_max_cum[-1]),
                                  "growth_exponent": self.growth_exponent, "grows": self.integral_grows},
        }

    def series(self) -> dict[str, list[float]]:
        """α(t0), β(t0) and the extreme eigenvalues of the growing integral, JSON-ready."""
        return {"t0": self.t0.tolist(), "alpha": self.alpha.tolist(), "beta": self.beta.tolist(),
                "t": self.t_cum.tolist(), "lambda_min_integral": self.lambda_min_cum.tolist(),
                "lambda_max_integral": self.lambda_max_cum.tolist()}


def default_window(trajectory: Trajectory, horizon: float) -> tuple[float, str]:
    """ρ = the trajectory's period when it is periodic, else a quarter of the horizon; with where it came from."""
    period = getattr(trajectory, "period", None)
    if period is not None:
        return float(period), "the trajectory's period"
    return horizon / 4.0, "a quarter of the horizon: the trajectory is not periodic"


def excitation(model: RobotModel, trajectory: Trajectory, horizon: float, window: float | None = None,
               rtol: float = RTOL, base: bool = True) -> Excitation:
    """Windowed Gram matrices ∫_{t0}^{t0+ρ} Y_dᵀ Y_d dt (6.5.2) for t0 = 0, ρ/32, … up to `horizon` − ρ, and the
    growing integral ∫_0^t Y_dᵀ Y_d (6.6.18) up to `horizon` (s). `window` ρ defaults to :func:`default_window`.
    With `base` (default), a model with unidentifiable directions is analysed in its base parameters (module doc)."""
    standard = None
    if base:
        from ..robots.identifiability import BaseParameterModel
        from .metrics import base_of

        basis = base_of(model)
        if basis is not None:
            model, standard = BaseParameterModel(basis), basis.K.shape[1]
    horizon = as_scalar(horizon, "horizon", positive=True)
    rtol = as_scalar(rtol, "rtol", positive=True, maximum=1.0)
    if window is None:
        window, source = default_window(trajectory, horizon)
    else:
        window, source = as_scalar(window, "window", positive=True), "given"
    if window > horizon * (1 + 1e-12):
        raise ConfigError("window", f"ρ = {window:g} s is longer than the horizon {horizon:g} s: shorten the window or "
                          "lengthen the horizon (--t-final)")
    block = window / WINDOWS_PER_PERIOD
    n_blocks = max(int(np.floor(horizon / block + 1e-9)), WINDOWS_PER_PERIOD)
    B = block_grams(model, trajectory, block, n_blocks, INTERVALS_PER_WINDOW // WINDOWS_PER_PERIOD)
    n_windows = n_blocks - WINDOWS_PER_PERIOD + 1
    W = sum(B[i : i + n_windows] for i in range(WINDOWS_PER_PERIOD))
    lam, vec = np.linalg.eigh(W)
    worst = int(np.argmin(lam[:, 0]))
    weakest = vec[worst, :, 0]
    weakest = weakest * np.sign(weakest[np.argmax(np.abs(weakest))])
    lam_cum = np.linalg.eigvalsh(np.cumsum(B, axis=0))
    return Excitation(
        param_names=tuple(model.param_names), window=float(window), window_source=source, horizon=float(horizon),
        rtol=rtol, t0=block * np.arange(n_windows), alpha=np.maximum(lam[:, 0], 0.0), beta=lam[:, -1],
        eigenvalues=np.maximum(lam[worst], 0.0), weakest=weakest, t_cum=block * np.arange(1, n_blocks + 1),
        lambda_min_cum=np.maximum(lam_cum[:, 0], 0.0), lambda_max_cum=lam_cum[:, -1], standard_parameters=standard)
