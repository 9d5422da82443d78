"""Adaptive inertia-related controller of Slotine & Li (docs/laws.md#slotine-li, Table 6.3.1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from ..arrays import matvec
from ..robots.base import RobotModel
from ..trajectories import Reference
from .base import Array, EstimateState, errors, gains, slotine_li_products, slotine_li_regressor
from .registry import Contender


@dataclass(frozen=True, eq=False)
class InertiaRelated(EstimateState):
    """Slotine–Li: the adaptive inertia-related controller (Table 6.3.1).

    r = ė + Λe                                         (6.3.8)
    τ = Y(q, q̇, q̇_d + Λe, q̈_d + Λė) φ̂ + K_v r       (6.3.11), (6.3.14)
    dφ̂/dt = Γ Yᵀ r                                    (6.3.16)
    V = ½ rᵀ M(q) r + ½ φ̃ᵀ Γ⁻¹ φ̃,  dV/dt = −rᵀ K_v r  (6.3.7), (6.3.17)

    No joint acceleration and no inverse of M̂ are needed. State x = φ̂. Gains: a scalar (k·I), a list (diagonal) or a
    symmetric positive definite matrix. With `adaptation = "natural"` and the scalar `gamma`, the update is the natural
    adaptive law dĴᵢ/dt = Ĵᵢ Bᵢ Ĵᵢ / γ on b = Yᵀr and V's parameter term γ Σ D(Jᵢ‖Ĵᵢ) (docs/natural.md): the same dV/dt.
    With `adaptation = "pullback"`, `gamma` and `phi_ref` (φ₀, default φ̂(0)): the constant pullback metric
    dĴᵢ/dt = P₀ᵢ Bᵢ P₀ᵢ / γ, P₀ᵢ = J(φ₀ᵢ), with V's parameter term (γ/2) Σ tr(P₀ᵢ⁻¹ J̃ᵢ P₀ᵢ⁻¹ J̃ᵢ): the same dV/dt.
    """

    per_run: ClassVar[tuple[str, ...]] = ("Lam", "Kv", "Gamma", "phi_hat0")  # varies per run in one vectorized batch

    kind = "slotine_li"
    aliases = ("inertia_related",)  # the book's name, Table 6.3.1
    tuned = ("Lam", "Kv", "Gamma")
    family = "6"
    lineup = (Contender("slotine_li", "Slotine–Li", "Table 6.3.1", "Example 6.3.1",
                        {"kind": "slotine_li", "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}, rank=10, book_kv="Example 6.3.1"),)

    model: RobotModel
    Lam: Any
    Kv: Any
    Gamma: Any = None
    phi_hat0: Any = None
    adaptation: str = "euclidean"
    gamma: Any = None
    phi_ref: Any = None

    def __post_init__(self) -> None:
        gains(self, ("Lam", "Kv"), self.model.n)
        self.adapts()

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        e, de = errors(q, dq, ref)
        return de + matvec(self.Lam, e)

    def regressor(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        """(Y, r) with the Slotine–Li reference velocity q̇_d + Λe and acceleration q̈_d + Λė (6.3.11)."""
        return slotine_li_regressor(self.model, self.Lam, q, dq, ref)

    def regressor_products(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference,
                           phi: Array) -> tuple[Array, Array, Array]:
        """(Y φ, Yᵀ r, r) for :meth:`regressor`'s (Y, r)."""
        return slotine_li_products(self.model, self.Lam, q, dq, ref, phi)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        Yphi, Ytr, r = self.regressor_products(t, x, q, dq, ref, self.phi_hat(x))
        return Yphi + matvec(self.Kv, r), self.geometry.rate(x, Ytr)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """V of (6.3.7) with the true φ (its parameter term the geometry's)."""
        r = self.filtered_error(t, x, q, dq, ref)
        M = self.model.mass_matrix(q, phi)
        return 0.5 * (r * matvec(M, r)).sum(axis=-1) + self.geometry.lyapunov(x, phi)
