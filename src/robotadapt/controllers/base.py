"""The controller contract and the error signals every law shares (docs/laws.md#model, docs/laws.md#slotine-li).

A controller holds only constants (model, gains, initial estimate). Its time-varying state `x` (φ̂, filter states,
integrals) comes in and its derivative goes out::

    tau, dx = ctrl(t, x, q, dq, ref)

with `q, dq` of shape `(..., n)`, `x` of shape `(..., s)`, `ref` a :class:`~robotadapt.trajectories.Reference`.
Controllers never see the true φ; only the optional monitors (`lyapunov`) take it, to evaluate the theory's V(t).

Optional parts a controller may have, each a protocol below: a Lyapunov function, a filtered error, a regressor with its
passivity output (for the integral (6.4.4)), acceleration feedback (Table 6.2.1 needs q̈), and a projection of its state
applied after every integration step. A law whose own assumptions can fail on a state (M̂ singular) has a guard
(:class:`HasGuard`), an indicator the loop reads on numpy and traced arrays alike (traced code cannot raise): the
simulator ends the run there and keeps the partial result.
"""

from __future__ import annotations

from functools import cached_property
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from ..arrays import array_namespace, matvec
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_gain, as_vector
from .geometry import Euclidean, Natural, adaptation_gains, geometry

Array = Any


class ControlLaw(Protocol):
    """What every controller has: its model, its state's layout and initial value, and its estimate."""

    model: RobotModel

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the entries of the state vector x."""

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        """The state x at t = 0, given the first measurement (filters that start from it need it)."""

    def phi_hat(self, x: Array) -> Array:
        """The parameter estimate held in (or fixed by) the controller, shape `x.shape[:-1] + (p,)`."""


@runtime_checkable
class Controller(ControlLaw, Protocol):
    """A control law whose torque and state derivative need only (t, x, q, q̇, ref)."""

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        """(τ, dx/dt): the torque and the derivative of the controller's state, e.g. (6.3.14) and (6.3.16)."""


@runtime_checkable
class HasLyapunov(Protocol):
    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """The Lyapunov function of the controller's stability proof, evaluated with the true φ."""


@runtime_checkable
class HasRegressor(Protocol):
    def regressor(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        """(Z, r): the regressor multiplying φ̂ in the torque and the filtered error, so that M ṙ + V_m r = Zφ − τ;
        the passivity integral (6.4.4) is ∫ −rᵀ Z φ̃."""


@runtime_checkable
class HasRegressorProducts(Protocol):
    def regressor_products(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference,
                           phi: Array) -> tuple[Array, Array, Array]:
        """(Z φ, Zᵀ r, r) for the law's (Z, r) of `regressor`, without forming Z where the model can
        (:meth:`~robotadapt.robots.base.RobotModel.regressor_products`): the torque's Z φ̂, the update's Zᵀ r and the
        passivity integrand −(Zᵀ r)ᵀ φ̃ from one pass."""


@runtime_checkable
class NeedsAcceleration(ControlLaw, Protocol):
    """A controller whose update law needs the measured joint acceleration (Table 6.2.1). Its torque must not."""

    def torque(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """τ from the state and the measured q, q̇ (6.2.5)."""

    def update(self, t: Array, x: Array, q: Array, dq: Array, ddq: Array, ref: Reference) -> Array:
        """dx/dt with the measured q̈ (6.2.19)."""


@runtime_checkable
class HasGuard(Protocol):
    """A law whose assumptions can fail on a state (adaptive computed torque: M̂(q) must stay positive definite). Its
    torque or update returns NaN there, raising nothing (traced arrays cannot raise); the loop reads `guard` at every
    evaluation and stops the run itself, with `stop_reason`."""

    def guard(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """True where the law's assumption holds at (x, q), a boolean of shape `x.shape[:-1]`. Raises nothing."""

    def stop_reason(self, q: Array, x: Array) -> str:
        """Why a run stops at (q, x) where the guard fails, in words (numpy arrays)."""


@runtime_checkable
class FiltersTorque(Protocol):
    """A controller whose state filters the torque the plant receives (the composite law's τ_f = f * τ,
    docs/laws.md#composite).

    Its own derivative assumes the plant receives the torque it commands; where an actuator saturates, delays or
    rate-limits it, or a wrapper adds to it, the simulator passes the applied torque through `applied`."""

    def applied(self, dx: Array, tau: Array, u: Array) -> Array:
        """dx/dt with the torque filter driven by the applied torque `u` instead of the command `tau`."""


@runtime_checkable
class HasProjection(Protocol):
    def project(self, x: Array) -> Array:
        """Map the state back into its admissible set (applied after every fixed step)."""


@runtime_checkable
class HasDelayLine(Protocol):
    """A controller with a delay line of one period (the repetitive law (7.2.32)); it needs the fixed-step integrator.

    At the start of every step k the simulator reads `past` = the value stored N steps earlier, calls `sample`, writes
    back what it returns, and keeps the new state x constant over the step's stages (x holds the sampled part)."""

    def delay_line(self, dt: float, q0: Array, dq0: Array) -> Array:
        """The initial contents of the line, shape `(N, ...)`, N steps of `dt` per period."""

    def sample(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, past: Array) -> tuple[Array, Array]:
        """(new state x, value to store in the line now)."""


@runtime_checkable
class HasStep(Protocol):
    """A law whose state lives on a manifold (the natural law's pseudo-inertias): a sampled-data tick moves it by
    `step` (the exponential map) in place of x + h·dx."""

    def step(self, x: Array, dx: Array, h: Any) -> Array:
        """x after a step of length h along dx/dt."""


@runtime_checkable
class Prepares(Protocol):
    def prepare(self, trajectory: Any, dt: float, t_final: float) -> Controller:
        """A copy of the controller with tables computed ahead of the run (e.g. Y_d along the desired trajectory)."""


@runtime_checkable
class HasInstantEstimate(Protocol):
    def phi_hat_at(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The φ̂ the torque uses when it depends on the signals too (Landau's PI law: φ̂_I + F_p Zᵀ r, (6.4.20))."""


@runtime_checkable
class HasFilteredError(Protocol):
    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The filtered tracking error r the controller drives to zero."""


def errors(q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
    """e = q_des − q, ė = q̇_des − q̇ (the book's sign)."""
    return ref.q_des - q, ref.dq_des - dq


def slotine_li_reference(Lam: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array, Array]:
    """(v, a, r): the reference velocity q̇_d + Λe and acceleration q̈_d + Λė (6.3.11), and r = ė + Λe (6.3.8)."""
    e, de = errors(q, dq, ref)
    Le, Lde = matvec(Lam, e), matvec(Lam, de)
    return ref.dq_des + Le, ref.ddq_des + Lde, de + Le


def slotine_li_regressor(model: RobotModel, Lam: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
    """(Y, r): Y(q, q̇, q̇_d + Λe, q̈_d + Λė) (6.3.11) and r (6.3.8), shared by every law with Table 6.3.1's torque."""
    v, a, r = slotine_li_reference(Lam, q, dq, ref)
    return model.regressor(q, dq, v, a), r


def slotine_li_products(model: RobotModel, Lam: Array, q: Array, dq: Array, ref: Reference,
                        phi: Array) -> tuple[Array, Array, Array]:
    """(Y φ, Yᵀ r, r) for slotine_li_regressor's (Y, r), through the model's `regressor_products` (no Y formed)."""
    v, a, r = slotine_li_reference(Lam, q, dq, ref)
    return (*model.regressor_products(q, dq, v, a, phi, r), r)


def freeze(obj: Any, **values: Any) -> None:
    """Set validated fields on a frozen dataclass from its `__post_init__`."""
    for name, value in values.items():
        object.__setattr__(obj, name, value)


def gains(obj: Any, names: tuple[str, ...], dim: int) -> None:
    """Validate the named `dim`×`dim` gain fields of `obj` (scalar → k·I, list → diag, matrix) as symmetric PD."""
    freeze(obj, **{name: as_gain(getattr(obj, name), dim, f"controller.{name}") for name in names})


def estimate(obj: Any, name: str = "phi_hat0") -> None:
    """Validate a parameter-estimate field against the model's parameter count."""
    if getattr(obj, name) is None:
        raise ConfigError(f"controller.{name}", "required: the initial estimate φ̂(0), one value per parameter")
    freeze(obj, **{name: as_vector(getattr(obj, name), obj.model.p, f"controller.{name}", broadcast=False)})


class EstimateState:
    """The state of a law that adapts φ̂ with a gain (Slotine–Li, adaptive computed torque, DCAL: Tables 6.3.1, 6.2.1,
    7.2.1): the book's Euclidean update with Γ (state x = φ̂), or `adaptation = "natural"` with the scalar γ (state:
    log-Cholesky coordinates of each link's pseudo-inertia, :mod:`robotadapt.controllers.geometry`). A mixin of the
    laws' dataclasses, which hold `model`, `Gamma`, `phi_hat0`, `adaptation` and `gamma` and call :meth:`adapts` from
    their `__post_init__`. The law's b (the vector its proof pairs with φ̃) moves the state by `geometry.rate(x, b)`."""

    model: RobotModel
    Gamma: Array
    phi_hat0: Array
    adaptation: str
    gamma: Any
    #: the cached constants built from Γ or γ (a tuned gain rebuilds them; studies.gain_space)
    derived: ClassVar[tuple[str, ...]] = ("geometry",)

    def adapts(self) -> None:
        """Validate `adaptation`, `Gamma`, `gamma` and `phi_hat0` (physically consistent for the natural law)."""
        Gamma, gamma = adaptation_gains(self.adaptation, self.Gamma, self.gamma, self.model.param_names)
        freeze(self, Gamma=Gamma, gamma=gamma)
        estimate(self)
        self.geometry.initial_state(self.phi_hat0)

    @cached_property
    def geometry(self) -> Euclidean | Natural:
        return geometry(self.adaptation, self.Gamma, self.gamma, self.model.param_names)

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.geometry.state_names(self.model.param_names)

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        return self.geometry.initial_state(self.phi_hat0)

    def phi_hat(self, x: Array) -> Array:
        return self.geometry.estimate(x)

    def step(self, x: Array, dx: Array, h: Any) -> Array:
        """x after a control period h along dx/dt (HasStep): the exponential map of the natural law."""
        return self.geometry.step(x, dx, h)


def inverse(A: Array) -> Array:
    """A⁻¹ in the namespace of A (numpy, or JAX when a compiled evaluation traces the law's derived constants)."""
    return array_namespace(A).linalg.inv(A)


def positive_definite(xp: Any, A: Array) -> Array:
    """Per matrix of `A` (`(..., n, n)`, symmetric): True where it is positive definite, shape `(...)`; False for
    non-finite entries. The Cholesky test: in closed form for n ≤ 2 (a₁₁ > 0 and det A > 0, Sylvester), else a finite
    Cholesky factor, which numpy refuses for the whole stack (LinAlgError: asked again matrix by matrix) and JAX
    returns with NaNs. Raises nothing and writes nothing, so that a compiled loop can trace it."""
    n = A.shape[-1]
    if n == 1:
        return A[..., 0, 0] > 0
    if n == 2:
        return (A[..., 0, 0] > 0) & (A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0] > 0)
    if xp is np:
        try:
            return np.all(np.isfinite(np.linalg.cholesky(A)), axis=(-2, -1))
        except np.linalg.LinAlgError:
            return np.array([_cholesky_ok(a) for a in A.reshape(-1, n, n)], dtype=bool).reshape(A.shape[:-2])
    return xp.all(xp.isfinite(xp.linalg.cholesky(A)), axis=(-2, -1))


def _cholesky_ok(A: Array) -> bool:
    try:
        return bool(np.all(np.isfinite(np.linalg.cholesky(A))))
    except np.linalg.LinAlgError:
        return False
