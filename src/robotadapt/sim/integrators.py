"""Integrators as option objects: :class:`RK4` (fixed step, default, deterministic, batchable), :class:`SolveIVP` (scipy's
error-controlled solvers, tolerances always explicit) and :class:`Sampled` (sampled-data control: the controller at its
ticks only, zero-order hold on the torque, the plant by RK4 between them; :mod:`robotadapt.sim.sampled`), and the check
that a plant's effects and stiffness suit the integrator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ..plant.plant import Plant
from ..pytree import Module
from ..validation import ConfigError, as_scalar
from .backends import AUTO_MIN_STEPS as AUTO_MIN_STEPS  # importable from here too, as before
from .backends import NotTraceableWarning as NotTraceableWarning
from .backends import check_backend

Array = Any


@dataclass(frozen=True)
class RK4(Module):
    """Classic fixed-step Runge–Kutta 4 with step `dt` (s), stepped by numpy or compiled by JAX
    (:mod:`robotadapt.sim.compiled`) or translated to C (:mod:`robotadapt.native`; the same step, equal to round-off):
    `backend` "auto" (default: compiled unless the run is short, :func:`robotadapt.sim.backends.choose`), "numpy", "jax"
    or "c"."""

    dt: float = 1e-3
    backend: str = "auto"

    def __post_init__(self) -> None:
        object.__setattr__(self, "dt", as_scalar(self.dt, "simulation.dt", positive=True))
        check_backend(self.backend)


@dataclass(frozen=True)
class SolveIVP:
    """Error-controlled integration with `method` ('RK45', 'RK23', 'DOP853', 'Radau', 'BDF', 'LSODA'), explicit
    tolerances, and the result sampled every `dt` seconds: scipy.integrate.solve_ivp (`backend` "auto" or "numpy"), or
    the same explicit Runge–Kutta pair compiled through diffrax ("jax": :mod:`robotadapt.sim.compiled_ivp`; equal to
    scipy's run to the tolerance, not to round-off, which is why "auto" keeps scipy, the reference)."""

    method: str = "RK45"
    rtol: float = 1e-8
    atol: float = 1e-10
    dt: float = 1e-3
    backend: str = "auto"

    def __post_init__(self) -> None:
        known = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
        if self.method not in known:
            raise ConfigError("simulation.method", f"unknown method {self.method!r}; use 'rk4' or one of {known}")
        for name in ("rtol", "atol", "dt"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), f"simulation.{name}", positive=True))
        check_backend(self.backend)
        if self.backend == "c":
            raise ConfigError("simulation.backend", "the C backend runs fixed-step and sampled runs (method = 'rk4'); "
                              "an error-controlled method runs on 'numpy' (scipy) or 'jax' (diffrax)")


DISCRETIZATIONS = ("euler", "hold")
_MAX_SUBSTEPS = 10**6


@dataclass(frozen=True)
class Sampled(Module):
    """Sampled-data control: the controller runs only at t_k = k·Ts (`control_period` Ts, s) and its torque is held
    over [t_k, t_k + Ts) (zero-order hold); the plant is integrated by RK4 with the step `dt` = Ts/m, m whole (default:
    the largest such step ≤ 1 ms). The controller sees the plant through its sensor (:mod:`robotadapt.plant.sensors`; exact
    samples without one); a controller with acceleration feedback gets q̈_m,k = (q̇_m,k − q̇_m,k−1)/Ts, the backward
    difference of the velocities it measured (0 at k = 0); a delay line (the repetitive law) holds T/Ts ticks.

    `discretization` is the rule advancing the controller's state x between ticks, from the samples y_k at t_k:

    - ``"euler"``: x_{k+1} = x_k + Ts·f(t_k, x_k, y_k), forward Euler, what `x += Ts * dx` in a control loop does (a
      law on a manifold, Law.step: its exponential map along f, the natural law);
    - ``"hold"``: x_{k+1} = x(t_k + Ts) of dx/dt = f(t_k, x, y_k) with t, y and the reference held at their samples,
      integrated by RK4 on the plant's sub-steps: the zero-order-hold equivalent (exact for the linear filters of the
      passivity servo and the composite law, up to RK4's error; the same as Euler when f does not depend on x, as for
      the gradient law).

    A projection (Law.project) is applied after each update (each sub-step of "hold"). As Ts → 0 the run tends to
    the continuous-time one, to first order in Ts.
    """

    control_period: float
    dt: Any = None  # the plant's step (s): a float once constructed
    discretization: str = "euler"
    backend: str = "auto"  # as for RK4: "auto", "numpy", "jax" or "c"
    substeps: int = field(init=False)

    def __post_init__(self) -> None:
        Ts = as_scalar(self.control_period, "simulation.control_period", positive=True)
        check_backend(self.backend)
        if not isinstance(self.discretization, str) or self.discretization not in DISCRETIZATIONS:
            raise ConfigError("simulation.discretization", f"expected one of {', '.join(DISCRETIZATIONS)}; got "
                              f"{self.discretization!r}")
        hint = Ts / max(1, math.ceil(Ts / 1e-3 - 1e-9))
        if self.dt is None:
            dt = hint
        else:
            dt = as_scalar(self.dt, "simulation.dt", positive=True)
            if dt > Ts * (1 + 1e-9):
                raise ConfigError("simulation.dt", f"the plant's step {dt:g} s is longer than the control period "
                                  f"{Ts:g} s; use dt = Ts/m, e.g. {hint:.6g}")
            if abs(Ts / dt - round(Ts / dt)) > 1e-6:
                raise ConfigError("simulation.dt", f"the control period {Ts:g} s is not a whole number of plant "
                                  f"steps of {dt:g} s; use dt = Ts/m, e.g. {hint:.6g}")
        substeps = max(1, round(Ts / dt))
        if substeps > _MAX_SUBSTEPS:
            raise ConfigError("simulation.dt", f"{substeps:.3g} plant steps per control period; at most "
                              f"{_MAX_SUBSTEPS:.0e} (use a larger dt)")
        for name, value in (("control_period", Ts), ("dt", Ts / substeps), ("substeps", substeps)):
            object.__setattr__(self, name, value)

    def describe(self) -> dict[str, Any]:
        return {"control_period": self.control_period, "dt": self.dt, "substeps": self.substeps,
                "discretization": self.discretization}



_RK4_STABLE = 2.5  # |λ dt| inside RK4's stability region (2.78 on the real axis, 2.83 on the imaginary one)


def check_plant_step(plant: Plant, integrator: RK4 | SolveIVP | Sampled) -> None:
    """Refuse effects that need control ticks in continuous time, and a fixed step too long for the plant's fastest
    unmodeled dynamics (a motor's electrical pole, a stiff joint), which RK4 would turn into a numerical blow-up."""
    if plant.needs_sampling and not isinstance(integrator, Sampled):
        raise ConfigError("simulation.control_period", "the plant's sensor, torque rate limit and delay act at "
                          "control ticks: set simulation.control_period (sampled-data mode)")
    rate = plant.fastest_rate
    if isinstance(integrator, RK4 | Sampled) and rate * integrator.dt > _RK4_STABLE:
        raise ConfigError("simulation.dt", f"the plant's fastest unmodeled dynamics (rate {rate:.4g} 1/s: motor "
                          f"L/(R + K_c), joint √(K/J)) need a step dt ≤ {_RK4_STABLE / rate:.3g} s, got "
                          f"{integrator.dt:g} s")
