"""Integrators as option objects: :class:`RK4` (fixed step, default, deterministic, batchable), :class:`SolveIVP` (scipy's
error-controlled solvers, tolerances always explicit) and :class:`Sampled` (sampled-data control: the controller at its
ticks only, zero-order hold on the torque, the plant by RK4 between them; :mod:`robotadapt.sim.sampled`), and the check
that a plant's effects and stiffness suit the integrator.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from ..plant.plant import Plant
from ..validation import ConfigError, as_scalar

Array = Any
T = TypeVar("T")


BACKENDS = ("auto", "numpy", "jax", "c")
AUTO_MIN_STEPS = 2000  # "auto" compiles a run of at least this many steps (steps × runs for a batch): below it the
# numpy loop (≈0.3 ms a step on the two-link arm) finishes before a warm program is traced and loaded (≈0.5 s)


def check_backend(backend: Any) -> str:
    """A valid `simulation.backend` name, else a one-line ConfigError naming the field."""
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise ConfigError("simulation.backend", f"expected one of {', '.join(BACKENDS)}; got {backend!r}")
    if backend == "c":
        from ..native.build import require_compiler

        require_compiler("simulation.backend")
    return backend


def choose_backend(backend: str, steps: int, traceable: bool, single: bool = False) -> str:
    """The backend a run takes: "numpy", "jax" or "c" as asked; "auto" compiles a loop whose models are traceable when
    it has at least `AUTO_MIN_STEPS` steps, and steps it with numpy otherwise. A `single` run compiles to C where a C
    compiler is present (one native call per chunk, no JAX to import once its program is stored), a batch with JAX."""
    if backend != "auto":
        return backend
    if not traceable or steps < AUTO_MIN_STEPS:
        return "numpy"
    from ..native.build import compiler

    return "c" if single and compiler() is not None else "jax"


class NotTraceableWarning(UserWarning):
    """Under `backend = "auto"`, a law or model JAX could not trace was stepped with numpy instead (slower, same
    numbers), or a program the C translator lacks a primitive of was compiled with JAX; docs/tutorial.md#traceable says
    what tracing needs and how to check a law."""


def run_on(asked: str, backend: str, run: Callable[[str], T]) -> tuple[T, str]:
    """`run(backend)` and the backend it ran on. Under "auto", a program the C translator lacks a primitive of (a
    ConfigError naming `native`) runs with JAX, and a program JAX cannot trace (a ConfigError naming
    `simulation.backend`, e.g. a user's law written with numpy calls) with numpy, each with a warning saying why; a
    backend asked for by name fails with the error."""
    try:
        return run(backend), backend
    except ConfigError as exc:
        if asked != "auto" or backend == "numpy" or exc.field not in ("simulation.backend", "native"):
            raise
        if exc.field == "native":
            warnings.warn(f"{exc.reason.split(':')[0]}; compiled with JAX instead (simulation.backend = 'auto')",
                          NotTraceableWarning, stacklevel=3)
            return run_on(asked, "jax", run)
        why = exc.reason.removesuffix("; use backend = 'numpy'")
        warnings.warn(f"{why}; stepped with numpy instead (simulation.backend = 'auto'): slower, same numbers — "
                      "docs/tutorial.md#traceable", NotTraceableWarning, stacklevel=3)
        return run("numpy"), "numpy"


@dataclass(frozen=True)
class RK4:
    """Classic fixed-step Runge–Kutta 4 with step `dt` (s), stepped by numpy or compiled by JAX
    (:mod:`robotadapt.sim.compiled`) or translated to C (:mod:`robotadapt.native`; the same step, equal to round-off):
    `backend` "auto" (default: compiled unless the run is short, :func:`choose_backend`), "numpy", "jax" or "c"."""

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
class Sampled:
    """Sampled-data control: the controller runs only at t_k = k·Ts (`control_period` Ts, s) and its torque is held
    over [t_k, t_k + Ts) (zero-order hold); the plant is integrated by RK4 with the step `dt` = Ts/m, m whole (default:
    the largest such step ≤ 1 ms). The controller sees the plant through its sensor (:mod:`robotadapt.plant.sensors`; exact
    samples without one); a controller with acceleration feedback gets q̈_m,k = (q̇_m,k − q̇_m,k−1)/Ts, the backward
    difference of the velocities it measured (0 at k = 0); a delay line (the repetitive law) holds T/Ts ticks.

    `discretization` is the rule advancing the controller's state x between ticks, from the samples y_k at t_k:

    - ``"euler"``: x_{k+1} = x_k + Ts·f(t_k, x_k, y_k), forward Euler, what `x += Ts * dx` in a control loop does (a
      law on a manifold, HasStep: its exponential map along f, the natural law);
    - ``"hold"``: x_{k+1} = x(t_k + Ts) of dx/dt = f(t_k, x, y_k) with t, y and the reference held at their samples,
      integrated by RK4 on the plant's sub-steps: the zero-order-hold equivalent (exact for the linear filters of the
      passivity servo and the composite law, up to RK4's error; the same as Euler when f does not depend on x, as for
      the gradient law).

    A projection (HasProjection) is applied after each update (each sub-step of "hold"). As Ts → 0 the run tends to
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
