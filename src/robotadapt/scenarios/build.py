"""From a scenario's sections to library objects: robot, plant, trajectory, controller, integrator.

Each `kind` maps to a constructor; the keys a section may hold are the constructor's own parameter names, so an unknown
key is an error that lists the known ones, and a missing required key names itself.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from dataclasses import MISSING, dataclass, fields, is_dataclass
from typing import Any

import numpy as np

from ..plant import Plant, sinusoidal_disturbance
from ..robots import RobotModel
from ..simulation import RK4, SolveIVP
from ..validation import ConfigError, as_scalar, as_vector, check_names

# kind → "module:attribute" (imported on use, so optional parts cost nothing until named) and what the constructor
# takes first: the robot model, the joint count n, the parameter count p, or nothing.
REGISTRY: dict[str, dict[str, tuple[str, str | None]]] = {
    "robot": {
        "one_link": ("robots.one_link:OneLinkArm", None),
        "two_link": ("robots.two_link:TwoLinkArm", None),
        "polar": ("robots.polar:PolarArm", None),
        "planar": ("robots.symbolic:planar_arm", None),
        "dh": ("robots.symbolic:from_dh_table", None),
        "puma560": ("robots.symbolic:puma560", None),
        "urdf": ("robots.pinocchio:PinocchioArm.from_urdf", None),
        "example_robot": ("robots.pinocchio:PinocchioArm.example", None),
    },
    "trajectory": {
        "sinusoid": ("trajectories:sinusoid", "n"),
        "sum_of_sines": ("trajectories:SumOfSines.make", "n"),
        "exponential_step": ("trajectories:exponential_step", "n"),
        "quintic": ("trajectories:quintic", "n"),
        "constant": ("trajectories:constant", "n"),
    },
    "controller": {
        "slotine_li": ("controllers.inertia_related:InertiaRelated", "model"),
        "computed_torque": ("controllers.baseline:ComputedTorque", "model"),
        "pd": ("controllers.baseline:PD", "model"),
        "pd_gravity": ("controllers.baseline:PDGravity", "model"),
        "adaptive_computed_torque": ("controllers.computed_torque:AdaptiveComputedTorque", "model"),
        "passivity": ("controllers.passivity:PassivityBased", "model"),
        "composite": ("controllers.composite:Composite", "model"),
        "sign_robust": ("controllers.robust:SignRobust", "model"),
        "dcal": ("controllers.dcal:DCAL", "model"),
        "repetitive": ("controllers.repetitive:Repetitive", "model"),
    },
    "servo": {
        "pd": ("controllers.passivity:pd_servo", "n"),
        "pid": ("controllers.passivity:pid_servo", "n"),
        "state_space": ("controllers.passivity:state_space_servo", "n"),
    },
    "law": {
        "gradient": ("adaptation:Gradient", "p"),
        "landau_pi": ("adaptation:LandauPI", "p"),
        "sigma": ("adaptation:SwitchingSigma", "p"),
    },
}
# keys whose value is itself a table with a kind, and the registry it names
NESTED = {"servo": "servo", "law": "law", "base": "controller"}
# the field prefix each registry's constructors write in their errors (rewritten to the nested path when nested)
CANONICAL = {"robot": "robot", "trajectory": "trajectory", "controller": "controller", "servo": "controller.servo",
             "law": "controller.law"}
FIRST_ARG = {"model": "model", "n": "n", "p": "p"}


def _resolve(target: str) -> Callable[..., Any]:
    module, _, attr = target.partition(":")
    obj: Any = importlib.import_module(f"robotadapt.{module}")
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


@dataclass(frozen=True, eq=False)
class Setup:
    """Everything `simulate` needs, built from a scenario."""

    plant: Plant
    controller: Any
    trajectory: Any
    t_final: float
    integrator: RK4 | SolveIVP
    q0: np.ndarray
    dq0: np.ndarray
    log_every: int
    max_state: float


def _params(ctor: Callable[..., Any], first: str | None) -> dict[str, bool]:
    """The constructor's keyword names (less its first argument) → whether each is required."""
    if is_dataclass(ctor):
        names = {f.name: f.default is MISSING and f.default_factory is MISSING for f in fields(ctor)
                 if not f.metadata.get("internal")}
    else:
        sig = inspect.signature(ctor)
        names = {k: p.default is inspect.Parameter.empty for k, p in sig.parameters.items()}
    if first is not None:
        names.pop(next(iter(names)))
    return names


def build(registry: str, section: Any, name: str, model: RobotModel | None = None) -> Any:
    """Call the constructor that `section['kind']` names in `REGISTRY[registry]` with the section's other keys; nested
    tables (servo, law, base) are built first. `phi_hat0` defaults to zeros."""
    table = REGISTRY[registry]
    if not isinstance(section, dict):
        raise ConfigError(name, f"expected a table with a kind ({', '.join(sorted(table))}), got {section!r}")
    kind = section.get("kind")
    if not isinstance(kind, str) or kind not in table:
        raise ConfigError(f"{name}.kind", f"expected one of {', '.join(sorted(table))}; got {kind!r}")
    target, first = table[kind]
    ctor = _resolve(target)
    params = _params(ctor, first)
    keys = {k: v for k, v in section.items() if k != "kind"}
    check_names(list(keys), list(params), name)
    if "phi_hat0" in params and model is not None:
        keys.setdefault("phi_hat0", np.zeros(model.p))
    for key, required in params.items():
        if required and key not in keys:
            raise ConfigError(f"{name}.{key}", f"missing; kind {kind!r} takes {', '.join(params)}")
    for key in NESTED.keys() & keys.keys():
        keys[key] = build(NESTED[key], keys[key], f"{name}.{key}", model)
    args = () if first is None else ({"model": model, "n": model.n, "p": model.p}[first],)  # type: ignore[union-attr]
    try:
        return ctor(*args, **keys)
    except ConfigError as exc:  # "controller.Kv" raised by a nested base is "controller.base.Kv" here
        root = CANONICAL[registry]
        if name == root or not (exc.field == root or exc.field.startswith(root + ".")):
            raise
        raise ConfigError(name + exc.field[len(root):], exc.reason) from None


def robot(section: Any) -> RobotModel:
    return build("robot", section, "robot")


def plant(section: dict[str, Any], model: RobotModel) -> tuple[Plant, np.ndarray, np.ndarray]:
    if not isinstance(section, dict):
        raise ConfigError("plant", "expected a table with phi, q0, dq0 and optionally disturbance")
    check_names(list(section), ["phi", "q0", "dq0", "disturbance"], "plant")
    if "phi" not in section:
        if model.default_phi is None:
            raise ConfigError("plant.phi", f"missing: the true parameters {', '.join(model.param_names)}")
        section = dict(section, phi=model.default_phi)  # the model's own (published or URDF) parameters
    dist = section.get("disturbance")
    if dist is not None:
        if not isinstance(dist, dict):
            raise ConfigError("plant.disturbance", "expected a table with amplitude, omega, phase, bias")
        check_names(list(dist), ["amplitude", "omega", "phase", "bias"], "plant.disturbance")
        dist = sinusoidal_disturbance(model.n, **dist)
    phi = as_vector(section["phi"], model.p, "plant.phi", broadcast=False)
    q0 = as_vector(section.get("q0", 0.0), model.n, "plant.q0")
    dq0 = as_vector(section.get("dq0", 0.0), model.n, "plant.dq0")
    return Plant(model, phi, dist), q0, dq0


def simulation(section: dict[str, Any]) -> tuple[float, RK4 | SolveIVP, int, float]:
    if not isinstance(section, dict):
        raise ConfigError("simulation", "expected a table with t_final, dt, method")
    check_names(list(section), ["t_final", "dt", "method", "rtol", "atol", "log_every", "max_state"], "simulation")
    if "t_final" not in section:
        raise ConfigError("simulation.t_final", "missing: the simulated time in seconds")
    t_final = as_scalar(section["t_final"], "simulation.t_final", positive=True)
    dt = as_scalar(section.get("dt", 1e-3), "simulation.dt", positive=True)
    if dt > t_final:
        raise ConfigError("simulation.dt", f"the step {dt:g} s is longer than t_final = {t_final:g} s")
    method = section.get("method", "rk4")
    if not isinstance(method, str):
        raise ConfigError("simulation.method", f"expected a name such as 'rk4' or 'RK45', got {method!r}")
    if method.lower() == "rk4":
        if "rtol" in section or "atol" in section:
            raise ConfigError("simulation.rtol", "tolerances apply to solve_ivp methods, not to the fixed-step 'rk4'")
        integ: RK4 | SolveIVP = RK4(dt)
    else:
        integ = SolveIVP(method, section.get("rtol", 1e-8), section.get("atol", 1e-10), dt)
    log_every = section.get("log_every", 1)
    if isinstance(log_every, bool) or not isinstance(log_every, int) or log_every < 1:
        raise ConfigError("simulation.log_every", f"expected a positive whole number, got {log_every!r}")
    max_state = as_scalar(section.get("max_state", 1e6), "simulation.max_state", positive=True)
    return t_final, integ, log_every, max_state


def setup(data: dict[str, Any]) -> Setup:
    """Build every object of a scenario (already parsed TOML), validating each field once."""
    for name in ("robot", "plant", "trajectory", "controller", "simulation"):
        if name not in data:
            raise ConfigError(name, f"missing section [{name}]")
    model = robot(data["robot"])
    the_plant, q0, dq0 = plant(data["plant"], model)
    t_final, integ, log_every, max_state = simulation(data["simulation"])
    return Setup(the_plant, build("controller", data["controller"], "controller", model),
                 build("trajectory", data["trajectory"], "trajectory", model), t_final, integ, q0, dq0, log_every,
                 max_state)
