"""The passivity-based class of adaptive controllers (Ortega & Spong; Brogliato, Landau & Lozano):
docs/laws.md#passivity, Table 6.4.1.

The servo filter is given by G(s) = K(s)/s (6.4.2), proper, in state space::

    ξ' = A ξ + B e,   w = G(s) e = D e + C ξ

so that r = H⁻¹(s) e = ė + w (6.4.1), and the signals of (6.4.3) need no joint acceleration::

    v = q̇_d + w,   a = q̈_d + K(s) e = q̈_d + ẇ = q̈_d + D ė + C (A ξ + B e),   Z = Y(q, q̇, v, a)

H(s) = (sI + G(s))⁻¹ has the realization (state [e; ξ], input r, output e) with state matrix [[−D, −C], [B, A]]: it is
strictly proper by construction, and stable when every eigenvalue of that matrix has a negative real part, which
every :class:`Servo` checks at construction. The PD and PID servos hold their gains Λ, Ψ and read D = Λ, C = Ψ off
them, so `robotadapt tune` varies the gains themselves. The update law is any part of
:mod:`robotadapt.controllers.adaptation` that satisfies (6.4.4).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace, matvec
from ..pytree import Module
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_array, as_gain
from .adaptation import UpdateLaw
from .base import Array, Law, errors, estimate, freeze, gains
from .registry import Contender, OfTruth

_SERVO = "controller.servo"


def _matrix(value: Any, shape: tuple[int, int], field: str) -> Array:
    """A finite matrix of exactly `shape` (an empty list stands for any matrix with no entries)."""
    arr = as_array(value, field)
    if arr.size == 0 and 0 in shape:
        return np.zeros(shape)
    if arr.shape != shape:
        raise ConfigError(field, f"expected a {shape[0]}x{shape[1]} matrix (nested lists), got shape {arr.shape}")
    return arr


class Servo(Module):
    """A servo filter G(s) = K(s)/s = D + C (sI − A)⁻¹ B of the passivity-based class (6.4.2), by its matrices: D n×n,
    A m×m, B m×n, C n×m, with m ≥ 0 filter states ξ (m = 0: G(s) = D is static). :class:`ServoFilter` holds them;
    :class:`PdServo` and :class:`PidServo` hold their gains, fix A and B by n and read D (and C) off the gains, so a
    gain set on a built servo (a traced one when `robotadapt tune` varies Λ or Ψ) is the D and C the law uses. Every
    servo checks at construction that H(s) = (sI + G(s))⁻¹ is stable (6.4.19)."""

    #: the gains a fair comparison tunes (as a law's `tuned`, :mod:`robotadapt.controllers.registry`)
    tuned: ClassVar[tuple[str, ...]] = ()

    D: Array
    A: Array
    B: Array
    C: Array
    n: int

    @property
    def m(self) -> int:
        """Number of filter states ξ."""
        return int(self.A.shape[0])

    @property
    def state_matrix(self) -> Array:
        """[[−D, −C], [B, A]]: the state matrix of H(s), state [e; ξ], input r (ė = r − D e − C ξ)."""
        return np.block([[-self.D, -self.C], [self.B, self.A]])

    def _check_stable(self) -> None:
        """H(s) stable (6.4.19): every eigenvalue of [[−D, −C], [B, A]] has a negative real part, else a ConfigError
        naming `controller.servo`."""
        lead = float(np.max(np.linalg.eigvals(self.state_matrix).real))
        if not lead < -1e-12 * max(1.0, float(np.abs(self.state_matrix).max())):
            raise ConfigError(_SERVO, f"H(s) = (sI + G(s))^-1 is not stable: its state matrix [[-D, -C], [B, A]] has an "
                              f"eigenvalue with real part {lead:.3g} (every real part must be negative)")

    def _check_gains(self, *names: str) -> None:
        """The named gains as n×n SPD matrices (a number k is k·I, a list the diagonal), then H(s) stable (6.4.19)."""
        freeze(self, **{name: as_gain(getattr(self, name), self.n, f"{_SERVO}.{name}") for name in names})
        self._check_stable()


@dataclass(frozen=True, eq=False)
class ServoFilter(Servo):
    """Any proper G(s) = D + C (sI − A)⁻¹ B (6.4.2) given by its matrices. Construction checks the shapes and that
    H(s) is stable (6.4.19)."""

    D: Any
    A: Any
    B: Any
    C: Any
    n: int = field(init=False, repr=False, metadata={"internal": True})

    def __post_init__(self) -> None:
        D = as_array(self.D, f"{_SERVO}.D")
        if D.ndim != 2 or D.shape[0] != D.shape[1]:
            raise ConfigError(f"{_SERVO}.D", f"expected a square matrix, got shape {D.shape}")
        A = as_array(self.A, f"{_SERVO}.A")
        m = 0 if A.size == 0 else (A.shape[0] if A.ndim else 1)
        n = D.shape[0]
        freeze(self, D=D, A=_matrix(A, (m, m), f"{_SERVO}.A"), B=_matrix(self.B, (m, n), f"{_SERVO}.B"),
               C=_matrix(self.C, (n, m), f"{_SERVO}.C"), n=n)
        self._check_stable()


@dataclass(frozen=True, eq=False)
class PdServo(Servo):
    """K(s) = Λ s, i.e. G(s) = D = Λ in (6.4.2): r = ė + Λe, Slotine–Li as a member of the class (Example 6.4.2). No
    state."""

    tuned = ("Lam",)

    n: int
    Lam: Any
    A: Array = field(init=False, repr=False, metadata={"internal": True})
    B: Array = field(init=False, repr=False, metadata={"internal": True})
    C: Array = field(init=False, repr=False, metadata={"internal": True})

    def __post_init__(self) -> None:
        freeze(self, A=np.zeros((0, 0)), B=np.zeros((0, self.n)), C=np.zeros((self.n, 0)))
        self._check_gains("Lam")

    @property
    def D(self) -> Array:
        return self.Lam


@dataclass(frozen=True, eq=False)
class PidServo(Servo):
    """K(s) = Λ s + Ψ (Example 6.4.3 (3)), in (6.4.2) D = Λ, A = 0, B = I, C = Ψ: ξ = ε = ∫ e, r = ė + Λe + Ψε, so
    that K_v r is the PID law K_v ė + K_p e + K_I ∫e with K_p = K_v Λ, K_I = K_v Ψ; h_i(s) = s / (s² + λ_i s + ψ_i)
    (Example 6.4.3 (5))."""

    tuned = ("Lam", "Psi")

    n: int
    Lam: Any
    Psi: Any
    A: Array = field(init=False, repr=False, metadata={"internal": True})
    B: Array = field(init=False, repr=False, metadata={"internal": True})

    def __post_init__(self) -> None:
        freeze(self, A=np.zeros((self.n, self.n)), B=np.eye(self.n))
        self._check_gains("Lam", "Psi")

    @property
    def D(self) -> Array:
        return self.Lam

    @property
    def C(self) -> Array:
        return self.Psi


pd_servo, pid_servo = PdServo, PidServo  # the scenario kinds `pd` and `pid` (their keys: the fields after n)


def state_space_servo(n: int, D: Any, A: Any, B: Any, C: Any) -> ServoFilter:
    """Any proper G(s) = D + C (sI − A)⁻¹ B given by its matrices (nested lists; `A = []`, `B = []`,
    `C = [[], ...]` for a static G)."""
    servo = ServoFilter(D=D, A=A, B=B, C=C)
    if servo.n != n:
        raise ConfigError(f"{_SERVO}.D", f"expected {n}x{n} (one row per joint), got {servo.n}x{servo.n}")
    return servo


@dataclass(frozen=True, eq=False)
class PassivityBased(Law):
    """Adaptive passivity-based controller, Table 6.4.1, with servo filter `servo` and update law `law`.

    r = ė + w,  w = G(s) e                                                   (6.4.1)
    Z φ = M(q)(q̈_d + K(s) e) + V_m(q, q̇)(q̇_d + G(s) e) + G(q) + F(q̇)       (6.4.3)
    τ = Z φ̂ + K_v r                                                         (6.4.5)
    φ̂ = law.estimate(x_a, y),  dx_a/dt = law.derivative(x_a, y),  y = Zᵀ r    (6.4.20)

    State x = [ξ, x_a]: the servo filter's states, then the law's (x_a = φ̂ for the gradient and σ-modification laws,
    the integral part φ̂_I for Landau's PI law). Closed loop: M ṙ + V_m r + K_v r = Z φ̃ (6.4.7).

    Lyapunov function, evaluated by :meth:`lyapunov` with the true φ::

        V = ½ rᵀ M(q) r + law.lyapunov(x_a, φ)

    Gradient law (Example 6.4.1): V = ½ rᵀ M r + ½ φ̃ᵀ Γ⁻¹ φ̃, which is (6.4.8) with β = ½ φ̃(0)ᵀ Γ⁻¹ φ̃(0), since
    ∫₀ᵗ −rᵀ Z φ̃ = ½ φ̃(t)ᵀ Γ⁻¹ φ̃(t) − β; dV/dt = −rᵀ K_v r (6.4.11).
    Landau PI law (6.4.21): V = ½ rᵀ M r + ½ φ̃_Iᵀ K_I⁻¹ φ̃_I, φ̃_I = φ − φ̂_I. With skew symmetry,
    d/dt ½ rᵀ M r = rᵀ(Z φ − τ) = −rᵀ K_v r + yᵀ(φ̃_I − F_p y) and d/dt ½ φ̃_Iᵀ K_I⁻¹ φ̃_I = −φ̃_Iᵀ y, so
    dV/dt = −rᵀ K_v r − yᵀ F_p y ≤ 0.

    `phi_hat(x)` is the estimate at y = 0: φ̂ itself for the gradient and σ laws, but only the integral part φ̂_I for
    the PI law, whose φ̂ = φ̂_I + F_p Zᵀ r also depends on (q, q̇, q_d, ...): :meth:`phi_hat_at` gives the full φ̂.
    """

    per_run: ClassVar[tuple[str, ...]] = ("phi_hat0",)  # varies per run in one vectorized batch

    kind = "passivity"
    tuned = ("Kv",)  # and its servo's and update law's own
    family = "6"
    lineup = (  # σ-modification: φ0 = 1.25 ‖φ‖ > ‖φ‖ (6.7.15); sigma-modification.toml's 3 is 1.23 ‖φ‖
        Contender("passivity", "passivity: PID servo + gradient", "Table 6.4.1, Examples 6.4.1, 6.4.3", "Problem 6.4-1",
                  {"kind": "passivity", "Kv": 10.0, "servo": {"kind": "pid", "Lam": 2.5, "Psi": 1.0},
                   "law": {"kind": "gradient", "Gamma": 20.0}}, rank=60),
        Contender("passivity_pi", "passivity: PID servo + Landau PI", "(6.4.20)–(6.4.21)", "Problem 6.4-2",
                  {"kind": "passivity", "Kv": 10.0, "servo": {"kind": "pid", "Lam": 2.5, "Psi": 1.0},
                   "law": {"kind": "landau_pi", "K_I": 20.0, "F_p": 2.0}}, rank=61),
        Contender("sigma", "switching σ-modification", "(6.7.13)–(6.7.14)", "Example 6.3.1; φ0 = 1.25 ‖φ‖",
                  {"kind": "passivity", "Kv": 10.0, "servo": {"kind": "pd", "Lam": 2.5},
                   "law": {"kind": "sigma", "Gamma": 20.0, "phi0": OfTruth(1.25, norm=True)}}, rank=62),
    )

    model: RobotModel
    servo: Servo
    Kv: Any
    law: UpdateLaw
    phi_hat0: Any

    def __post_init__(self) -> None:
        gains(self, ("Kv",), self.model.n)
        estimate(self)
        if not isinstance(self.servo, Servo):
            raise ConfigError(_SERVO, f"expected a servo filter (pd, pid or state_space), got {self.servo!r}")
        if self.servo.n != self.model.n:
            raise ConfigError(_SERVO, f"the servo filter is for {self.servo.n} joints, the robot has {self.model.n}")
        if getattr(self.law, "p", None) != self.model.p:
            raise ConfigError("controller.law", f"expected an update law for the model's {self.model.p} parameters, "
                              f"got {self.law!r}")

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"xi_{i + 1}" for i in range(self.servo.m)) + self.law.state_names(self.model.param_names)

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        """ξ(0) = 0 (for the PID servo ∫₀⁰ e = 0), then the law's state from φ̂(0)."""
        return np.concatenate([np.zeros(self.servo.m), self.law.initial_state(self.phi_hat0)])

    def _split(self, x: Array) -> tuple[Array, Array]:
        m = self.servo.m
        return x[..., :m], x[..., m:]

    def _signals(self, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array, Array]:
        """(Z, r, dξ/dt) of (6.4.1)–(6.4.3) at the given instants."""
        s = self.servo
        e, de = errors(q, dq, ref)
        xi, _ = self._split(x)
        w = e @ s.D.T + xi @ s.C.T
        dxi = xi @ s.A.T + e @ s.B.T
        Z = self.model.regressor(q, dq, ref.dq_des + w, ref.ddq_des + de @ s.D.T + dxi @ s.C.T)
        return Z, de + w, dxi

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """r = ė + G(s) e (6.4.1)."""
        return self._signals(x, q, dq, ref)[1]

    def regressor(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        """(Z, r) of (6.4.3) and (6.4.1), so that M ṙ + V_m r = Z φ − τ."""
        Z, r, _ = self._signals(x, q, dq, ref)
        return Z, r

    def passivity_caveat(self) -> str | None:
        """The law's reason the passivity claim (6.4.4) is not implied for its gains, or None."""
        return self.law.passivity_caveat()

    def phi_hat(self, x: Array) -> Array:
        """The estimate at zero passivity output y = Zᵀ r: φ̂ (gradient, σ), the integral part φ̂_I (Landau PI)."""
        _, xa = self._split(x)
        return self.law.estimate(xa, 0.0 * xa)

    def phi_hat_at(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The φ̂ the torque uses, law.estimate(x_a, Zᵀ r): for the PI law φ̂_I + F_p Zᵀ r (6.4.20)."""
        Z, r, _ = self._signals(x, q, dq, ref)
        return self.law.estimate(self._split(x)[1], matvec(Z.mT, r))

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        Z, r, dxi = self._signals(x, q, dq, ref)
        _, xa = self._split(x)
        y = matvec(Z.mT, r)
        tau = matvec(Z, self.law.estimate(xa, y)) + r @ self.Kv.T
        dxa = self.law.derivative(xa, y)
        # both parts carry the leading axes of x, q, dq and ref: ξ enters dξ/dt directly and y through r
        return tau, array_namespace(dxi, dxa).concatenate([dxi, dxa], axis=-1)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """V = ½ rᵀ M(q) r + law.lyapunov(x_a, φ) with the true φ: (6.4.8) for the gradient law (class docstring)."""
        r = self.filtered_error(t, x, q, dq, ref)
        M = self.model.mass_matrix(q, phi)
        return 0.5 * (r * matvec(M, r)).sum(axis=-1) + self.law.lyapunov(self._split(x)[1], phi)
