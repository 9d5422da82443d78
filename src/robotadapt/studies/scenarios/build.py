"""From a scenario's sections to library objects: robot, plant, trajectory, controller, integrator.

Each `kind` maps to a constructor; the keys a section may hold are the constructor's own parameter names, so an unknown
key is an error that lists the known ones, and a missing required key names itself.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from dataclasses import MISSING, dataclass, fields, is_dataclass
from functools import cache
from typing import Any

import numpy as np

from ...plant.actuators import Actuator, DCMotor
from ...plant.plant import Plant, sinusoidal_disturbance
from ...plant.sensors import Sensor
from ...plant.unmodeled import ElasticJoint, Payload
from ...robots import RobotModel
from ...sim.integrators import RK4, Sampled, SolveIVP, check_backend
from ...validation import ConfigError, as_scalar, as_vector, check_names

# kind → "module:attribute" (imported on use, so optional parts cost nothing until named) and what the constructor
# takes first: the robot model, the joint count n, the parameter count p, or nothing.
REGISTRY: dict[str, dict[str, tuple[str, str | None]]] = {
    "robot": {
        "one_link": ("robots.one_link:OneLinkArm", None),
        "two_link": ("robots.two_link:TwoLinkArm", None),
        "polar": ("robots.polar:PolarArm", None),
        "planar": ("robots.catalog:planar", None),
        "dh": ("robots.catalog:dh_arm", None),
        "puma560": ("robots.catalog:puma560_arm", None),
        "urdf": ("robots.catalog:urdf_arm", None),
        "example_robot": ("robots.catalog:example_arm", None),
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
# other names of a kind: the same constructor (the book calls Slotine–Li's law the inertia-related one, Table 6.3.1)
ALIASES: dict[str, dict[str, str]] = {"controller": {"inertia_related": "slotine_li"}}
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
    integrator: RK4 | SolveIVP | Sampled
    q0: np.ndarray
    dq0: np.ndarray
    log_every: int
    max_state: float


def _params(ctor: Callable[..., Any], first: str | None) -> dict[str, bool]:
    """The constructor's keyword names (less its first argument) → whether each is required."""
    return dict(_signature(ctor, first))


@cache  # inspecting a signature costs more than building the object: once per constructor
def _signature(ctor: Callable[..., Any], first: str | None) -> dict[str, bool]:
    if is_dataclass(ctor):
        names = {f.name: f.default is MISSING and f.default_factory is MISSING for f in fields(ctor)
                 if not f.metadata.get("internal")}
    else:
        sig = inspect.signature(ctor)
        names = {k: p.default is inspect.Parameter.empty for k, p in sig.parameters.items()}
    if first is not None:
        names.pop(next(iter(names)))
    return names


def canonical_kind(registry: str, kind: Any) -> Any:
    """The registry's own name of `kind` (`inertia_related` → `slotine_li`); any other value as it is."""
    return ALIASES.get(registry, {}).get(kind, kind) if isinstance(kind, str) else kind


def build(registry: str, section: Any, name: str, model: RobotModel | None = None) -> Any:
    """Call the constructor that `section['kind']` names in `REGISTRY[registry]` with the section's other keys; nested
    tables (servo, law, base) are built first. `phi_hat0` defaults to zeros."""
    table = REGISTRY[registry]
    if not isinstance(section, dict):
        raise ConfigError(name, f"expected a table with a kind ({', '.join(sorted(table))}), got {section!r}")
    kind = canonical_kind(registry, section.get("kind"))
    if not isinstance(kind, str) or kind not in table:
        known = sorted([*table, *ALIASES.get(registry, {})])
        raise ConfigError(f"{name}.kind", f"expected one of {', '.join(known)}; got {section.get('kind')!r}")
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


# [plant] keys beyond the true parameters, the initial state and the disturbance: flat keys of the actuator and the
# sensor (`plant.torque_limit = 5`), the payload, and tables for the true model, elastic joints and motors
PAYLOAD = {"payload": "mass", "payload_offset": "offset", "payload_time": "time"}
PLANT_TABLES = {"elastic_joint": ElasticJoint, "motor": DCMotor}


def _part(ctor: Callable[..., Any], values: dict[str, Any], n: int) -> Any:
    """`ctor(n, **values)`, or None when no value is given."""
    return ctor(n, **values) if values else None


def _table(section: dict[str, Any], key: str, n: int) -> Any:
    """The elastic joint or motor of `[plant.KEY]`, or None."""
    if key not in section:
        return None
    ctor, table = PLANT_TABLES[key], section[key]
    params = _params(ctor, "n")
    if not isinstance(table, dict):
        raise ConfigError(f"plant.{key}", f"expected a table with {', '.join(params)}, got {table!r}")
    check_names(list(table), list(params), f"plant.{key}")
    for name, required in params.items():
        if required and name not in table:
            raise ConfigError(f"plant.{key}.{name}", f"missing; [plant.{key}] takes {', '.join(params)}")
    return ctor(n, **table)


def plant(section: dict[str, Any], model: RobotModel) -> tuple[Plant, np.ndarray, np.ndarray]:
    """The true plant: `robot` (a table like [robot], default the controller's model) with `phi` in its
    parameterization, `q0`, `dq0`, `disturbance`; a payload (`payload` kg at `payload_offset`, from `payload_time`); the
    actuator's and the sensor's keys; `[plant.elastic_joint]` and `[plant.motor]` tables."""
    if not isinstance(section, dict):
        raise ConfigError("plant", "expected a table with phi, q0, dq0 and optionally disturbance")
    actuator_keys, sensor_keys = list(_params(Actuator, "n")), list(_params(Sensor, "n"))
    check_names(list(section), ["phi", "q0", "dq0", "disturbance", "robot", *PAYLOAD, *actuator_keys, *sensor_keys,
                                *PLANT_TABLES], "plant")
    truth = model
    if "robot" in section:
        truth = build("robot", section["robot"], "plant.robot")
        if truth.n != model.n:
            raise ConfigError("plant.robot", f"has {truth.n} joints, the controller's robot {model.n}")
    if "phi" not in section:
        if truth.default_phi is None:
            raise ConfigError("plant.phi", f"missing: the true parameters {', '.join(truth.param_names)}")
        section = dict(section, phi=truth.default_phi)  # the model's own (published or URDF) parameters
    dist = section.get("disturbance")
    if dist is not None:
        if not isinstance(dist, dict):
            raise ConfigError("plant.disturbance", "expected a table with amplitude, omega, phase, bias")
        check_names(list(dist), ["amplitude", "omega", "phase", "bias"], "plant.disturbance")
        dist = sinusoidal_disturbance(model.n, **dist)
    phi = as_vector(section["phi"], truth.p, "plant.phi", broadcast=False)
    q0 = as_vector(section.get("q0", 0.0), model.n, "plant.q0")
    dq0 = as_vector(section.get("dq0", 0.0), model.n, "plant.dq0")
    payload = {arg: section[key] for key, arg in PAYLOAD.items() if key in section}
    if payload and "mass" not in payload:
        raise ConfigError("plant.payload", "missing: the payload's mass (kg) for payload_offset / payload_time")
    n = model.n
    return Plant(truth, phi, dist, Payload(**payload) if payload else None, _table(section, "elastic_joint", n),
                 _table(section, "motor", n), _part(Actuator, {k: section[k] for k in actuator_keys if k in section}, n),
                 _part(Sensor, {k: section[k] for k in sensor_keys if k in section}, n)), q0, dq0


def simulation(section: dict[str, Any]) -> tuple[float, RK4 | SolveIVP | Sampled, int, float]:
    """t_final, the integrator (RK4, a solve_ivp method, or sampled-data control with `control_period`), log_every,
    max_state."""
    if not isinstance(section, dict):
        raise ConfigError("simulation", "expected a table with t_final, dt, method")
    check_names(list(section), ["t_final", "dt", "method", "backend", "rtol", "atol", "log_every", "max_state",
                                "control_period", "discretization"], "simulation")
    backend = check_backend(section.get("backend", "auto"))
    if backend == "jax" and str(section.get("method", "rk4")).lower() != "rk4":
        raise ConfigError("simulation.backend", "the compiled backend steps the fixed-step 'rk4' (continuous or "
                          "sampled-data); solve_ivp methods run on numpy: drop backend or use method = 'rk4'")
    if "t_final" not in section:
        raise ConfigError("simulation.t_final", "missing: the simulated time in seconds")
    t_final = as_scalar(section["t_final"], "simulation.t_final", positive=True)
    method = section.get("method", "rk4")
    if not isinstance(method, str):
        raise ConfigError("simulation.method", f"expected a name such as 'rk4' or 'RK45', got {method!r}")
    integ: RK4 | SolveIVP | Sampled
    if "control_period" in section:
        if method.lower() != "rk4":
            raise ConfigError("simulation.method", "sampled-data control integrates the plant with 'rk4' between "
                              f"control ticks, got {method!r}")
        if "rtol" in section or "atol" in section:
            raise ConfigError("simulation.rtol", "tolerances apply to solve_ivp methods, not to sampled-data control")
        integ = Sampled(section["control_period"], section.get("dt"), section.get("discretization", "euler"), backend)
        if integ.control_period > t_final:
            raise ConfigError("simulation.control_period", f"the control period {integ.control_period:g} s is longer "
                              f"than t_final = {t_final:g} s")
    else:
        if "discretization" in section:
            raise ConfigError("simulation.discretization", "applies to sampled-data control: set "
                              "simulation.control_period")
        dt = as_scalar(section.get("dt", 1e-3), "simulation.dt", positive=True)
        if dt > t_final:
            raise ConfigError("simulation.dt", f"the step {dt:g} s is longer than t_final = {t_final:g} s")
        if method.lower() == "rk4":
            if "rtol" in section or "atol" in section:
                raise ConfigError("simulation.rtol", "tolerances apply to solve_ivp methods, not to the fixed-step 'rk4'")
            integ = RK4(dt, backend)
        else:
            integ = SolveIVP(method, section.get("rtol", 1e-8), section.get("atol", 1e-10), dt)
    log_every = section.get("log_every", 1)
    if isinstance(log_every, bool) or not isinstance(log_every, int) or log_every < 1:
        raise ConfigError("simulation.log_every", f"expected a positive whole number, got {log_every!r}")
    max_state = as_scalar(section.get("max_state", 1e6), "simulation.max_state", positive=True)
    return t_final, integ, log_every, max_state


def _estimate(section: Any, the_plant: Plant, model: RobotModel) -> Any:
    """`phi_hat0 = {scale = s}` in [controller]: s × the true value of each of the controller's parameters, e.g. 0.7
    for an estimate 30 % low on all of them (n-DOF arms, whose φ has tens of entries). The true values are the plant's
    entries of the same names, so the plant's robot may add parameters (friction) the controller's lacks."""
    if isinstance(section, dict) and isinstance(section.get("base"), dict):  # the law a robust one wraps
        section = dict(section, base=_estimate(section["base"], the_plant, model))
    value = section.get("phi_hat0") if isinstance(section, dict) else None
    if not isinstance(value, dict):
        return section
    check_names(list(value), ["scale"], "controller.phi_hat0")
    if "scale" not in value:
        raise ConfigError("controller.phi_hat0.scale", "missing: phi_hat0 = {scale = 0.7} starts at 0.7 × plant.phi")
    truth = dict(zip(the_plant.model.param_names, the_plant.phi, strict=True))
    missing = [name for name in model.param_names if name not in truth]
    if missing:
        raise ConfigError("controller.phi_hat0", f"a scale of the true parameters needs the plant's robot to have the "
                          f"controller's parameters; it lacks {', '.join(missing[:5])}: give phi_hat0 as a list")
    scale = as_scalar(value["scale"], "controller.phi_hat0.scale")
    return dict(section, phi_hat0=[scale * float(truth[name]) for name in model.param_names])


def setup(data: dict[str, Any]) -> Setup:
    """Build every object of a scenario (already parsed TOML), validating each field once."""
    for name in ("robot", "plant", "trajectory", "controller", "simulation"):
        if name not in data:
            raise ConfigError(name, f"missing section [{name}]")
    model = robot(data["robot"])
    the_plant, q0, dq0 = plant(data["plant"], model)
    t_final, integ, log_every, max_state = simulation(data["simulation"])
    controller = build("controller", _estimate(data["controller"], the_plant, model), "controller", model)
    return Setup(the_plant, controller,
                 build("trajectory", data["trajectory"], "trajectory", model), t_final, integ, q0, dq0, log_every,
                 max_state)
