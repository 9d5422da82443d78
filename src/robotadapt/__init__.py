"""robotadapt: adaptive control of rigid robot manipulators (layers: docs/architecture.md).

The front door, `import robotadapt as ra`: the names a user needs, each imported from its module when first used, so
that importing the package stays light (no JAX, scipy or matplotlib until a name needs them) and changes nothing
outside it (no import hooks, no JAX settings). docs/own-arm.md walks through them on an arm of your own. The laws and
update laws are every class registered in `robotadapt.controllers` (:mod:`robotadapt.controllers.registry`), by its
name: `ra.InertiaRelated`, `ra.Gradient`, ...; the first such name imports the controllers.

>>> import robotadapt as ra
>>> arm = ra.TwoLinkArm()
>>> ctrl = ra.InertiaRelated(arm, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])   # Slotine–Li, Table 6.3.1
>>> res = ra.simulate(ra.Plant(arm, [0.8, 2.3]), ctrl, ra.sinusoid(2), t_final=10, integrator=ra.RK4(1e-3))
>>> res.status, res.phi_hat[-1].round(6).tolist()
('ok', [0.8, 2.3])
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

#: module (relative to the package) → the names the front door takes from it, besides the laws (module docstring)
EXPORTS = {
    "studies.scenarios": ("load", "available"),
    "sim": ("simulate", "simulate_batch", "RK4", "Sampled", "SolveIVP", "SimulationResult"),
    "plant": ("Plant", "sinusoidal_disturbance"),
    "plant.actuators": ("Actuator", "DCMotor"),
    "plant.sensors": ("Sensor",),
    "plant.unmodeled": ("Payload", "ElasticJoint"),
    "robots": ("OneLinkArm", "TwoLinkArm", "PolarArm", "PinocchioArm", "SymbolicArm"),
    "robots.catalog": ("planar", "dh_arm", "urdf_arm", "example_arm"),
    "controllers": ("pd_servo", "pid_servo", "state_space_servo"),
    "trajectories": ("sinusoid", "sum_of_sines", "quintic", "constant", "exponential_step"),
    "analysis.metrics": ("metrics",),
    "report.files": ("save_result",),
    "report.figures": ("save_figures",),
    "report.output": ("FigureFormat",),
}
_WHERE = {name: module for module, names in EXPORTS.items() for name in names}


def _laws() -> dict[str, Any]:
    """Every registered law and update law by its class name (imports robotadapt.controllers)."""
    laws: dict[str, Any] = import_module(f"{__name__}.controllers.registry").by_name()
    return laws


def __getattr__(name: str) -> Any:
    """`ra.<name>`: the object of that name in its module, or the registered law of that class name, imported now
    (PEP 562); `ra.__all__`: every name, the laws registered so far with them."""
    module = _WHERE.get(name)
    if module is not None:
        value = getattr(import_module(f"{__name__}.{module}"), name)
    elif name == "__version__":  # the installed metadata, read when asked: 45 ms of every start otherwise
        value = import_module("importlib.metadata").version(__name__)
    elif name == "__all__":
        return ["__version__", *_WHERE, *_laws()]
    elif name.startswith("_") or name not in (laws := _laws()):
        raise AttributeError(f"module 'robotadapt' has no attribute {name!r}")
    else:
        value = laws[name]
        if not value.__module__.startswith(f"{__name__}."):
            return value  # a user's law: looked up again next time (it may be unregistered)
    globals()[name] = value  # the next access is a plain lookup
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | {"__version__"} | set(_WHERE) | set(_laws()))
