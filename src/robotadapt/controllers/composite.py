"""Composite adaptive controller of Slotine & Li (docs/laws.md#composite, Table 6.6.1): tracking error and prediction
error together."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace, matvec
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_gain, as_scalar, scalar_gain
from .base import Array, Law, errors, estimate, freeze, gains, slotine_li_products, slotine_li_regressor
from .registry import Contender


@dataclass(frozen=True, eq=False)
class Composite(Law):
    """Composite adaptive control (Table 6.6.1): the Slotine–Li torque with a least-squares update driven by both the
    tracking error r and the prediction error of the filtered torque.

    r = ė + Λe,   τ = Y(q, q̇, q̇_d + Λe, q̈_d + Λė) φ̂ + K_v r                   (6.3.8), (6.3.14)
    τ_f = f * τ,  f(s) = a/(s + a),  τ_f = W_f φ                                (6.6.5), (6.6.6), (6.6.11)
    τ̃_f = τ_f − W_f φ̂                                                          (6.6.15)
    dφ̂/dt = P (Yᵀ r + W_fᵀ τ̃_f)                                                (6.6.28)
    dP/dt = λ(t) P − P W_fᵀ W_f P,   P(0) = P0                                  (6.6.17) (+ forgetting)
    V = ½ rᵀ M r + ½ φ̃ᵀ P⁻¹ φ̃,  dV/dt = −rᵀ K_v r − ½ ‖W_f φ̃‖² − ½ λ φ̃ᵀ P⁻¹ φ̃   (6.6.29), (6.6.33)

    W_f needs no joint acceleration (docs/laws.md#composite): with the momentum regressor Y_h (Y_h φ = M q̇) and the remainder
    regressor Y_g (Y_g φ = −V_mᵀ q̇ + G + F), one filter state gives

    dZ3/dt = −a Z3 + a² Y_h − a Y_g,   Z3(0) = a Y_h(q(0), q̇(0)),   W_f = a Y_h − Z3,

    and the applied torque u (τ itself unless an actuator or a wrapper changes it, :meth:`applied`) is filtered as
    dτ_f/dt = −a τ_f + a u, τ_f(0) = 0.

    Forgetting (docs/laws.md#composite "Optional variants", Slotine & Li 1989): λ(t) = `forgetting` (λ0 ≥ 0, 0 = the
    book's pure
    least squares), or, with `k0`, the bounded-gain rule λ(t) = λ0 (1 − ‖P‖/k0), which keeps the spectral norm ‖P‖ ≤ k0.

    State x = [φ̂ (p), P (p×p, row-major), τ_f (n), Z3 (n×p, row-major)]. `a` > 0 is the filter pole (1/s); `P0` a
    symmetric positive definite p×p gain (scalar → k·I, list → diagonal, or a matrix); `Lam`, `Kv` as for Slotine–Li.
    """

    per_run: ClassVar[tuple[str, ...]] = ("phi_hat0",)  # varies per run in one vectorized batch

    kind = "composite"
    tuned = ("Lam", "Kv", "P0")
    family = "6"
    lineup = (Contender("composite", "composite (least squares)", "Table 6.6.1",
                        "Λ, K_v of Example 6.3.1; a = 1, P(0) = 10 I of Example 6.6.3",
                        {"kind": "composite", "Lam": 2.5, "Kv": 10.0, "a": 1.0, "P0": 10.0}, rank=70),)

    model: RobotModel
    Lam: Any
    Kv: Any
    a: Any
    P0: Any
    phi_hat0: Any
    forgetting: Any = 0.0
    k0: Any = None

    def __post_init__(self) -> None:
        gains(self, ("Lam", "Kv"), self.model.n)
        estimate(self)
        P0 = as_gain(self.P0, self.model.p, "controller.P0")
        freeze(self, a=scalar_gain(self.a, "controller.a"), P0=P0,
               forgetting=scalar_gain(self.forgetting, "controller.forgetting", nonnegative=True))
        if self.k0 is not None:
            k0 = as_scalar(self.k0, "controller.k0", positive=True)
            if self.forgetting == 0.0:
                raise ConfigError("controller.k0", "bounded-gain forgetting needs a forgetting factor > 0 "
                                  "(set controller.forgetting)")
            norm = float(np.linalg.eigvalsh(P0)[-1])
            if k0 < norm:
                raise ConfigError("controller.k0", f"must be at least ‖P0‖ = {norm:g}, got {k0:g}")
            freeze(self, k0=k0)

    def _split(self, x: Array) -> tuple[Array, Array, Array, Array]:
        """(φ̂, P, τ_f, Z3) from the flat state."""
        xp = array_namespace(x)
        n, p, lead = self.model.n, self.model.p, x.shape[:-1]
        P = xp.reshape(x[..., p : p + p * p], lead + (p, p))
        Z3 = xp.reshape(x[..., p + p * p + n :], lead + (n, p))
        return x[..., :p], P, x[..., p + p * p : p + p * p + n], Z3

    @property
    def state_names(self) -> tuple[str, ...]:
        names, n = self.model.param_names, self.model.n
        return (tuple(f"{name}_hat" for name in names) + tuple(f"P[{i},{j}]" for i in names for j in names)
                + tuple(f"tau_f{k + 1}" for k in range(n)) + tuple(f"Z3[{k + 1},{j}]" for k in range(n) for j in names))

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        """[φ̂(0), P0, τ_f(0) = 0, Z3(0) = a Y_h(q0, q̇0)]: W_f(0) = 0, so W_f φ = τ_f from the start."""
        xp = array_namespace(q0, dq0)
        Z3 = self.a * self.model.momentum_regressor(xp.asarray(q0, dtype=xp.float64), xp.asarray(dq0, dtype=xp.float64))
        return xp.concatenate([xp.asarray(self.phi_hat0), xp.asarray(self.P0.reshape(-1)), xp.zeros(self.model.n),
                               xp.reshape(Z3, (-1,))])

    def phi_hat(self, x: Array) -> Array:
        return x[..., : self.model.p]

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        e, de = errors(q, dq, ref)
        return de + e @ self.Lam.T

    def regressor(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        """(Y, r) with the Slotine–Li reference velocity q̇_d + Λe and acceleration q̈_d + Λė (6.3.11)."""
        return slotine_li_regressor(self.model, self.Lam, q, dq, ref)

    def regressor_products(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference,
                           phi: Array) -> tuple[Array, Array, Array]:
        """(Y φ, Yᵀ r, r) for :meth:`regressor`'s (Y, r)."""
        return slotine_li_products(self.model, self.Lam, q, dq, ref, phi)

    def filtered_regressor(self, x: Array, q: Array, dq: Array) -> Array:
        """W_f = a Y_h(q, q̇) − Z3, shape `(..., n, p)`, with W_f φ = f * τ (6.6.11)."""
        return self.a * self.model.momentum_regressor(q, dq) - self._split(x)[3]

    def forgetting_factor(self, P: Array) -> Array:
        """λ(t): λ0, or λ0 (1 − ‖P‖/k0) with the spectral norm ‖P‖ = λ_max(P) when `k0` is set; shape `P.shape[:-2]`."""
        if self.k0 is None:
            return self.forgetting + 0.0 * P[..., 0, 0]
        xp = array_namespace(P)
        return self.forgetting * (1.0 - xp.linalg.eigvalsh(P)[..., -1] / self.k0)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        xp = array_namespace(x, q, dq)
        phi_hat, P, tau_f, _ = self._split(x)
        Yphi, Ytr, r = self.regressor_products(t, x, q, dq, ref, phi_hat)
        tau = Yphi + r @ self.Kv.T
        Wf = self.filtered_regressor(x, q, dq)
        tau_err = tau_f - matvec(Wf, phi_hat)  # (6.6.15)
        dphi = matvec(P, Ytr + matvec(Wf.mT, tau_err))  # (6.6.28)
        WP = Wf @ P
        dP = self.forgetting_factor(P)[..., None, None] * P - WP.mT @ WP  # (6.6.17) with forgetting
        dP = 0.5 * (dP + dP.mT)
        dtau_f = self.a * (tau - tau_f)
        dZ3 = self.a * (Wf - self.model.remainder_regressor(q, dq))  # −a Z3 + a² Y_h − a Y_g
        lead = dP.shape[:-2]
        n, p = self.model.n, self.model.p
        dx = xp.concatenate([dphi, xp.reshape(dP, lead + (p * p,)), dtau_f, xp.reshape(dZ3, lead + (n * p,))], axis=-1)
        return tau, dx

    def applied(self, dx: Array, tau: Array, u: Array) -> Array:
        """dx/dt with dτ_f/dt = −a τ_f + a u for the torque u the plant receives (docs/laws.md#composite: the
        filtered torque is the
        applied one, so that τ_f − W_f φ̂ = W_f φ̃ (6.6.15) holds under torque limits, delays and added terms)."""
        xp = array_namespace(dx, u)
        k, n = self.model.p * (self.model.p + 1), self.model.n
        return xp.concatenate([dx[..., :k], dx[..., k : k + n] + self.a * (u - tau), dx[..., k + n :]], axis=-1)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """V of (6.6.29) with the true φ: ½ rᵀ M(q) r + ½ φ̃ᵀ P⁻¹ φ̃."""
        xp = array_namespace(x, q)
        phi_hat, P, _, _ = self._split(x)
        r = self.filtered_error(t, x, q, dq, ref)
        M = self.model.mass_matrix(q, phi)
        phi_err = phi - phi_hat
        P_inv_phi_err = xp.linalg.solve(P, phi_err[..., None])[..., 0]
        return 0.5 * (r * matvec(M, r)).sum(axis=-1) + 0.5 * (phi_err * P_inv_phi_err).sum(axis=-1)

    def lambda_min_P_inv(self, x: Array) -> Array:
        """λ_min(P⁻¹) = 1/λ_max(P): grows without bound exactly when the infinite-integral condition (6.6.18) holds
        (without forgetting, P⁻¹(t) = P0⁻¹ + ∫ W_fᵀ W_f, (6.6.25))."""
        xp = array_namespace(x)
        return 1.0 / xp.linalg.eigvalsh(self._split(x)[1])[..., -1]

    def monitors(self, x: Array, q: Array) -> dict[str, Array]:
        """`lambda_min_P_inv` (:meth:`lambda_min_P_inv`) at the logged states."""
        return {"lambda_min_P_inv": self.lambda_min_P_inv(x)}
