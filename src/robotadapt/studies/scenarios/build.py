"""From a scenario's sections to library objects: robot, plant, trajectory, controller, integrator.

Each `kind` maps to a constructor; the keys a section may hold are the constructor's own parameter names, so an unknown
key is an error that lists the known ones, and a missing required key names itself.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import json
import os
import sys
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from ...controllers.registry import aliases as law_aliases
from ...controllers.registry import registered
from ...plant.actuators import Actuator, DCMotor
from ...plant.mujoco import MujocoPlant, with_options
from ...plant.plant import Plant, sinusoidal_disturbance
from ...plant.sensors import Sensor
from ...plant.unmodeled import ElasticJoint, Payload
from ...robots import RobotModel
from ...robots.workspace import inverse_kinematics, reach
from ...sim.integrators import RK4, Sampled, SolveIVP, check_backend
from ...task_trajectories import reach_check
from ...validation import ConfigError, as_array, as_scalar, as_vector, check_names

# kind → "module:attribute" (imported on use, so optional parts cost nothing until named) and what the constructor
# takes first (the robot model, the joint count n, the parameter count p, or nothing), for the kinds that are not laws;
# a law and an update law declare their kind in their own class (robotadapt.controllers.registry: LAWS)
TARGETS: dict[str, dict[str, tuple[str, str | None]]] = {
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
        "sum_of_sines": ("trajectories:sum_of_sines", "n"),
        "fourier": ("trajectories:fourier", "n"),
        "exponential_step": ("trajectories:exponential_step", "n"),
        "quintic": ("trajectories:quintic", "n"),
        "constant": ("trajectories:constant", "n"),
        # the hand's path, for a task-space law (docs/task-space.md); a sum of sines there has one sine per coordinate
        "circle": ("task_trajectories:Circle", None),
        "figure_eight": ("task_trajectories:FigureEight", None),
        "line": ("task_trajectories:Line", None),
    },
    "servo": {
        "pd": ("controllers.passivity:pd_servo", "n"),
        "pid": ("controllers.passivity:pid_servo", "n"),
        "state_space": ("controllers.passivity:state_space_servo", "n"),
    },
}
#: the registries whose kinds register themselves, their classes' `kind` and `aliases`
LAWS = ("controller", "law")
#: every registry, in the order of docs/keys.md
REGISTRIES = ("robot", "trajectory", "controller", "servo", "law")
# keys whose value is itself a table with a kind, and the registry it names
NESTED = {"servo": "servo", "law": "law", "base": "controller"}
# the field prefix each registry's constructors write in their errors (rewritten to the nested path when nested)
CANONICAL = {"robot": "robot", "trajectory": "trajectory", "controller": "controller", "servo": "controller.servo",
             "law": "controller.law"}
FIRST_ARG = {"model": "model", "n": "n", "p": "p"}


# what a user's constructor (`kind = "module:attribute"`) takes first, by registry: as the packaged kinds do
USER_FIRST: dict[str, str | None] = {"robot": None, "trajectory": "n", "controller": "model", "servo": "n", "law": "p"}


def _resolve(target: str) -> Callable[..., Any]:
    module, _, attr = target.partition(":")
    obj: Any = importlib.import_module(f"robotadapt.{module}")
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def _user_module(module: str, name: str) -> Any:
    """The module of a user's `kind = "module:attribute"`: importable from the Python path, or a `module.py` file in the
    current folder (the console script `robotadapt` does not put the folder on the path)."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        local = Path.cwd() / f"{module}.py"
        if exc.name != module.partition(".")[0] or "." in module or not local.is_file():
            raise ConfigError(name, f"cannot import {module!r} ({exc}): install it, add its folder to PYTHONPATH or "
                              f"run from the folder that holds {module.split('.')[0]}.py") from None
    if module not in sys.modules:  # loaded once per process, under its own name (so its objects pickle by reference)
        spec = importlib.util.spec_from_file_location(module, local)
        loaded = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
        sys.modules[module] = loaded
        try:
            spec.loader.exec_module(loaded)  # type: ignore[union-attr]
        except BaseException:
            del sys.modules[module]
            raise
    return sys.modules[module]


def kinds(registry: str) -> list[str]:
    """The kinds `registry` knows by name, in order: a law's (`LAWS`) every registered one (a user's module's too, once
    imported), the others those of `TARGETS`."""
    return list(registered(registry)) if registry in LAWS else list(TARGETS[registry])


def aliases(registry: str) -> dict[str, str]:
    """Other name → kind (`inertia_related` → `slotine_li`: the book calls Slotine–Li's law the inertia-related one,
    Table 6.3.1), from the laws' `aliases`."""
    return law_aliases(registry) if registry in LAWS else {}


def constructor(registry: str, kind: Any, name: str) -> tuple[Callable[..., Any], str | None]:
    """The constructor `kind` names in `registry` and what it takes first (the model, n, p or nothing): a packaged kind
    (:func:`kinds`, or an alias), or a user's `"module:attribute"` (a class or function of an importable module, e.g.
    `"deadzone:DeadZoneSlotineLi"`, taking first what the registry's packaged kinds take, `USER_FIRST`; docs/tutorial.md).
    `name` is the field an error names (`controller.kind`)."""
    kind = canonical_kind(registry, kind)
    if registry in LAWS:
        law = registered(registry).get(kind) if isinstance(kind, str) else None
        if law is not None:
            return law, law.first
    elif isinstance(kind, str) and kind in TARGETS[registry]:
        target, first = TARGETS[registry][kind]
        return _resolve(target), first
    if not (isinstance(kind, str) and kind.count(":") == 1 and all(kind.split(":"))):
        known = sorted([*kinds(registry), *aliases(registry)])
        raise ConfigError(name, f"expected one of {', '.join(known)}, or \"module:Class\" for your own; got {kind!r}")
    module, attr = kind.split(":")
    obj: Any = _user_module(module, name)
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ConfigError(name, f"module {module!r} has no {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise ConfigError(name, f"{kind!r} is not a class or function")
    return obj, USER_FIRST[registry]


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
    data: dict[str, Any] = field(default_factory=dict)  # the scenario with every value used written out


REQUIRED = inspect.Parameter.empty  # the default of a key that has none


def _params(ctor: Callable[..., Any], first: str | None) -> dict[str, bool]:
    """The constructor's keyword names (less its first argument) → whether each is required."""
    return {k: v is REQUIRED for k, v in _signature(ctor, first).items()}


@cache  # inspecting a signature costs more than building the object: once per constructor
def _signature(ctor: Callable[..., Any], first: str | None) -> dict[str, Any]:
    """The constructor's keyword names (less its first argument) → default value, or REQUIRED."""
    if is_dataclass(ctor):
        names = {f.name: f.default if f.default is not MISSING else
                 f.default_factory() if f.default_factory is not MISSING else REQUIRED
                 for f in fields(ctor) if f.init and not f.metadata.get("internal")}
    else:
        sig = inspect.signature(ctor)
        names = {k: p.default for k, p in sig.parameters.items()}
    if first is not None:
        names.pop(next(iter(names)))
    return names


def keys(registry: str, kind: str) -> dict[str, Any]:
    """The keys a `kind` of `registry` takes → default (REQUIRED when it has none): the constructor's signature."""
    ctor, first = constructor(registry, kind, f"{registry}.kind")
    return dict(_signature(ctor, first))


def plain(value: Any) -> Any:
    """`value` as TOML can write it (arrays and tuples as lists, numpy numbers as floats), or None when it cannot."""
    if isinstance(value, np.ndarray | tuple | list):
        items = [plain(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
        return None if any(v is None for v in items) else items
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    return None


def _with_defaults(section: dict[str, Any], defaults: dict[str, Any]) -> dict[str, Any]:
    """`section` with every default it leaves out that TOML can write (None defaults stay out: they mean "none")."""
    out = dict(section)
    for key, default in defaults.items():
        if key not in out and default is not REQUIRED and plain(default) is not None:
            out[key] = plain(default)
    return out


def canonical_kind(registry: str, kind: Any) -> Any:
    """The registry's own name of `kind` (`inertia_related` → `slotine_li`); any other value as it is."""
    return aliases(registry).get(kind, kind) if isinstance(kind, str) else kind


def _names(names: tuple[str, ...] | list[str], shown: int = 8) -> str:
    """Parameter names in order, or the first few and where the whole order is listed."""
    if len(names) <= shown:
        return ", ".join(names)
    return f"{', '.join(names[:shown - 2])}, ... (all {len(names)}: docs/keys.md, 'Parameter order')"


def per_parameter(value: Any, model: RobotModel, field: str, *, broadcast: bool) -> np.ndarray:
    """A vector of the model's `p` parameters; a wrong length names `p` and the parameters in order. A plain number is
    the same value for every parameter when `broadcast` (`phi_hat0 = 0`: zeros)."""
    arr = as_array(value, field)
    if arr.ndim == 0 and broadcast:
        return np.full(model.p, float(arr))
    if arr.shape != (model.p,):
        got = (f"{arr.shape[0]} number{'s' if arr.shape[0] != 1 else ''}" if arr.ndim == 1 else
               "a number" if arr.ndim == 0 else f"shape {arr.shape}")
        raise ConfigError(field, f"expected a list of {model.p} numbers, one per parameter in the order "
                          f"{_names(model.param_names)}; got {got}")
    return arr


def build(registry: str, section: Any, name: str, model: RobotModel | None = None, n: int | None = None) -> Any:
    """Call the constructor that `section['kind']` names in `registry` (:func:`constructor`) with the section's other
    keys; nested tables (servo, law, base) are built first. `phi_hat0` defaults to zeros; a plain number is that value
    for all. `n`: the dimension a trajectory takes first (default the arm's joints; a task-space law's m)."""
    if not isinstance(section, dict):
        raise ConfigError(name, f"expected a table with a kind ({', '.join(sorted(kinds(registry)))}), got {section!r}")
    ctor, first = constructor(registry, section.get("kind"), f"{name}.kind")
    params = _params(ctor, first)
    keys = {k: v for k, v in section.items() if k != "kind"}
    estimated = "phi_hat0" in params and model is not None
    check_names(list(keys), list(params), name,
                required=[k for k, req in params.items() if req and not (estimated and k == "phi_hat0")])
    if estimated:
        keys["phi_hat0"] = per_parameter(keys.get("phi_hat0", 0.0), model, f"{name}.phi_hat0",  # type: ignore[arg-type]
                                         broadcast=True)
    for key in NESTED.keys() & keys.keys():
        keys[key] = build(NESTED[key], keys[key], f"{name}.{key}", model)
    sizes = {} if model is None else {"model": model, "n": model.n if n is None else n, "p": model.p}
    args = () if first is None else (sizes[first],)
    try:
        return ctor(*args, **keys)
    except ConfigError as exc:  # "controller.Kv" raised by a nested base is "controller.base.Kv" here
        root = CANONICAL[registry]
        if name == root or not (exc.field == root or exc.field.startswith(root + ".")):
            raise
        raise ConfigError(name + exc.field[len(root):], exc.reason) from None


def _on_path(law: Any, trajectory: Any, t_final: float, q0: np.ndarray, dq0: np.ndarray,
             section: Any) -> tuple[np.ndarray, np.ndarray]:
    """A task-space run's start (docs/task-space.md): the path checked against the arm's reach (one line naming the
    first point out of it), then, unless `plant.q0` / `plant.dq0` are given, the hand at x_d(0) (the joint angles
    nearest the law's posture) moving at ẋ_d(0) (q̇ = J⁺ ẋ_d(0))."""
    model, tool = law.model, law.tool
    bound = reach(model, tool)
    if bound is not None:
        reach_check(trajectory, bound[0], bound[1], bound[2], t_final)
    ref = trajectory(0.0)
    section = section if isinstance(section, dict) else {}
    if "q0" not in section:
        q0 = inverse_kinematics(model, ref.q_des, law.posture, tool)
    if "dq0" not in section:
        m = law.error_size
        dq0 = np.linalg.pinv(np.asarray(model.hand(q0, np.zeros(model.n), tool).J)[:m]) @ np.asarray(ref.dq_des)
    return q0, dq0


def resolved(registry: str, section: dict[str, Any], model: RobotModel | None = None) -> dict[str, Any]:
    """A section that built, with every default its constructor used written out (nested tables too), so that the
    written scenario reproduces the run if a default changes."""
    ctor, first = constructor(registry, section["kind"], f"{registry}.kind")
    defaults = _signature(ctor, first)
    out = _with_defaults(section, defaults)
    if "phi_hat0" in defaults and model is not None and "phi_hat0" not in out:
        out["phi_hat0"] = [0.0] * model.p
    if isinstance(out.get("Gamma"), dict):
        out["Gamma"] = {"eps": EPS, **out["Gamma"]}
    for key in NESTED.keys() & out.keys():
        out[key] = resolved(NESTED[key], out[key], model)
    return out


_ROBOTS: dict[str, RobotModel] = {}  # robots built, by their section: the runs of a sweep share one
_MAX_ROBOTS = 32


def _robot_key(section: Any) -> str | None:
    """A section as text, with its constructor's defaults as they are now and the modification time of a file it
    names; None if it is not plain data."""
    try:
        key = json.dumps(section, sort_keys=True)
        ctor, _ = constructor("robot", section["kind"], "robot.kind")
    except (TypeError, ValueError, KeyError, ConfigError):
        return None
    ctor = getattr(ctor, "__init__", ctor) if isinstance(ctor, type) else ctor
    key += f"|{ctor.__defaults__!r}|{ctor.__kwdefaults__!r}"
    path = section.get("path") if isinstance(section, dict) else None
    if isinstance(path, str) and os.path.isfile(path):
        key += f"|{os.stat(path).st_mtime_ns}"
    return key


def robot(section: Any) -> RobotModel:
    """The model `[robot]` describes; built once per process for each section (models are immutable: building a URDF
    arm takes some 40 ms, which a sweep of a thousand Panda runs would otherwise pay a thousand times)."""
    key = _robot_key(section)
    if key is None:
        return build("robot", section, "robot")
    if key not in _ROBOTS:
        if len(_ROBOTS) >= _MAX_ROBOTS:
            _ROBOTS.pop(next(iter(_ROBOTS)))
        _ROBOTS[key] = build("robot", section, "robot")
    return _ROBOTS[key]


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
    check_names(list(table), list(params), f"plant.{key}", required=[k for k, req in params.items() if req])
    return ctor(n, **table)


def plant_keys() -> dict[str, Any]:
    """The flat keys of [plant] → default (REQUIRED for none; the actuator's and sensor's as their constructors')."""
    dist = dict(_signature(sinusoidal_disturbance, "n"))
    payload = _signature(Payload, None)
    return {"phi": REQUIRED, "q0": 0.0, "dq0": 0.0, "disturbance": dist, "robot": REQUIRED,
            **{key: payload[arg] for key, arg in PAYLOAD.items()}, **_signature(Actuator, "n"), **_signature(Sensor, "n"),
            "engine": "robotadapt", **MUJOCO_KEYS}


# [plant] keys of the MuJoCo engine (`engine = "mujoco"`) → default (None: the simulation's step, φ's columns or zero)
MUJOCO_KEYS: dict[str, Any] = {"timestep": None, "integrator": "RK4", "actuation": "motor", "damping": None,
                               "armature": None, "frictionloss": None, "joint_limits": False}
ENGINES = ("robotadapt", "mujoco")


def _mujoco(truth: RobotModel, robot_section: Any) -> dict[str, Any]:
    """What a MuJoCo plant needs besides the truth model: the URDF file and locked joints of a URDF arm (none for the
    book's arms)."""
    kind = robot_section.get("kind") if isinstance(robot_section, dict) else None
    locked = tuple(robot_section.get("locked_joints", ())) if kind in ("urdf", "example_robot") else ()
    if kind == "urdf":
        return {"urdf": str(robot_section["path"]), "locked_joints": locked}
    if kind == "example_robot":
        from importlib.metadata import distribution

        from ...robots.pinocchio import EXAMPLES

        relative, gripper = EXAMPLES[robot_section["name"]]
        robots = distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots")
        return {"urdf": str(robots / relative), "locked_joints": gripper + locked}
    return {}


def plant(section: dict[str, Any], model: RobotModel,
          robot_section: Any = None) -> tuple[Plant, np.ndarray, np.ndarray, dict[str, Any]]:
    """The true plant: `robot` (a table like [robot], default the controller's model, whose table is `robot_section`)
    with `phi` in its parameterization, `q0`, `dq0`, `disturbance`; a payload (`payload` kg at `payload_offset`, from
    `payload_time`); the actuator's and the sensor's keys; `[plant.elastic_joint]` and `[plant.motor]` tables; `engine`
    "robotadapt" (the project's dynamics) or "mujoco" (:class:`~robotadapt.plant.mujoco.MujocoPlant`, with MuJoCo's
    options `MUJOCO_KEYS`). Also the section with every value used written out."""
    if not isinstance(section, dict):
        raise ConfigError("plant", "expected a table with phi, q0, dq0 and optionally disturbance")
    actuator_keys, sensor_keys = list(_params(Actuator, "n")), list(_params(Sensor, "n"))
    check_names(list(section), ["phi", "q0", "dq0", "disturbance", "robot", *PAYLOAD, *actuator_keys, *sensor_keys,
                                *PLANT_TABLES, "engine", *MUJOCO_KEYS], "plant")
    engine = section.get("engine", "robotadapt")
    if engine not in ENGINES:
        raise ConfigError("plant.engine", f"expected one of {', '.join(ENGINES)}; got {engine!r}")
    options = {key: section[key] for key in MUJOCO_KEYS if key in section}
    if options and engine != "mujoco":
        raise ConfigError(f"plant.{next(iter(options))}", "is an option of the MuJoCo plant: set plant.engine = "
                          "'mujoco', or drop it")
    out = dict(section)
    truth = model
    if "robot" in section:
        truth = build("robot", section["robot"], "plant.robot")
        if truth.n != model.n:
            raise ConfigError("plant.robot", f"has {truth.n} joints, the controller's robot {model.n}")
        out["robot"] = resolved("robot", section["robot"])
        robot_section = section["robot"]
    given_phi = "phi" in section
    if "phi" not in section:
        if truth.default_phi is None:
            raise ConfigError("plant.phi", f"missing: the {truth.p} true parameters {_names(truth.param_names)}")
        section = dict(section, phi=truth.default_phi)  # the model's own (published or URDF) parameters
    dist = section.get("disturbance")
    if dist is not None:
        if not isinstance(dist, dict):
            raise ConfigError("plant.disturbance", "expected a table with amplitude, omega, phase, bias")
        check_names(list(dist), ["amplitude", "omega", "phase", "bias"], "plant.disturbance")
        out["disturbance"] = _with_defaults(dist, _signature(sinusoidal_disturbance, "n"))
        dist = sinusoidal_disturbance(model.n, **dist)
    phi = per_parameter(section["phi"], truth, "plant.phi", broadcast=False)
    q0 = as_vector(section.get("q0", 0.0), model.n, "plant.q0")
    dq0 = as_vector(section.get("dq0", 0.0), model.n, "plant.dq0")
    out = {**dict(phi=phi.tolist(), q0=q0.tolist(), dq0=dq0.tolist()), **out}
    payload = {arg: section[key] for key, arg in PAYLOAD.items() if key in section}
    if payload and "mass" not in payload:
        raise ConfigError("plant.payload", "missing: the payload's mass (kg) for payload_offset / payload_time")
    if payload:
        out = _with_defaults(out, {key: _signature(Payload, None)[arg] for key, arg in PAYLOAD.items()})
    n = model.n
    parts = [{k: section[k] for k in keys if k in section} for keys in (actuator_keys, sensor_keys)]
    for given, ctor in zip(parts, (Actuator, Sensor), strict=True):
        if given:  # a part's defaults only when the part is there: no key, no actuator (sensor) at all
            out = _with_defaults(out, _signature(ctor, "n"))
    for key, ctor in PLANT_TABLES.items():
        if isinstance(section.get(key), dict):
            out[key] = _with_defaults(section[key], _signature(ctor, "n"))
    kwargs = dict(model=truth, phi=phi, disturbance=dist, payload=Payload(**payload) if payload else None,
                  elastic_joint=_table(section, "elastic_joint", n), motor=_table(section, "motor", n),
                  actuator=_part(Actuator, parts[0], n), sensor=_part(Sensor, parts[1], n))
    if engine != "mujoco":
        return Plant(**kwargs), q0, dq0, out
    if not given_phi:  # the model's own parameters, with MuJoCo's options in their columns
        kwargs["phi"] = with_options(truth, phi, options)
        out["phi"] = kwargs["phi"].tolist()
    out = _with_defaults({**out, "engine": engine}, MUJOCO_KEYS)
    return MujocoPlant(**kwargs, **_mujoco(truth, robot_section), **options), q0, dq0, out


def mujoco_view(data: dict[str, Any], the_plant: Plant) -> MujocoPlant:
    """A MuJoCo model of a scenario's true arm (`data`: the scenario's tables) for pictures: the plant itself when MuJoCo
    steps it, else one built from the same description."""
    if isinstance(the_plant, MujocoPlant):
        return the_plant
    robot_section = data["plant"].get("robot", data["robot"])
    try:
        return MujocoPlant(the_plant.model, the_plant.phi_at(0.0), **_mujoco(the_plant.model, robot_section))
    except ConfigError as exc:
        raise ConfigError("--video", f"no MuJoCo model of this arm: {exc.reason}") from None


# [simulation] keys → default (REQUIRED: none; None: not used unless given)
SIMULATION: dict[str, Any] = {"t_final": REQUIRED, "dt": 1e-3, "method": "rk4", "backend": "auto", "rtol": 1e-8,
                              "atol": 1e-10, "log_every": 1, "max_state": 1e6, "control_period": None,
                              "discretization": "euler"}


def simulation(section: dict[str, Any]) -> tuple[float, RK4 | SolveIVP | Sampled, int, float, dict[str, Any]]:
    """t_final, the integrator (RK4, a solve_ivp method, or sampled-data control with `control_period`), log_every,
    max_state, and the section with every value used written out."""
    if not isinstance(section, dict):
        raise ConfigError("simulation", "expected a table with t_final, dt, method")
    check_names(list(section), list(SIMULATION), "simulation", required=["t_final"])
    backend = check_backend(section.get("backend", "auto"))
    t_final = as_scalar(section["t_final"], "simulation.t_final", positive=True)
    method = section.get("method", "rk4")
    if not isinstance(method, str):
        raise ConfigError("simulation.method", f"expected a name such as 'rk4' or 'RK45', got {method!r}")
    integ: RK4 | SolveIVP | Sampled
    used = ["method", "backend", "log_every", "max_state"]
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
        used.append("discretization")
    else:
        if "discretization" in section:
            raise ConfigError("simulation.discretization", "applies to sampled-data control: set "
                              "simulation.control_period")
        dt = as_scalar(section.get("dt", SIMULATION["dt"]), "simulation.dt", positive=True)
        if dt > t_final:
            raise ConfigError("simulation.dt", f"the step {dt:g} s is longer than t_final = {t_final:g} s")
        used.append("dt")
        if method.lower() == "rk4":
            if "rtol" in section or "atol" in section:
                raise ConfigError("simulation.rtol", "tolerances apply to solve_ivp methods, not to the fixed-step 'rk4'")
            integ = RK4(dt, backend)
        else:
            integ = SolveIVP(method, section.get("rtol", SIMULATION["rtol"]), section.get("atol", SIMULATION["atol"]), dt,
                             backend)
            used += ["rtol", "atol"]
    log_every = section.get("log_every", 1)
    if isinstance(log_every, bool) or not isinstance(log_every, int) or log_every < 1:
        raise ConfigError("simulation.log_every", f"expected a positive whole number, got {log_every!r}")
    max_state = as_scalar(section.get("max_state", SIMULATION["max_state"]), "simulation.max_state", positive=True)
    return t_final, integ, log_every, max_state, {**section, **{k: SIMULATION[k] for k in used if k not in section}}


EPS = 1e-3  # the default ε of Gamma = {scale = s, eps = ε}: Γ_k = s (|φ_k| + ε)


def _truth_tables(section: Any, the_plant: Plant, model: RobotModel, name: str = "controller") -> Any:
    """Resolve the tables of [controller] (and its nested base and law) that are written in terms of the true φ, so
    that the law itself never sees the truth:

    - `phi_hat0 = {scale = s}`: s × the true value of each of the controller's parameters, e.g. 0.7 for an estimate
      30 % low on all of them (n-DOF arms, whose φ has tens of entries);
    - `phi_hat0 = {file = "DIR/identified.json"}`: the estimate `robotadapt identify` wrote (:func:`identified`);
    - `Gamma = {scale = s, eps = ε}`: the diagonal Γ_k = s (|φ_k| + ε), an adaptation gain scaled to each parameter's
      size (a uniform Γ adapts parameters of very different sizes at very different relative rates).

    The true values are the plant's entries of the same names, so the plant's robot may add parameters (friction) the
    controller's lacks."""
    if not isinstance(section, dict):
        return section
    section = dict(section)
    for key in NESTED.keys() & section.keys():  # the law a passivity-based one uses, the one a robust one wraps
        section[key] = _truth_tables(section[key], the_plant, model, f"{name}.{key}")
    if isinstance(section.get("phi_hat0"), dict) and "file" in section["phi_hat0"]:
        section["phi_hat0"] = identified(section["phi_hat0"], model, f"{name}.phi_hat0")
    for key, allowed in (("phi_hat0", ["scale"]), ("Gamma", ["scale", "eps"])):
        value = section.get(key)
        if not isinstance(value, dict):
            continue
        where = f"{name}.{key}"
        check_names(list(value), allowed, where, required=["scale"])
        truth = dict(zip(the_plant.model.param_names, the_plant.phi, strict=True))
        missing = [p for p in model.param_names if p not in truth]
        if missing:
            raise ConfigError(where, f"a scale of the true parameters needs the plant's robot to have the "
                              f"controller's parameters; it lacks {', '.join(missing[:5])}: give {key} as a list")
        phi = np.array([float(truth[p]) for p in model.param_names])
        if key == "phi_hat0":
            section[key] = (as_scalar(value["scale"], f"{where}.scale") * phi).tolist()
        else:
            scale = as_scalar(value["scale"], f"{where}.scale", positive=True)
            eps = as_scalar(value.get("eps", EPS), f"{where}.eps", nonnegative=True)
            section[key] = (scale * (np.abs(phi) + eps)).tolist()  # a list gain is the diagonal
    return section


def identified(value: dict[str, Any], model: RobotModel, where: str) -> list[float]:
    """φ̂(0) from an `identified.json` of `robotadapt identify` (docs/identification.md): its `phi` (the estimate it
    chose, standard parameters) or, for a base-parameter controller, its `base` values, matched to the controller's
    parameters by name."""
    check_names(list(value), ["file"], where, required=["file"])
    path = Path(str(value["file"]))
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        pairs = [*zip(data["param_names"], data["phi"], strict=True),
                 *zip(data["base_names"], data["base"][data["estimate"]], strict=True)]
    except FileNotFoundError:
        raise ConfigError(f"{where}.file", f"no such file: {str(path)!r} (write it with `robotadapt identify`)") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"{where}.file", f"{str(path)!r} is not an identified.json of `robotadapt identify` "
                          f"({type(exc).__name__}: {exc})") from None
    values = dict(pairs)
    missing = [p for p in model.param_names if p not in values]
    if missing:
        raise ConfigError(f"{where}.file", f"{str(path)!r} has no value for the controller's parameter"
                          f"{'s' * (len(missing) > 1)} {', '.join(missing[:4])}: identify with this scenario's robot")
    return [float(values[p]) for p in model.param_names]


def setup(data: dict[str, Any]) -> Setup:
    """Build every object of a scenario (already parsed TOML), validating each field once."""
    missing = [name for name in ("robot", "trajectory", "controller", "simulation") if name not in data]
    if missing:
        raise ConfigError(missing[0] if len(missing) == 1 else "scenario",
                          f"missing section{'s' if len(missing) > 1 else ''} {', '.join(f'[{m}]' for m in missing)}")
    model = robot(data["robot"])
    the_plant, q0, dq0, plant_data = plant(data.get("plant", {}), model, data["robot"])  # every key has a default
    t_final, integ, log_every, max_state, sim_data = simulation(data["simulation"])
    controller = build("controller", _truth_tables(data["controller"], the_plant, model), "controller", model)
    task = getattr(controller, "space", "joint") == "task"
    size = controller.error_size if task else None
    trajectory = build("trajectory", data["trajectory"], "trajectory", model, size)
    if task:
        q0, dq0 = _on_path(controller, trajectory, t_final, q0, dq0, data.get("plant", {}))
        plant_data = {**plant_data, "q0": q0.tolist(), "dq0": dq0.tolist()}
    full = {**data, "robot": resolved("robot", data["robot"]), "plant": plant_data,
            "trajectory": resolved("trajectory", data["trajectory"], model),
            "controller": resolved("controller", data["controller"], model), "simulation": sim_data}
    return Setup(the_plant, controller, trajectory, t_final, integ, q0, dq0, log_every, max_state, full)
