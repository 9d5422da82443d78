"""How a law that adapts φ̂ moves it (docs/natural.md): the book's Euclidean gradient, the natural adaptive law on
the manifold of pseudo-inertias (Lee, Kwon & Park, IROS 2018), or that law's metric frozen at a reference (their
constant pullback metric).

A law computes b, the vector its proof pairs with the estimation error (Yᵀr for Slotine–Li (6.3.16), Wᵀ M̂⁻¹ E1 for
adaptive computed torque (6.2.19), Y_dᵀ r for DCAL (7.2.7)), so that dV/dt holds the cross term −φ̃ᵀb with φ̃ = φ − φ̂.
A geometry turns b into the law's state derivative and holds the parameter term of V whose derivative cancels it:

- :class:`Euclidean`: x = φ̂, dφ̂/dt = Γ b, V_φ = ½ φ̃ᵀ Γ⁻¹ φ̃ (the book's laws);
- :class:`Natural`: dĴᵢ/dt = Ĵᵢ Bᵢ Ĵᵢ / γ per link, with Bᵢ the symmetric 4×4 matrix of tr(J(v) Bᵢ) = vᵀbᵢ, and
  dθ̂/dt = θ̂² b / γ for a positive scalar (mass, rotor inertia, friction); V_φ = γ Σᵢ D(Jᵢ‖Ĵᵢ) with the log-det
  divergence D(P‖Q) = log(|Q|/|P|) + tr(Q⁻¹P) − 4 (1-D: log(q/p) + p/q − 1). Its state holds each link's log-Cholesky
  factor of Ĵᵢ (the log of its diagonal, then the entries below it) and the log of each scalar, so every state is a
  physically consistent φ̂, and `step` is the exponential map Ĵ⁺ = L exp(h Lᵀ B L / γ) Lᵀ (Ĵ = L Lᵀ): a sampled-data
  tick cannot leave the set.
- :class:`Pullback`: the paper's constant pullback metric, the natural metric frozen at a fixed reference φ₀ with
  pseudo-inertias P₀ᵢ = J(φ₀ᵢ) ≻ 0: dĴᵢ/dt = P₀ᵢ Bᵢ P₀ᵢ / γ per link and dθ̂/dt = θ₀² b / γ per scalar, with state
  x = φ̂. Linear in b, it is the Euclidean law for the block-diagonal Γ_P of b ↦ P₀ B P₀ / γ (symmetric positive
  definite), so V_φ = ½ φ̃ᵀ Γ_P⁻¹ φ̃ = (γ/2) Σᵢ tr(P₀ᵢ⁻¹ J̃ᵢ P₀ᵢ⁻¹ J̃ᵢ) + (γ/2) Σ θ̃²/θ₀²: the natural law's γ D(J‖Ĵ)
  to second order at Ĵ = P₀. It does not keep Ĵ ≻ 0 by itself; its `step` is x + h·dx.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import array_namespace, expm, matvec, quad
from ..pytree import Module, derived
from ..robots.consistency import DUAL, Part, link_parameters, parts, pseudo_inertia, unformed
from ..validation import ConfigError, as_gain, as_vector, scalar_gain

Array = Any
ADAPTATIONS = ("euclidean", "natural", "pullback", "none")
# the 10 log-Cholesky coordinates of a link: log L_jj (j = 0…3), then L_ij below the diagonal, row by row
_ROWS, _COLS = (np.array(v) for v in ([0, 1, 2, 3, 1, 2, 2, 3, 3, 3], [0, 1, 2, 3, 0, 0, 1, 0, 1, 2]))
_UNIT = np.zeros((10, 4, 4))
_UNIT[np.arange(10), _ROWS, _COLS] = 1.0
_LOWER_HALF = np.tril(np.ones((4, 4)), -1) + 0.5 * np.eye(4)  # Φ(S): the part of S below the diagonal and half of it


class Direct(Module):
    """A geometry whose state is φ̂ itself (x = φ̂), stepped x + h·dx: the Euclidean and the pullback law."""

    def state_names(self, param_names: tuple[str, ...]) -> tuple[str, ...]:
        return tuple(f"{name}_hat" for name in param_names)

    def initial_state(self, phi_hat0: Array) -> Array:
        return np.array(phi_hat0, dtype=float)

    def estimate(self, x: Array) -> Array:
        return x

    def step(self, x: Array, dx: Array, h: Any) -> Array:
        return x + h * dx


@dataclass(frozen=True, eq=False)
class Euclidean(Direct):
    """The book's update dφ̂/dt = Γ b with state x = φ̂; V_φ = ½ φ̃ᵀ Γ⁻¹ φ̃ (6.3.7)."""

    Gamma: Array

    @derived
    def _Gamma_inv(self) -> Array:
        return None if self.Gamma is None else array_namespace(self.Gamma).linalg.inv(self.Gamma)  # Frozen: none


    def rate(self, x: Array, b: Array) -> Array:
        return matvec(self.Gamma, b)  # Γ may carry a runs axis (a batch of gains)

    def lyapunov(self, x: Array, phi: Array) -> Array:
        return 0.5 * quad(phi - x, self._Gamma_inv)


@dataclass(frozen=True, eq=False)
class Frozen(Euclidean):
    """No adaptation (`adaptation = "none"`): φ̂ stays φ̂(0), the baseline of an adaptation study. V then has no
    parameter term, and ½ rᵀ M r is no Lyapunov function of the loop (Y φ̃ drives it)."""

    Gamma: Array = None

    def rate(self, x: Array, b: Array) -> Array:
        return 0.0 * b

    def lyapunov(self, x: Array, phi: Array) -> Array:
        return 0.0 * (x * phi).sum(axis=-1)


class _Parts(Module):
    """φ split by its parts (`layout`: every parameter a link's 10 or a scalar): the links `(..., L, 10)` and the
    scalars `(..., S)`, and back."""

    layout: tuple[Part, ...]

    @derived
    def _order(self) -> tuple[Array, Array, Array]:
        """(entries of the links `(L, 10)`, entries of the scalars `(S,)`, the permutation that puts [links, scalars]
        back in φ's order)."""
        links = np.array([part.entries for part in self.layout if len(part.entries) == 10], dtype=int).reshape(-1, 10)
        scalars = np.array([part.entries[0] for part in self.layout if len(part.entries) == 1], dtype=int)
        return links, scalars, np.argsort(np.concatenate([links.ravel(), scalars]))

    def _split(self, v: Array) -> tuple[Array, Array]:
        links, scalars, _ = self._order
        return v[..., links], v[..., scalars]

    def _join(self, xp: Any, links: Array, scalars: Array) -> Array:
        flat = xp.reshape(links, links.shape[:-2] + (links.shape[-2] * links.shape[-1],))
        return xp.concatenate([flat, scalars], axis=-1)[..., self._order[2]]


@dataclass(frozen=True, eq=False)
class Natural(_Parts):
    """The natural adaptive law (Lee, Kwon & Park 2018) with gain γ on the parts of φ (`layout`, every parameter in
    one part), in log-Cholesky coordinates (module docstring; the derivation in docs/natural.md)."""

    gamma: Any
    layout: tuple[Part, ...]

    def state_names(self, param_names: tuple[str, ...]) -> tuple[str, ...]:
        names = list(param_names)
        for part in self.layout:
            if len(part.entries) == 1:
                names[part.entries[0]] = f"log_{param_names[part.entries[0]]}_hat"
            else:
                tag = part.name.replace(" ", "")
                for k, j in enumerate(part.entries):
                    i, c = _ROWS[k] + 1, _COLS[k] + 1
                    names[j] = f"{tag}_logL{i}{c}" if k < 4 else f"{tag}_L{i}{c}"
        return tuple(names)

    def initial_state(self, phi_hat0: Array) -> Array:
        """The coordinates of φ̂(0), which must be physically consistent (J ≻ 0 per link, > 0 per scalar)."""
        links, scalars = self._split(np.asarray(phi_hat0, dtype=float))
        J = pseudo_inertia(links)
        for part, low in zip([p for p in self.layout if len(p.entries) == 10], np.linalg.eigvalsh(J)[..., 0],
                             strict=True):
            if not low > 0:
                raise ConfigError("controller.phi_hat0", f"not physically consistent: {part.name}'s pseudo-inertia has "
                                  f"smallest eigenvalue {low:.3g}; the natural law starts from a real body (J ≻ 0), "
                                  "e.g. phi_hat0 = {scale = 0.7} of a consistent φ")
        for part, value in zip([p for p in self.layout if len(p.entries) == 1], scalars, strict=True):
            if not value > 0:
                raise ConfigError("controller.phi_hat0", f"not physically consistent: {part.name} = {value:g}; the "
                                  "natural law keeps a positive parameter positive, so it must start above 0")
        L = np.linalg.cholesky(J)
        coords = np.concatenate([np.log(L[..., _ROWS[:4], _COLS[:4]]), L[..., _ROWS[4:], _COLS[4:]]], axis=-1)
        return self._join(np, coords, np.log(scalars))

    def _factor(self, xp: Any, theta: Array) -> Array:
        """L of each link from its coordinates `(..., L, 10)`: exp on the diagonal."""
        return xp.einsum("...k,kab->...ab", xp.concatenate([xp.exp(theta[..., :4]), theta[..., 4:]], axis=-1), _UNIT)

    def estimate(self, x: Array) -> Array:
        xp = array_namespace(x)
        theta, s = self._split(x)
        L = self._factor(xp, theta)
        return self._join(xp, link_parameters(L @ xp.swapaxes(L, -1, -2)), xp.exp(s))

    def rate(self, x: Array, b: Array) -> Array:
        """dx/dt for dĴ/dt = Ĵ B Ĵ / γ: L̇ = L Φ(Lᵀ B L / γ) with Φ the lower part and half the diagonal, so
        d(log L_jj)/dt = Φ_jj; a scalar's d(log θ̂)/dt = θ̂ b / γ."""
        xp = array_namespace(x, b)
        theta, s = self._split(x)
        b_links, b_scalars = self._split(b)
        L = self._factor(xp, theta)
        B = xp.einsum("...k,kab->...ab", b_links, DUAL)
        Phi = (xp.swapaxes(L, -1, -2) @ B @ L) * (_LOWER_HALF / self.gamma)
        dL = L @ Phi
        pick = "...ab,kab->...k"
        return self._join(xp, xp.concatenate([xp.einsum(pick, Phi, _UNIT)[..., :4], xp.einsum(pick, dL, _UNIT)[..., 4:]],
                                             axis=-1), xp.exp(s) * b_scalars / self.gamma)

    def lyapunov(self, x: Array, phi: Array) -> Array:
        """γ Σ D(J‖Ĵ) over the parts, with the true φ (NaN where the truth itself is not a real body)."""
        xp = array_namespace(x, phi)
        theta, s = self._split(x)
        true_links, true_scalars = self._split(phi + 0.0 * x)
        L = self._factor(xp, theta)
        J = pseudo_inertia(true_links)
        A = xp.linalg.solve(L, xp.swapaxes(xp.linalg.solve(L, J), -1, -2))  # L⁻¹ J L⁻ᵀ, whose trace is tr(Ĵ⁻¹ J)
        sign, logdet = xp.linalg.slogdet(J)
        links = 2 * theta[..., :4].sum(axis=-1) - xp.where(sign > 0, logdet, xp.nan) + xp.trace(A, axis1=-2, axis2=-1) - 4
        scalars = s - xp.log(true_scalars) + true_scalars * xp.exp(-s) - 1
        return self.gamma * (links.sum(axis=-1) + scalars.sum(axis=-1))

    def step(self, x: Array, dx: Array, h: Any) -> Array:
        """The exponential map along dx over h: Ĵ⁺ = L exp(h S) Lᵀ with S = L⁻¹L̇ + (L⁻¹L̇)ᵀ (= Lᵀ B L / γ), then its
        Cholesky factor; a scalar's log moves by h·dx (θ̂⁺ = θ̂ exp(h θ̂ b / γ))."""
        xp = array_namespace(x, dx)
        theta, s = self._split(x)
        dtheta, ds = self._split(dx)
        L = self._factor(xp, theta)
        dL = xp.einsum("...k,kab->...ab", xp.concatenate([xp.exp(theta[..., :4]) * dtheta[..., :4], dtheta[..., 4:]],
                                                         axis=-1), _UNIT)
        Phi = xp.linalg.solve(L, dL)
        J = L @ expm(xp, h * (Phi + xp.swapaxes(Phi, -1, -2))) @ xp.swapaxes(L, -1, -2)
        L_next = xp.linalg.cholesky(0.5 * (J + xp.swapaxes(J, -1, -2)))
        coords = xp.einsum("...ab,kab->...k", L_next, _UNIT)
        return self._join(xp, xp.concatenate([xp.log(coords[..., :4]), coords[..., 4:]], axis=-1), s + h * ds)


@dataclass(frozen=True, eq=False)
class Pullback(Direct, _Parts):
    """The constant pullback metric of Lee, Kwon & Park (2018): the natural law's metric frozen at a reference φ₀
    (`phi_ref`, every part physically consistent: P₀ᵢ = J(φ₀ᵢ) ≻ 0 per link, θ₀ > 0 per scalar), state x = φ̂:

        dĴᵢ/dt = P₀ᵢ Bᵢ P₀ᵢ / γ   per link, Bᵢ the symmetric 4×4 matrix of tr(J(v) Bᵢ) = vᵀbᵢ (`DUAL`)
        dθ̂/dt  = θ₀² b / γ       per scalar (mass, rotor inertia, friction: the 1-D metric 1/θ² at θ₀)
        V_φ    = (γ/2) Σᵢ tr(P₀ᵢ⁻¹ J̃ᵢ P₀ᵢ⁻¹ J̃ᵢ) + (γ/2) Σ θ̃²/θ₀²,   J̃ᵢ = J(φ̃ᵢ), φ̃ = φ − φ̂

    Derivation (docs/natural.md#the-constant-pullback-metric): φ and P₀ are constant, so dJ̃ᵢ/dt = −dĴᵢ/dt and

        dV_φ/dt = −γ Σᵢ tr(P₀ᵢ⁻¹ J̃ᵢ P₀ᵢ⁻¹ dĴᵢ/dt) − γ Σ θ̃ (dθ̂/dt)/θ₀²
                = −Σᵢ tr(P₀ᵢ⁻¹ J̃ᵢ P₀ᵢ⁻¹ P₀ᵢ Bᵢ P₀ᵢ) − Σ θ̃ b = −Σᵢ tr(J̃ᵢ Bᵢ) − Σ θ̃ b = −φ̃ᵀb,

    which cancels the cross term +φ̃ᵀb of the law's servo part, as ½ φ̃ᵀΓ⁻¹φ̃ does for dφ̂/dt = Γ b: Slotine–Li's
    dV/dt = −rᵀK_v r (6.3.7), (6.3.16), (6.3.17); DCAL's (7.2.7), (7.2.14); adaptive computed torque's V (6.2.11) holds
    the parameter term without ½, so 2 V_φ there, with b = Wᵀ M̂⁻¹ E1 (6.2.19). The map b ↦ φ(P₀ B P₀)/γ is a constant
    block-diagonal Γ_P, symmetric positive definite (b'ᵀ Γ_P b = tr(P₀ B' P₀ B)/γ), and V_φ = ½ φ̃ᵀ Γ_P⁻¹ φ̃: the book's
    law with that Γ, so the book's proofs hold as written. V_φ is the second-order term of the natural law's
    γ D(J‖Ĵ) at Ĵ = J = P₀ (Hessian of the log-det divergence: tr(P⁻¹ X P⁻¹ X)), and at P₀ = Ĵ the rate is the
    natural law's. Nothing keeps Ĵ ≻ 0: the law is linear, `step` is x + h·dx and there is no projection, as for Γ.
    `phi_ref` may carry a leading runs axis (a batch whose φ̂(0), the default φ₀, varies per run)."""

    gamma: Any
    layout: tuple[Part, ...]
    phi_ref: Array

    @derived
    def _reference(self) -> tuple[Array, Array, Array]:
        """(P₀ `(..., L, 4, 4)`, P₀⁻¹, θ₀ `(..., S)`) of φ₀, in the namespace of `phi_ref`."""
        links, scalars = self._split(self.phi_ref)
        P0 = pseudo_inertia(links)
        return P0, array_namespace(P0).linalg.inv(P0), scalars


    def rate(self, x: Array, b: Array) -> Array:
        """dφ̂/dt: φ(P₀ B P₀ / γ) per link, θ₀² b / γ per scalar (linear in b; x does not enter)."""
        xp = array_namespace(x, b)
        P0, _, theta0 = self._reference
        b_links, b_scalars = self._split(b)
        B = xp.einsum("...k,kab->...ab", b_links, DUAL)
        return self._join(xp, link_parameters(P0 @ B @ P0 / self.gamma), theta0 * theta0 * b_scalars / self.gamma)

    def lyapunov(self, x: Array, phi: Array) -> Array:
        """(γ/2) Σ tr(P₀⁻¹ J̃ P₀⁻¹ J̃) + (γ/2) Σ θ̃²/θ₀² with the true φ (φ̃ = φ − φ̂)."""
        xp = array_namespace(x, phi)
        _, P0_inv, theta0 = self._reference
        error_links, error_scalars = self._split(phi - x)
        A = P0_inv @ pseudo_inertia(error_links)
        links = (A * xp.swapaxes(A, -1, -2)).sum(axis=(-2, -1))  # tr(A A)
        scalars = error_scalars * error_scalars / (theta0 * theta0)
        return 0.5 * self.gamma * (links.sum(axis=-1) + scalars.sum(axis=-1))


def pullback_reference(adaptation: str, phi_ref: Any, phi_hat0: Array, param_names: tuple[str, ...]) -> Any:
    """`phi_ref` validated for `adaptation` (None unless "pullback", and then None for the default φ₀ = φ̂(0)): one per
    parameter, every part physically consistent (J(φ₀ᵢ) ≻ 0, θ₀ > 0), or a one-line ConfigError naming the key that
    gave φ₀ (`controller.phi_ref`, or `controller.phi_hat0` for the default) and the fix."""
    if adaptation == "none":
        return None
    if adaptation != "pullback":
        if phi_ref is not None:
            raise ConfigError("controller.phi_ref", "is the pullback metric's reference φ₀: set adaptation = "
                              "\"pullback\", or remove phi_ref")
        return None
    key = "controller.phi_hat0" if phi_ref is None else "controller.phi_ref"
    value = np.asarray(phi_hat0, dtype=float) if phi_ref is None else as_vector(phi_ref, len(param_names), key,
                                                                                   broadcast=False)
    fix = ("set controller.phi_ref to a consistent φ (the identified one, or the URDF's), or start phi_hat0 from one"
           if phi_ref is None else "give the identified φ, or the URDF's")
    for part in parts(param_names):
        entries = list(part.entries)
        low = (np.linalg.eigvalsh(pseudo_inertia(value[entries]))[0] if len(entries) == 10 else value[entries[0]])
        if not low > 0:
            what = (f"{part.name}'s pseudo-inertia has smallest eigenvalue {low:.3g}" if len(entries) == 10 else
                    f"{part.name} = {low:g}")
            raise ConfigError(key, f"not physically consistent for adaptation = \"pullback\": {what}; the metric is "
                              f"the natural one at φ₀ = {key.split('.')[-1]}, which must be a real body (J ≻ 0 per link,"
                              f" > 0 per scalar): {fix}")
    return None if phi_ref is None else value


def adaptation_gains(adaptation: Any, Gamma: Any, gamma: Any, param_names: tuple[str, ...]) -> tuple[Any, Any]:
    """(Γ, γ) of a law's `adaptation`, `Gamma` and `gamma` fields, validated: Γ for "euclidean", γ > 0 for "natural"
    and "pullback" on a model whose every parameter has a physical form (a link's pseudo-inertia or a positive scalar).
    Under "natural" and "pullback" a scenario's Γ is the Euclidean law's and goes unused (None), so that `--set
    controller.adaptation="natural" --set controller.gamma=…` switches a packaged scenario (and "none" ignores both)."""
    if adaptation not in ADAPTATIONS:
        raise ConfigError("controller.adaptation", f"expected one of {', '.join(ADAPTATIONS)}, got {adaptation!r}")
    if adaptation == "none":  # φ̂(0) held: a scenario's gains go unused
        return None, None
    if adaptation == "euclidean":
        if Gamma is None:
            raise ConfigError("controller.Gamma", "required: the adaptation gain Γ (a scalar, a list or a p×p matrix), "
                              "or adaptation = \"natural\" with its gain gamma")
        if gamma is not None:
            raise ConfigError("controller.gamma", "is the natural law's gain: set adaptation = \"natural\" (or "
                              "\"pullback\"), or give Γ as controller.Gamma")
        return as_gain(Gamma, len(param_names), "controller.Gamma"), None
    rate = "dĴ/dt = Ĵ B Ĵ / γ" if adaptation == "natural" else "dĴ/dt = P₀ B P₀ / γ"
    if gamma is None:
        raise ConfigError("controller.gamma", f"required with adaptation = \"{adaptation}\": a positive scalar (larger "
                          f"is slower adaptation: {rate})")
    missing = unformed(param_names)
    if missing:
        raise ConfigError("controller.adaptation", f"\"{adaptation}\" needs every parameter to be a link's 10 inertial "
                          f"parameters or a positive scalar (mass, rotor inertia, friction); {', '.join(missing[:3])} "
                          "has no such form: use adaptation = \"euclidean\" (e.g. for base parameters)")
    return None, scalar_gain(gamma, "controller.gamma")


def geometry(adaptation: str, Gamma: Any, gamma: Any, param_names: tuple[str, ...],
             phi_ref: Any = None) -> Euclidean | Natural | Pullback:
    """The geometry of validated fields (:func:`adaptation_gains`; `phi_ref` the pullback metric's φ₀, resolved: the
    law's `phi_ref` or its φ̂(0), :func:`pullback_reference`)."""
    if adaptation == "none":
        return Frozen()
    if adaptation == "pullback":
        return Pullback(gamma, tuple(parts(param_names)), phi_ref)
    return Euclidean(Gamma) if adaptation == "euclidean" else Natural(gamma, tuple(parts(param_names)))
