"""Adaptive computed-torque controller of Craig, Hsu & Sastry (docs/laws.md#adaptive-computed-torque, Table 6.2.1).

The update law needs the measured joint acceleration q̈ and the inverse of the estimated mass matrix M̂(q), so the
controller sets :attr:`~robotadapt.controllers.base.Law.needs_acceleration` (the simulator hands it the plant's q̈
for the torque it just applied; the torque itself does not need q̈). Where M̂ loses definiteness the update is NaN and
the loop, which reads the law's guard (:meth:`~robotadapt.controllers.base.Law.guard`), stops the run there. An optional box
projection of φ̂ keeps M̂ invertible (docs/laws.md#adaptive-computed-torque "Projection"). The equations are written
against the array API of their
inputs, so numpy and JAX run the same code.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace, matvec, quad, solve
from ..pytree import derived
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_gain, as_vector
from .base import Array, EstimateState, errors, freeze, gains, positive_definite
from .registry import Contender


@dataclass(frozen=True, eq=False)
class AdaptiveComputedTorque(EstimateState):
    """Adaptive computed torque (Table 6.2.1).

    τ = M̂(q)(q̈_d + K_v ė + K_p e) + V̂_m q̇ + Ĝ + F̂ = Y(q, q̇, q̇, q̈_d + K_v ė + K_p e) φ̂   (6.2.5)
    ẋ = A x + B M̂⁻¹ W φ̃,  x = [e; ė],  A = [[0, I], [−K_p, −K_v]],  B = [0; I]             (6.2.10)
    dφ̂/dt = Γ Wᵀ(q, q̇, q̈) M̂⁻¹(q) E1,  E1 = Bᵀ P x = P12ᵀ e + P22 ė                       (6.2.19)
    V = xᵀ P x + φ̃ᵀ Γ⁻¹ φ̃,  AᵀP + PA = −Q,  dV/dt = −xᵀ Q x                   (6.2.11), (6.2.16), (6.2.18)

    with W(q, q̇, q̈) = Y(q, q̇, q̇, q̈) the plain regressor (6.2.3). The controller state (called x in the code, not to
    be confused with the book's x = [e; ė]) is φ̂.

    Parameters
    ----------
    model : RobotModel
        The regressor's structure; its parameters are the estimate φ̂.
    Kp, Kv : scalar, list or (n, n) array
        Servo gains, symmetric positive definite (a scalar means k·I, a list a diagonal).
    Gamma : scalar, list or (p, p) array
        Adaptation gain Γ, symmetric positive definite.
    phi_hat0 : (p,) array
        Initial estimate φ̂(0).
    adaptation, gamma : "euclidean" (Γ, the book's) or "natural" with the scalar γ > 0
        The natural law: the same b = Wᵀ M̂⁻¹ E1 moves each link's pseudo-inertia by dĴ/dt = Ĵ B Ĵ / γ, and V's
        parameter term is 2γ Σ D(Jᵢ‖Ĵᵢ) (docs/natural.md); no box.
    phi_ref : (p,) array, optional
        With `adaptation = "pullback"` and γ: the constant pullback metric dĴᵢ/dt = P₀ᵢ Bᵢ P₀ᵢ / γ on the same b,
        P₀ᵢ = J(φ₀ᵢ) of this reference φ₀ (default φ̂(0); physically consistent), V's parameter term
        γ Σ tr(P₀ᵢ⁻¹ J̃ᵢ P₀ᵢ⁻¹ J̃ᵢ); state φ̂, no box (its Γ is not diagonal).
    Q, P : (2n, 2n) array, optional
        The Lyapunov pair of (6.2.16); give at most one. From `Q`, P solves AᵀP + PA = −Q; a given `P` must make
        Q = −(AᵀP + PA) positive definite. With neither, scalar gains K_p = k_p I, K_v = k_v I take the book's
        P = [[(k_p + k_v/2) I, ½ I], [½ I, I]] (Example 6.2.2; then Q = diag(k_p I, (2k_v − 1) I), which needs
        k_v > ½, docs/laws.md#adaptive-computed-torque) and other gains Q = I. `lyapunov_pair` gives the (P, Q) in use.
    phi_min, phi_max : scalar or (p,) array, optional
        A box for φ̂ (None: unbounded; `bounds` gives the box with ∓∞). Components of dφ̂/dt that point out of the box
        at (or beyond) a bound are set to zero, `project` clips the state after each fixed step, and the estimate in
        use is the state clipped into the box (an RK4 stage may step out of it). With a diagonal Γ and the true φ in
        the box this keeps dV/dt ≤ −xᵀ Q x. Positive lower masses keep M̂ positive definite for the two-link arm
        (det M̂ = m̂2 l1² l2² (m̂1 + m̂2 s2²)) and the polar arm (M̂ = diag(m̂ r², m̂), r ≠ 0).
    """

    per_run: ClassVar[tuple[str, ...]] = ("phi_hat0",)  # varies per run in one vectorized batch

    needs_acceleration: ClassVar[bool] = True  # the update reads the measured q̈ (6.2.19)

    kind = "adaptive_computed_torque"
    tuned = ("Kp", "Kv", "Gamma")
    #: Γ of (6.2.19) carries M̂⁻¹, the box is φ's; K_p, K_v act through M̂ (6.2.5): rates, whatever the arm's scale
    powers = MappingProxyType({"Gamma": 2, "phi_min": 1, "phi_max": 1})
    lineup = (Contender("adaptive_computed_torque", "adaptive computed torque + projection", "Table 6.2.1",
                        "Example 6.2.2; box [0.1, 10] (docs: laws.md#adaptive-computed-torque)",
                        {"kind": "adaptive_computed_torque", "Kp": 125.0, "Kv": 50.0, "Gamma": 500.0, "phi_min": 0.1,
                         "phi_max": 10.0}, rank=50),)

    model: RobotModel
    Kp: Any
    Kv: Any
    Gamma: Any = None
    phi_hat0: Any = None
    Q: Any = None
    P: Any = None
    phi_min: Any = None
    phi_max: Any = None
    adaptation: str = "euclidean"
    gamma: Any = None
    phi_ref: Any = None
    book_pair: bool = field(init=False, default=False)  # (6.2.16)'s pair in the book's closed form (__post_init__)

    def __post_init__(self) -> None:
        n, p = self.model.n, self.model.p
        gains(self, ("Kp", "Kv"), n)
        self.adapts()
        if self.adaptation in ("natural", "pullback") and (self.phi_min is not None or self.phi_max is not None):
            why = ("the natural law keeps φ̂ a real body itself" if self.adaptation == "natural" else
                   "the pullback metric's Γ is not diagonal, and the box keeps dV/dt ≤ −xᵀQx for a diagonal Γ only")
            raise ConfigError("controller.phi_min", f"{why}; remove the box phi_min/phi_max, or use adaptation = "
                              "\"euclidean\"")
        if self.P is not None and self.Q is not None:
            raise ConfigError("controller.P", "give either P or Q (P is then solved from AᵀP + PA = −Q), not both")
        given = {k: getattr(self, k) for k in ("P", "Q", "phi_min", "phi_max") if getattr(self, k) is not None}
        freeze(self, **{k: as_gain(v, 2 * n, f"controller.{k}") if k in ("P", "Q") else as_vector(v, p, f"controller.{k}")
                        for k, v in given.items()})
        # which pair (6.2.16) takes: the book's closed form for scalar gains with neither P nor Q given; decided here,
        # on the gains as given, and kept when tuning puts in traced gains of the same form
        object.__setattr__(self, "book_pair", self.P is None and self.Q is None and _is_scalar(self.Kp)
                           and _is_scalar(self.Kv))
        # The fields keep what was given, so `dataclasses.replace` works; the derived constants are cached properties,
        # evaluated now so that bad input fails at construction.
        _ = self.lyapunov_pair, self.bounds

    @derived
    def lyapunov_pair(self) -> tuple[Array, Array]:
        """(P, Q) with AᵀP + PA = −Q, both symmetric positive definite (6.2.16): written with the namespace of the gains,
        so that a traced K_p, K_v or Q (tuning, :mod:`robotadapt.studies.gain_space`) gives a traced P; the checks run
        on concrete gains (at construction)."""
        n, xp = self.model.n, array_namespace(self.Kp, self.Kv, *[m for m in (self.P, self.Q) if m is not None])
        eye, concrete = xp.eye(n), xp is np
        A = xp.concatenate([xp.concatenate([0 * eye, eye], axis=1), xp.concatenate([-self.Kp, -self.Kv], axis=1)])
        if self.P is not None:
            Q = -(A.T @ self.P + self.P @ A)  # (6.2.10)
            if concrete:
                _check_pd(Q, "controller.P", "Q = −(AᵀP + PA) must be positive definite for these Kp, Kv; give "
                          "controller.Q instead to solve for P")
            return self.P, Q
        if self.book_pair:
            kp, kv = self.Kp[0, 0], self.Kv[0, 0]
            if concrete and not kv > 0.5:
                raise ConfigError("controller.Kv", f"the book's default P needs k_v > 1/2 (Q = diag(k_p I, (2k_v − 1) "
                                  f"I)), got {kv:g}; give controller.Q or controller.P")
            P = xp.concatenate([xp.concatenate([(kp + kv / 2) * eye, 0.5 * eye], axis=1),
                                xp.concatenate([0.5 * eye, eye], axis=1)])
            return P, xp.concatenate([xp.concatenate([kp * eye, 0 * eye], axis=1),
                                      xp.concatenate([0 * eye, (2 * kv - 1) * eye], axis=1)])
        Q = xp.eye(2 * n) if self.Q is None else self.Q
        P = lyapunov(xp, A, Q)
        if concrete:
            _check_pd(P, "controller.Q", "the solution P of AᵀP + PA = −Q is not positive definite to working "
                      "precision (badly scaled Kp, Kv?)")
        return P, Q

    @derived
    def bounds(self) -> tuple[Array, Array]:
        """(lower, upper) ends of the box for φ̂, −∞ / +∞ where not given."""
        p = self.model.p
        lo = np.full(p, -np.inf) if self.phi_min is None else self.phi_min
        hi = np.full(p, np.inf) if self.phi_max is None else self.phi_max
        if not np.all(lo < hi):
            raise ConfigError("controller.phi_max", f"must exceed controller.phi_min entry by entry, got {hi} ≤ {lo}")
        if not np.all((lo <= self.phi_hat0) & (self.phi_hat0 <= hi)):
            raise ConfigError("controller.phi_hat0", f"must lie in the box [phi_min, phi_max] = [{lo}, {hi}]")
        return lo, hi

    @derived
    def _BtP(self) -> Array:
        """Bᵀ P = [P12ᵀ, P22], shape (n, 2n)."""
        return self.lyapunov_pair[0][self.model.n :, :]

    def phi_hat(self, x: Array) -> Array:
        """φ̂: the state clipped into the box (the state itself without bounds); the natural law's estimate."""
        if self.adaptation == "natural":
            return self.geometry.estimate(x)
        return array_namespace(x).clip(x, *self.bounds)

    def project(self, x: Array) -> Array:
        """Clip the state into the box after each fixed step (the natural law's state needs none)."""
        return x if self.adaptation == "natural" else self.phi_hat(x)

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """E1 = Bᵀ P [e; ė] = P12ᵀ e + P22 ė (6.2.19); ½ e + ė with the book's P."""
        return array_namespace(q).concatenate(errors(q, dq, ref), axis=-1) @ self._BtP.T

    def torque(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """τ = Y(q, q̇, q̇, q̈_d + K_v ė + K_p e) φ̂ (6.2.5)."""
        e, de = errors(q, dq, ref)
        return matvec(self.model.regressor(q, dq, dq, ref.ddq_des + de @ self.Kv.T + e @ self.Kp.T), self.phi_hat(x))

    def guard(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """M̂(q) positive definite, per run: what the update (6.2.19) needs (the law's guard)."""
        return positive_definite(array_namespace(x, q), self.model.mass_matrix(q, self.phi_hat(x)))

    def update(self, t: Array, x: Array, q: Array, dq: Array, ddq: Array, ref: Reference) -> Array:
        """dφ̂/dt = Γ Wᵀ M̂⁻¹ E1 (6.2.19), zero where it points out of the box; NaN where M̂(q) is not positive definite
        (the loop reads `guard` and stops the run there, with `stop_reason`)."""
        xp = array_namespace(x, q)
        phi_hat = self.phi_hat(x)
        M_hat = self.model.mass_matrix(q, phi_hat)
        ok = positive_definite(xp, M_hat)
        M_hat = xp.where(ok[..., None, None], M_hat, xp.eye(self.model.n))  # solve would raise on a singular M̂
        W = self.model.regressor(q, dq, dq, ddq)
        dx = self.geometry.rate(x, matvec(W.mT, solve(xp, M_hat, self.filtered_error(t, x, q, dq, ref))))
        if self.adaptation == "euclidean":
            lo, hi = self.bounds
            dx = xp.where(((x <= lo) & (dx < 0)) | ((x >= hi) & (dx > 0)), 0.0, dx)
        return xp.where(ok[..., None], dx, xp.nan)

    def stop_reason(self, q: Array, x: Array) -> str:
        """Why a run stops at a state whose M̂(q) is not positive definite (the law's guard)."""
        phi_hat = self.phi_hat(np.asarray(x))
        return _not_pd(self.model.mass_matrix(np.asarray(q), phi_hat), phi_hat)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """V = xᵀ P x + φ̃ᵀ Γ⁻¹ φ̃ (6.2.11) with x = [e; ė] and the true φ; twice the geometry's parameter term, so the
        natural law's is 2γ Σ D(Jᵢ‖Ĵᵢ)."""
        P = self.lyapunov_pair[0]
        e = array_namespace(q).concatenate(errors(q, dq, ref), axis=-1)
        return quad(e, P) + 2 * self.geometry.lyapunov(self.phi_hat(x) if self.adaptation == "euclidean" else x, phi)


def _check_pd(S: Array, field: str, what: str) -> None:
    low = np.linalg.eigvalsh(S).min() if np.all(np.isfinite(S)) else np.nan
    if not low > 0:
        raise ConfigError(field, f"{what} (smallest eigenvalue {low:.3g})")


def lyapunov(xp: Any, A: Array, Q: Array) -> Array:
    """P with AᵀP + PA = −Q (6.2.16), by the Kronecker form (Aᵀ ⊗ I + I ⊗ Aᵀ) vec P = −vec Q: one dense solve of
    (2n)² unknowns, traceable and differentiable (a 7-joint arm: 196), symmetrised."""
    m = A.shape[0]
    eye = xp.eye(m)
    K = xp.kron(A.T, eye) + xp.kron(eye, A.T)
    P = xp.reshape(xp.linalg.solve(K, -xp.reshape(Q, (m * m,))), (m, m))
    return 0.5 * (P + P.T)


def _is_scalar(K: Array) -> bool:
    return bool(np.array_equal(K, K[0, 0] * np.eye(len(K))))


def _not_pd(M_hat: Array, phi_hat: Array) -> str:
    """The stop message, naming the estimate whose M̂(q) is furthest from positive definite."""
    low = np.linalg.eigvalsh(M_hat).min(axis=-1)
    worst = np.broadcast_to(phi_hat, low.shape + phi_hat.shape[-1:]).reshape(-1, phi_hat.shape[-1])[np.argmin(low)]
    estimate = np.array2string(worst, precision=4)
    return (f"the estimated mass matrix M̂(q) is no longer positive definite (φ̂ = {estimate} where it failed);"
            " set controller.phi_min/phi_max to project the estimate")
