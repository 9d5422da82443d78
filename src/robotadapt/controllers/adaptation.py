"""Parameter update laws as parts a controller composes (docs/laws.md#gradient, docs/laws.md#landau-pi,
docs/laws.md#sigma-modification).

A law sees the passivity output y = Zᵀ r of its controller (Z the regressor, r the filtered error) and keeps its own
state `xa` (shape `(..., state_size)`):

    φ̂ = law.estimate(xa, y),   dxa/dt = law.derivative(xa, y)

`lyapunov(xa, phi)` is the parameter part of the controller's Lyapunov function (with the true φ, for monitors only).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar, Protocol

import numpy as np

from ..arrays import array_namespace, quad
from ..pytree import Module, derived
from ..validation import as_gain, scalar_gain
from .base import inverse
from .registry import Registered

Array = Any


class UpdateLaw(Protocol):
    """An update law of the passivity class (Table 6.4.1) driven by y = Zᵀr; `p` is the number of parameters."""

    p: int

    @property
    def state_size(self) -> int:
        """Length of the law's state x_a (p: φ̂ for the gradient and σ laws, φ̂_I for Landau's PI law)."""

    def state_names(self, param_names: tuple[str, ...]) -> tuple[str, ...]:
        """Names of the entries of x_a, from the model's parameter names: what the state holds (φ̂ or φ̂_I)."""

    def passivity_caveat(self) -> str | None:
        """Why the passivity claim (6.4.4) is not implied for this law and its gains, or None where it is."""

    def initial_state(self, phi_hat0: Array) -> Array:
        """x_a(0) for the initial estimate φ̂(0)."""

    def estimate(self, xa: Array, y: Array) -> Array:
        """φ̂ from the state and y = Zᵀr (Landau's proportional term (6.4.20) uses y)."""

    def derivative(self, xa: Array, y: Array) -> Array:
        """dx_a/dt: Γ y for the gradient law (Example 6.4.1), (6.4.21) for Landau's law, (6.7.13) with leakage."""

    def lyapunov(self, xa: Array, phi: Array) -> Array:
        """The parameter part of the controller's Lyapunov function for the true φ (monitors only)."""


class EstimateLaw(Registered, Module):
    """The state of a law that keeps one vector of p parameters (φ̂ or φ̂_I), starting at φ̂(0): a mixin of the laws'
    dataclasses, which hold `p`. A law that names its `kind` is a kind of `[controller.law]`
    (:mod:`robotadapt.controllers.registry`)."""

    registry: ClassVar[str] = "law"
    first: ClassVar[str | None] = "p"

    p: int

    @property
    def state_size(self) -> int:
        return self.p

    def initial_state(self, phi_hat0: Array) -> Array:
        return np.array(phi_hat0, dtype=float)

    def state_names(self, param_names: tuple[str, ...]) -> tuple[str, ...]:
        """`m1_hat`, …: the state is φ̂ itself (gradient and σ laws)."""
        return tuple(f"{name}_hat" for name in param_names)

    def passivity_caveat(self) -> str | None:
        """Why the passivity claim (6.4.4) is not implied for this law and its gains, or None where it is."""
        return None


@dataclass(frozen=True, eq=False)
class Gradient(EstimateLaw):
    """Gradient law of Example 6.4.1: dφ̂/dt = Γ Zᵀ r. Passive with β = ½ φ̃(0)ᵀ Γ⁻¹ φ̃(0) (docs/laws.md#gradient)."""

    kind = "gradient"
    tuned = ("Gamma",)

    p: int
    Gamma: Any
    def __post_init__(self) -> None:
        object.__setattr__(self, "Gamma", as_gain(self.Gamma, self.p, "controller.law.Gamma"))

    @derived
    def _Gamma_inv(self) -> Array:
        return inverse(self.Gamma)

    def estimate(self, xa: Array, y: Array) -> Array:
        return xa

    def derivative(self, xa: Array, y: Array) -> Array:
        return y @ self.Gamma.T

    def lyapunov(self, xa: Array, phi: Array) -> Array:
        """½ φ̃ᵀ Γ⁻¹ φ̃ (6.3.7)."""
        return 0.5 * quad(phi - xa, self._Gamma_inv)


@dataclass(frozen=True, eq=False)
class LandauPI(EstimateLaw):
    """Landau's PI adaptation, (6.4.20) with F_I(t) = K_I (6.4.21):

    φ̂ = φ̂_I + F_p Zᵀ r,   dφ̂_I/dt = K_I Zᵀ r,   φ̂_I(0) = φ̂(0).

    State φ̂_I. Passive: ∫ −rᵀ Z φ̃ ≥ −½ φ̃_I(0)ᵀ K_I⁻¹ φ̃_I(0) (docs/laws.md#landau-pi). F_p = 0 is the gradient law.
    """

    kind = "landau_pi"
    tuned = ("K_I", "F_p")

    p: int
    K_I: Any
    F_p: Any
    def __post_init__(self) -> None:
        object.__setattr__(self, "K_I", as_gain(self.K_I, self.p, "controller.law.K_I"))
        object.__setattr__(self, "F_p", as_gain(self.F_p, self.p, "controller.law.F_p", semidefinite=True))

    @derived
    def _K_I_inv(self) -> Array:
        return inverse(self.K_I)

    def state_names(self, param_names: tuple[str, ...]) -> tuple[str, ...]:
        """`m1_hat_I`, …: the state is the integral part φ̂_I of (6.4.20)–(6.4.21), not the φ̂ the torque uses."""
        return tuple(f"{name}_hat_I" for name in param_names)

    def estimate(self, xa: Array, y: Array) -> Array:
        return xa + y @ self.F_p.T

    def derivative(self, xa: Array, y: Array) -> Array:
        return y @ self.K_I.T

    def lyapunov(self, xa: Array, phi: Array) -> Array:
        """½ φ̃_Iᵀ K_I⁻¹ φ̃_I: with ½ rᵀ M r its derivative is −rᵀ K_v r − yᵀ F_p y ≤ 0."""
        return 0.5 * quad(phi - xa, self._K_I_inv)


@dataclass(frozen=True, eq=False)
class SwitchingSigma(Gradient):
    """Switching σ-modification of Reed & Ioannou (6.7.13)–(6.7.14):

    dφ̂/dt = Γ Zᵀ r − σ_s S φ̂,   σ_s = σ0 · clip(‖φ̂‖/φ0 − 1, 0, 1)

    with S = I (the book's form, σ0 = 1) or S = Γ (`scaled = true`, Ioannou's form). φ0 > ‖φ‖ is an a-priori bound on
    the true parameters (6.7.15). The leakage keeps φ̂ bounded under disturbances; the tracking error then only enters a
    residual set (docs/laws.md#sigma-modification). The gradient law with a leak: its state, estimate and V are the
    gradient law's (½ φ̃ᵀ Γ⁻¹ φ̃).
    """

    kind = "sigma"

    phi0: Any
    sigma0: Any = 1.0
    scaled: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "phi0", scalar_gain(self.phi0, "controller.law.phi0"))
        object.__setattr__(self, "sigma0", scalar_gain(self.sigma0, "controller.law.sigma0"))

    def sigma(self, xa: Array) -> Array:
        """σ_s of (6.7.14): 0 inside ‖φ̂‖ < φ0, a linear ramp to σ0 at 2φ0, σ0 beyond."""
        xp = array_namespace(xa)
        norm = xp.sqrt((xa * xa).sum(axis=-1))
        return self.sigma0 * xp.clip(norm / self.phi0 - 1.0, 0.0, 1.0)

    def surrogate(self, width: float) -> SmoothedSigma:
        """The smooth law tuning differentiates in place of this one (docs/tuning.md#switching-laws): the ramp's kinks
        and ‖φ̂‖ at 0 rounded over `width`, continued toward the exact law as width → 0."""
        return SmoothedSigma(**{f.name: getattr(self, f.name) for f in fields(SwitchingSigma)}, width=width)

    def passivity_caveat(self) -> str | None:
        """With S = I, dV_φ/dt = −rᵀZφ̃ + σ_s φ̃ᵀΓ⁻¹φ̂, and φ̃ᵀΓ⁻¹φ̂ ≤ 0 whenever ‖φ̂‖ > ‖φ‖ only for Γ = γI
        (Cauchy–Schwarz); for another Γ the leak can add to V_φ (Γ = diag(100, 1), φ̂ = (3, 1): +0.327)."""
        G = np.asarray(self.Gamma)
        if self.scaled or np.allclose(G, G[0, 0] * np.eye(G.shape[0]), rtol=1e-12, atol=0.0):
            return None
        return ("the leak σ_s φ̂ with S = I and a Γ that is not γI can increase V_φ = ½φ̃ᵀΓ⁻¹φ̃, so (6.4.4) is not "
                "implied; use scaled = true (S = Γ) or a scalar Γ")

    def derivative(self, xa: Array, y: Array) -> Array:
        leak = xa @ self.Gamma.T if self.scaled else xa
        return y @ self.Gamma.T - self.sigma(xa)[..., None] * leak


@dataclass(frozen=True, eq=False)
class SmoothedSigma(SwitchingSigma):
    """:class:`SwitchingSigma` with σ_s of (6.7.14) made smooth for tuning's gradients: ‖φ̂‖ ≈ √(‖φ̂‖² + w²φ0²) (smooth
    at φ̂ = 0, where the fair comparison starts) and clip(u, 0, 1) ≈ w·[softplus(u/w) − softplus((u − 1)/w)], both exact
    as the width w → 0 (w traced, > 0)."""

    width: Any = 1.0

    def sigma(self, xa: Array) -> Array:
        xp = array_namespace(xa)
        w = self.width
        u = xp.sqrt((xa * xa).sum(axis=-1) + (w * self.phi0) ** 2) / self.phi0 - 1.0
        return self.sigma0 * w * (xp.logaddexp(0.0, u / w) - xp.logaddexp(0.0, (u - 1.0) / w))
