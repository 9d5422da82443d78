"""The controller contract and the error signals every law shares (docs/laws.md#model, docs/laws.md#slotine-li).

A controller holds only constants (model, gains, initial estimate). Its time-varying state `x` (φ̂, filter states,
integrals) comes in and its derivative goes out::

    tau, dx = ctrl(t, x, q, dq, ref)

with `q, dq` of shape `(..., n)`, `x` of shape `(..., s)`, `ref` a :class:`~robotadapt.trajectories.Reference`.
Controllers never see the true φ; only the optional monitors (`lyapunov`) take it, to evaluate the theory's V(t).

Every law derives from :class:`Law`, whose hooks (a Lyapunov function, a filtered error, a regressor with its passivity
output for the integral (6.4.4), acceleration feedback (Table 6.2.1 needs q̈), a projection of its state, a guard, a
delay line, tables prepared ahead, a torque filter) have defaults the simulator always calls. A law whose own
assumptions can fail on a state (M̂ singular) has a guard, an indicator the loop reads on numpy and traced arrays alike
(traced code cannot raise): the simulator ends the run there and keeps the partial result.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace, matvec
from ..pytree import Module, derived
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_gain, as_vector
from .geometry import Euclidean, Natural, Pullback, adaptation_gains, geometry, pullback_reference
from .registry import Contender, Registered

Array = Any


class Law(Registered, Module, ABC):
    """The base of every control law (docs/laws.md#model, docs/tutorial.md): a frozen dataclass holding constants only
    (its model, gains, initial estimate), a pytree whose gains are leaves (:mod:`robotadapt.pytree`). A law gives its
    torque and state derivative (`__call__`), its state's names and initial value and its estimate; every other part
    of the contract is a hook with a default here, which the simulator always calls, so a law overrides what it has and
    nothing is probed:

    ========================  ====================================================  ===========================
    hook                      what it is                                             default
    ========================  ====================================================  ===========================
    `guard`, `stop_reason`    where the law's own assumptions fail (M̂ singular)     None: always holds
    `project`                 the state mapped back into its admissible set          identity
    `applied`                 dx/dt with the torque filter driven by the applied u   dx unchanged (no filter)
    `delay_line`, `sample`    a delay line of one period (7.2.32)                    None: no line
    `prepare`                 tables computed ahead of the run (Y_d)                 itself
    `step`                    the discrete step of a sampled-data tick               x + h·dx
    `regressor`               (Z, r), the passivity output of (6.4.4)                None: no passivity output
    `regressor_products`      (Z φ, Zᵀ r, r) without forming Z where it can          through `regressor`
    `filtered_error`          the filtered error r the law drives to zero            None
    `lyapunov`                V of the law's proof, with the true φ                  None
    `phi_hat_at`              the φ̂ its torque uses when signals enter it (6.4.20)  `phi_hat(x)`
    `passivity_caveat`        why the gains may not imply the passivity claim        None
    `lyapunov_caveat`         why `lyapunov` is no Lyapunov function of the loop     None
    `monitors`                the law's own monitor series (λ_min(P⁻¹))             none
    `tracking_error`          (e, ė) the metrics measure; `error_size` its length   q_des − q; n
    ========================  ====================================================  ===========================

    A law whose update reads the measured q̈ (Table 6.2.1) sets `needs_acceleration` and gives `torque` and `update`
    in place of `__call__`. The facts the simulator fixes before a run (whether the law has a guard, a delay line, a
    passivity output, a torque filter) are read off which hooks the law overrides (:meth:`has`), once.

    A law registers itself in its class body (:mod:`robotadapt.controllers.registry`): `kind` (its scenario kind and
    `ra.<ClassName>`), `aliases`, `tuned` (the gains a fair comparison varies), and for the comparison
    (:mod:`robotadapt.studies.compare`) its `lineup` entries, its gain `family` and the `powers` of the arm's scale
    its gains carry."""

    model: RobotModel
    #: Table 6.2.1's split: `torque` needs no q̈, `update` takes the plant's q̈ for the torque just applied
    needs_acceleration: ClassVar[bool] = False
    #: its entries in the comparison's lineup (none: it runs there only as a scenario's own law)
    lineup: ClassVar[tuple[Contender, ...]] = ()
    #: a baseline with a fixed φ̂: the comparison gives it the nominal model (the model's published values, else the
    #: true φ), not the adaptive laws' common φ̂(0)
    nominal: ClassVar[bool] = False
    #: where its reference lives: "joint" (q_d) or "task" (the hand's x_d: docs/task-space.md); the comparison runs
    #: the laws of the scenario's law's space
    space: ClassVar[str] = "joint"
    #: the comparison's gain family: the laws of one family take from the scenario's law the gains that play the same
    #: part ("6": r = ė + Λe, chapter 6; "7.2": r = ė + e, §7.2); None: shares none
    family: ClassVar[str | None] = None
    #: the power of the arm's scale s each gain carries in the comparison: 1 for torque gains and adaptation gains
    #: (φ scales as M, the regressor does not), none (a key not listed) for rates and options; the servo's and the
    #: update law's gains of a passivity-based law are its own
    powers: ClassVar[Mapping[str, int]] = MappingProxyType({"Kv": 1, "Kp": 1, "Ka": 1, "kL": 1, "kd": 1, "Gamma": 1,
                                                            "P0": 1, "K_I": 1, "F_p": 1})

    def has(self, hook: str) -> bool:
        """Whether the law gives its own `hook` (a wrapper answers for what it wraps)."""
        return getattr(type(self), hook) is not getattr(Law, hook)

    @property
    def records(self) -> int:
        """Trailing entries of x kept for a monitor only (the repetitive law's window integrals of V): the divergence
        guard skips them."""
        return 0

    #: (τ, dx/dt) = law(t, x, q, q̇, ref): the torque and the derivative of the law's state, e.g. (6.3.14) and
    #: (6.3.16); a law with `needs_acceleration` gives `torque` and `update` instead
    __call__: Callable[..., tuple[Array, Array]]

    @property
    @abstractmethod
    def state_names(self) -> tuple[str, ...]:
        """Names of the entries of the state vector x."""

    @abstractmethod
    def initial_state(self, q0: Array, dq0: Array) -> Array:
        """The state x at t = 0, given the first measurement (filters that start from it need it)."""

    @abstractmethod
    def phi_hat(self, x: Array) -> Array:
        """The parameter estimate held in (or fixed by) the law, shape `x.shape[:-1] + (p,)`."""

    def torque(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """τ alone (a law with `needs_acceleration`: from the state and the measured q, q̇, (6.2.5))."""
        return self(t, x, q, dq, ref)[0]

    def update(self, t: Array, x: Array, q: Array, dq: Array, ddq: Array, ref: Reference) -> Array:
        """dx/dt with the measured q̈ (a law with `needs_acceleration`, (6.2.19)); else the state derivative of
        `__call__`."""
        return self(t, x, q, dq, ref)[1]

    def respond(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference,
                apply: Callable[[Array], tuple[Array, Any, Any]]) -> tuple[Array, Array, Array, Any]:
        """The law inside a loop, in Table 6.2.1's order: τ, then `apply(τ)` — the loop's (u, the torque the plant
        receives; q̈ measured under it, or None; anything else the loop keeps) — then dx/dt: `update` with that q̈ for
        a law with `needs_acceleration`, else `__call__`'s, told u through `applied`. Returns (τ, u, dx/dt, the rest):
        the one call of a law in the continuous loop and the sampled tick alike."""
        if self.needs_acceleration:
            tau = self.torque(t, x, q, dq, ref)
            u, ddq, rest = apply(tau)
            return tau, u, self.update(t, x, q, dq, ddq, ref), rest
        tau, dx = self(t, x, q, dq, ref)
        u, _, rest = apply(tau)
        return tau, u, self.applied(dx, tau, u), rest

    def guard(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array | None:
        """True where the law's assumption holds at (x, q), a boolean of shape `x.shape[:-1]`; None: it always holds.
        Raises nothing (traced arrays cannot raise): the torque or update is NaN where it fails, and the loop stops
        the run there itself, with `stop_reason`."""
        return None

    def stop_reason(self, q: Array, x: Array) -> str:
        """Why a run stops at (q, x) where the guard fails, in words (numpy arrays)."""
        return "the law's guard failed"

    def project(self, x: Array) -> Array:
        """The state mapped back into its admissible set (applied after every fixed step and tick)."""
        return x

    def applied(self, dx: Array, tau: Array, u: Array) -> Array:
        """dx/dt with a torque filter in the state driven by the torque the plant receives, `u`, instead of the command
        `tau` (the composite law's τ_f = f * τ): where an actuator saturates, delays or rate-limits the torque."""
        return dx

    def delay_line(self, dt: float, q0: Array, dq0: Array) -> Array | None:
        """The initial contents `(N, ...)` of a delay line of one period, N steps of `dt` (the repetitive law (7.2.32));
        None: no line. At the start of every step k the simulator reads the value stored N steps earlier, calls
        `sample`, writes back what it returns, and holds the new state over the step's stages."""
        return None

    def sample(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, past: Array) -> tuple[Array, Array]:
        """(new state x, value to store in the line now) at a step's start (a law with a delay line)."""
        return x, past

    def prepare(self, trajectory: Any, dt: float, t_final: float) -> Law:
        """The law with tables computed ahead of the run (Y_d along the desired trajectory); itself by default."""
        return self

    def step(self, x: Array, dx: Array, h: Any) -> Array:
        """x after a sampled-data tick of length h along dx/dt: x + h·dx, or a manifold's exponential map (the natural
        law's pseudo-inertias)."""
        return x + h * dx

    def regressor(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array] | None:
        """(Z, r): the regressor multiplying φ̂ in the torque and the filtered error, so that M ṙ + V_m r = Zφ − τ; the
        passivity integral (6.4.4) is ∫ −rᵀ Z φ̃. None: the law has no passivity output."""
        return None

    def regressor_products(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference,
                           phi: Array) -> tuple[Array, Array, Array]:
        """(Z φ, Zᵀ r, r) for `regressor`'s (Z, r): the torque's Z φ̂, the update's Zᵀ r and the passivity integrand
        −(Zᵀ r)ᵀ φ̃ from one pass; a law whose model gives them without forming Z overrides it
        (:meth:`~robotadapt.robots.base.RobotModel.regressor_products`)."""
        found = self.regressor(t, x, q, dq, ref)
        if found is None:
            raise TypeError(f"{type(self).__name__} has no passivity output: its regressor is None")
        Z, r = found
        return matvec(Z, phi), matvec(Z.mT, r), r

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array | None:
        """The filtered tracking error r the law drives to zero; None: the law has none."""
        return None

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array | None:
        """The Lyapunov function of the law's stability proof, evaluated with the true φ (monitors only); None."""
        return None

    def phi_hat_at(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The φ̂ the torque uses (Landau's PI law: φ̂_I + F_p Zᵀ r, (6.4.20)); `phi_hat(x)` by default."""
        return self.phi_hat(x)

    def passivity_caveat(self) -> str | None:
        """Why the law's gains may not imply its passivity claim (the σ-modification's), or None."""
        return None

    def lyapunov_caveat(self) -> str | None:
        """Why `lyapunov` is no Lyapunov function of this loop (a law that holds φ̂), so that its growth warns of
        nothing; None."""
        return None

    def monitors(self, x: Array, q: Array) -> dict[str, Array]:
        """The law's own monitor series at the logged states and joint angles (the composite law's λ_min(P⁻¹),
        (6.6.27); a task-space law's σ_min(J))."""
        return {}

    @property
    def error_size(self) -> int:
        """The length of the tracking error the law drives to zero: n joints, or a task-space law's m coordinates."""
        return self.model.n

    def tracking_error(self, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        """(e, ė) the run's metrics measure: e = q_des − q by default; a task-space law's x_d − x(q) (its reference
        holds x_d, ẋ_d, ẍ_d)."""
        return errors(q, dq, ref)


def as_law(controller: Any) -> Law:
    """`controller`, checked to be a :class:`Law` (the argument check of the simulator's front doors: every optional
    hook it calls has its default there), else a one-line ConfigError naming the fix."""
    if not isinstance(controller, Law):
        raise ConfigError("controller", f"{type(controller).__name__} is not a law: derive it from "
                          "robotadapt.controllers.Law (docs/tutorial.md), which gives every optional part a default")
    return controller


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


class FixedEstimate(Law):
    """The state of a law whose estimate φ̂ is a constant, `phi_hat0` (the baselines, operational-space control): none."""

    phi_hat0: Array

    @property
    def state_names(self) -> tuple[str, ...]:
        return ()

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        return np.zeros(0)

    def phi_hat(self, x: Array) -> Array:
        xp = array_namespace(x)
        return xp.broadcast_to(xp.asarray(self.phi_hat0), x.shape[:-1] + self.phi_hat0.shape)


class EstimateState(Law):
    """The state of a law that adapts φ̂ with a gain (Slotine–Li, adaptive computed torque, DCAL: Tables 6.3.1, 6.2.1,
    7.2.1): the book's Euclidean update with Γ (state x = φ̂), `adaptation = "natural"` with the scalar γ (state:
    log-Cholesky coordinates of each link's pseudo-inertia), or `adaptation = "pullback"` with γ and the reference
    `phi_ref` (default φ̂(0); state x = φ̂), :mod:`robotadapt.controllers.geometry`. A mixin of the laws' dataclasses,
    which hold `model`, `Gamma`, `phi_hat0`, `adaptation`, `gamma` and `phi_ref` and call :meth:`adapts` from their
    `__post_init__`. The law's b (the vector its proof pairs with φ̃) moves the state by `geometry.rate(x, b)`."""

    model: RobotModel
    Gamma: Array
    phi_hat0: Array
    adaptation: str
    gamma: Any
    phi_ref: Any

    def adapts(self) -> None:
        """Validate `adaptation`, `Gamma`, `gamma`, `phi_hat0` (physically consistent for the natural law) and
        `phi_ref` (the pullback metric's φ₀, physically consistent; None: φ̂(0), which then must be)."""
        Gamma, gamma = adaptation_gains(self.adaptation, self.Gamma, self.gamma, self.model.param_names)
        freeze(self, Gamma=Gamma, gamma=gamma)
        estimate(self)
        freeze(self, phi_ref=pullback_reference(self.adaptation, self.phi_ref, self.phi_hat0, self.model.param_names))
        self.geometry.initial_state(self.phi_hat0)

    @derived
    def geometry(self) -> Euclidean | Natural | Pullback:
        return geometry(self.adaptation, self.Gamma, self.gamma, self.model.param_names,
                        self.phi_hat0 if self.phi_ref is None else self.phi_ref)

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.geometry.state_names(self.model.param_names)

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        return self.geometry.initial_state(self.phi_hat0)

    def phi_hat(self, x: Array) -> Array:
        return self.geometry.estimate(x)

    def lyapunov_caveat(self) -> str | None:
        if self.adaptation != "none":
            return None
        return ("φ̂ is held at φ̂(0) (adaptation = \"none\"): V = ½ rᵀ M r has no parameter term, and Y φ̃ drives it, so "
                "it is no Lyapunov function of this loop")

    def step(self, x: Array, dx: Array, h: Any) -> Array:
        """x after a control period h along dx/dt: the exponential map of the natural law (x + h·dx for Γ)."""
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
