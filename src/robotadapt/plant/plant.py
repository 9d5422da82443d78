"""The true system a controller acts on: a robot model, its true parameters and an additive disturbance (6.7.1),

    τ = M(q) q̈ + V_m(q, q̇) q̇ + G(q) + F(q̇) + T_d(t, q, q̇)

and what the real world adds (each optional, each composable): a payload and elastic joints
(:mod:`robotadapt.plant.unmodeled`), a DC motor per joint, torque and rate limits and a computational delay
(:mod:`robotadapt.plant.actuators`), and the measurement path of a sampled-data controller (:mod:`robotadapt.plant.sensors`).
The true model may differ from the controller's (friction or geometry the controller's model lacks, a URDF truth).

The plant's state is s = [q, q̇, θ, θ̇, i]: θ, θ̇ (motor side) with elastic joints, i (armature currents) with motors.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace, matvec, repeat, rk4, solve
from ..pytree import Module
from ..robots.base import RobotModel
from ..validation import ConfigError, as_scalar, as_vector
from .actuators import Actuator, DCMotor
from .sensors import Sensor
from .unmodeled import ElasticJoint, Payload

Array = Any
Disturbance = Callable[[Array, Array, Array], Array]


@dataclass(frozen=True, eq=False)
class SinusoidalDisturbance(Module):
    """T_d,i(t) = A_i sin(ω t + φ_i) + b_i (Example 6.7.1 uses A = 2, ω = 10 rad/s on both joints)."""

    per_run: ClassVar[tuple[str, ...]] = ("amplitude", "phase", "bias")  # varies per run in one vectorized batch

    amplitude: Array
    omega: float
    phase: Array
    bias: Array

    def __call__(self, t: Array, q: Array, dq: Array) -> Array:
        xp = array_namespace(q)
        tt = xp.asarray(t, dtype=xp.float64)[..., None]
        return self.amplitude * xp.sin(self.omega * tt + self.phase) + self.bias + 0.0 * q

    @property
    def bound(self) -> Array:
        """Component-wise bound sup_t |T_d,i| (what k_d must exceed, 6.7.8)."""
        return np.abs(self.amplitude) + np.abs(self.bias)


def sinusoidal_disturbance(n: int, amplitude: Any = 0.0, omega: Any = 1.0, phase: Any = 0.0,
                           bias: Any = 0.0) -> SinusoidalDisturbance:
    """Validated constructor; `bias` alone gives a constant disturbance (Problem 6.7-1: T_d = [2, 1])."""
    f = "plant.disturbance"
    return SinusoidalDisturbance(as_vector(amplitude, n, f"{f}.amplitude"), as_scalar(omega, f"{f}.omega"),
                                 as_vector(phase, n, f"{f}.phase"), as_vector(bias, n, f"{f}.bias"))


@dataclass(frozen=True, eq=False)
class Plant(Module):
    """`model` with the true parameters `phi` and an optional disturbance `T_d(t, q, q̇)` (torques, shape `(..., n)`);
    optionally a `payload` (φ in `model`'s parameterization changes when it is attached), `elastic_joint`s, a `motor`
    per joint, an `actuator` (limits, delay) and a `sensor` (the measurement path, sampled-data mode only)."""

    per_run: ClassVar[tuple[str, ...]] = ("phi",)  # varies per run in one vectorized batch

    model: RobotModel
    phi: Any
    disturbance: Disturbance | None = None
    payload: Payload | None = None
    elastic_joint: ElasticJoint | None = None
    motor: DCMotor | None = None
    actuator: Actuator | None = None
    sensor: Sensor | None = None
    _phi_loaded: Any = field(init=False, repr=False, metadata={"internal": True})

    stepped_on_host: ClassVar[bool] = False  # stepped by another engine on the host (MuJoCo): the sampled-data loop, numpy

    def __post_init__(self) -> None:
        phi = as_vector(self.phi, self.model.p, "plant.phi", broadcast=False)
        object.__setattr__(self, "phi", phi)
        n = self.model.n
        for name in ("elastic_joint", "motor", "actuator", "sensor"):
            part = getattr(self, name)
            if part is not None and part.n != n:
                raise ConfigError(f"plant.{name}", f"is built for {part.n} joints, the robot has {n}")
        loaded = None if self.payload is None else phi + self.payload.change(self.model)
        object.__setattr__(self, "_phi_loaded", loaded)

    def check_state(self, q: Array) -> None:
        """Raise unless M(q) is positive definite at the initial configuration (negative masses, r = 0, ...)."""
        M = self.model.mass_matrix(np.asarray(q, dtype=float), self.phi)
        eig = np.linalg.eigvalsh(0.5 * (M + np.swapaxes(M, -1, -2)))
        if not np.all(eig > 0):
            names = ", ".join(f"{k}={v:g}" for k, v in zip(self.model.param_names, self.phi, strict=True))
            raise ConfigError("plant.phi", f"the mass matrix is not positive definite at q0 ({names}): "
                              "masses must be positive and the configuration non-singular")

    # -- parameters ---------------------------------------------------------------------------------------------------

    @property
    def varies(self) -> bool:
        """True when the true φ changes during a run (a payload attached after t = 0)."""
        return self.payload is not None and self.payload.time > 0

    def phi_at(self, t: Array) -> Array:
        """The true φ at time(s) `t`: `phi`, plus the payload's change from its attach time on; `t.shape + (p,)` when
        φ varies, else `(p,)`."""
        if self._phi_loaded is None:
            return self.phi
        if not self.varies:
            return self._phi_loaded
        if isinstance(t, float | int):
            return self._phi_loaded if t >= self.payload.time else self.phi  # type: ignore[union-attr]
        xp = array_namespace(t)
        return xp.where(xp.asarray(t)[..., None] >= self.payload.time, self._phi_loaded, self.phi)  # type: ignore[union-attr]

    def truth_for(self, model: RobotModel, t: Array) -> Array | None:
        """φ(t) in `model`'s parameterization (the controller's), or None when `model` is not the plant's own."""
        return self.phi_at(t) if same_model(self.model, model) else None

    # -- dynamics -----------------------------------------------------------------------------------------------------

    @property
    def n_extra(self) -> int:
        """How many states the plant has beyond q, q̇: θ, θ̇ per elastic joint, i per motor."""
        n = self.model.n
        return 2 * n * (self.elastic_joint is not None) + n * (self.motor is not None)

    def extra_series(self, s: Array) -> dict[str, Array]:
        """The extra states of plant states `s` (`(..., 2n + n_extra)`) by name: motor_angle, motor_velocity, current."""
        n, k, out = self.model.n, 2 * self.model.n, {}
        if self.elastic_joint is not None:
            out["motor_angle"], out["motor_velocity"] = s[..., k : k + n], s[..., k + n : k + 2 * n]
            k += 2 * n
        if self.motor is not None:
            out["current"] = s[..., k : k + n]
        return out

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        """s(0) = [q0, q̇0, θ0, θ̇0, i0]: the springs hold the arm against gravity, θ0 = q0 + K⁻¹G(q0), θ̇0 = q̇0;
        the currents start at zero."""
        parts = [q0, dq0]
        if self.elastic_joint is not None:
            parts += [q0 + self.model.gravity(q0, self.phi_at(0.0)) / self.elastic_joint.K, dq0]
        if self.motor is not None:
            parts.append(np.zeros(self.model.n))
        return np.concatenate(parts)

    def saturate(self, tau: Array) -> Array:
        """The torque the plant receives for the command τ in continuous time (the actuator's saturation)."""
        return tau if self.actuator is None else self.actuator.saturate(tau)

    def acceleration(self, t: Array, q: Array, dq: Array, tau: Array) -> Array:
        """q̈ from (6.7.1): M q̈ = τ − V_m q̇ − G − F − T_d (with a rigidly geared motor, M + N²J_m)."""
        if self.disturbance is not None:
            tau = tau - self.disturbance(t, q, dq)
        phi = self.phi_at(t)
        if self.motor is None or self.elastic_joint is not None or not self.motor.has_rotor_inertia:
            return self.model.forward_dynamics(q, dq, tau, phi)
        xp = array_namespace(q, dq, tau)
        bias = matvec(self.model.regressor(q, dq, dq, 0.0 * dq), phi)
        M = self.model.mass_matrix(q, phi) + xp.diag(xp.asarray(self.motor.reflected_inertia))
        return solve(xp, M, tau - bias)

    def derivative(self, t: Array, s: Array, u: Array) -> Array:
        """ds/dt of the plant state s = [q, q̇, θ, θ̇, i] for the applied torque command u (module docstrings of
        :mod:`robotadapt.plant.unmodeled` and :mod:`robotadapt.plant.actuators`)."""
        n = self.model.n
        q, dq = s[..., :n], s[..., n : 2 * n]
        xp = array_namespace(s, u)
        if self.elastic_joint is None and self.motor is None:
            return xp.concatenate([dq, self.acceleration(t, q, dq, u)], axis=-1)
        extra = self.extra_series(s)
        speed = extra["motor_velocity"] if self.elastic_joint is not None else dq
        drive = u if self.motor is None else self.motor.torque(extra["current"])
        if self.elastic_joint is None:
            out = [dq, self.acceleration(t, q, dq, drive)]
        else:
            spring = self.elastic_joint.torque(q, dq, extra["motor_angle"], speed)
            J = self.elastic_joint.J + (0.0 if self.motor is None else self.motor.reflected_inertia)
            out = [dq, self.acceleration(t, q, dq, spring), speed, (drive - spring) / J]
        if self.motor is not None:
            out.append(self.motor.current_rate(u, extra["current"], speed))
        return xp.concatenate(out, axis=-1)

    def advance(self, t: Array, s: Array, u: Array, steps: int, dt: float,
                dynamics: Callable[[Array, Array, Array], Array]) -> Array:
        """The state s at time t after `steps` steps of `dt` with the torque u held (the sampled-data loop's hold):
        classic RK4 of `dynamics(t, s, u)` = ds/dt. A plant stepped by another engine overrides it
        (`stepped_on_host`)."""
        return repeat(array_namespace(s), steps, lambda i, s: rk4(lambda t, s: dynamics(t, s, u), t + i * dt, s, dt), s)

    @property
    def fastest_rate(self) -> float:
        """The fastest known rate of the unmodeled dynamics (1/s): electrical (R + K_c)/L, motor-side √(K/J) + D/J;
        0 for a rigid, directly driven arm. A fixed step must keep `dt · rate` inside RK4's stability region."""
        rates = [0.0]
        if self.motor is not None:
            rates.append(self.motor.rate)
        if self.elastic_joint is not None:
            rates.append(self.elastic_joint.rate(0.0 if self.motor is None else self.motor.reflected_inertia))
        return max(rates)

    @property
    def needs_sampling(self) -> bool:
        """True when an effect is defined only at control ticks: a sensor, a rate limit or a delay."""
        return self.sensor is not None or (self.actuator is not None and self.actuator.needs_sampling)

    def describe(self) -> dict[str, Any]:
        """The real-world effects of this plant, JSON-ready (what a result records in its `info`)."""
        out: dict[str, Any] = {}
        if self.payload is not None:
            out["payload"] = {"mass": self.payload.mass, "offset": self.payload.offset.tolist(),
                              "time": self.payload.time, "phi_loaded": self._phi_loaded.tolist()}
        if self.elastic_joint is not None:
            out["elastic_joint"] = {k: getattr(self.elastic_joint, k).tolist() for k in ("J", "K", "D")}
        for name in ("motor", "actuator", "sensor"):
            part = getattr(self, name)
            if part is not None and part.describe():
                out[name] = part.describe()
        return out


def same_model(a: RobotModel, b: RobotModel) -> bool:
    """True when `a` and `b` are the same model: the same object, or the same class with equal fields."""
    if a is b:
        return True
    if type(a) is not type(b) or a.param_names != b.param_names or not is_dataclass(a):
        return False
    return all(_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))


def _equal(x: Any, y: Any) -> bool:
    if x is y:
        return True
    if isinstance(x, np.ndarray | float | int | tuple | list) and not isinstance(x, bool):
        try:
            return bool(np.array_equal(x, y))
        except (TypeError, ValueError):
            return False
    try:
        return bool(x == y)
    except (TypeError, ValueError):
        return False
