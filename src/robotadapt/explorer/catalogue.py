"""What a view runs: the scenarios the explorer may run (the packaged ones and the file named on its command line, no
other), every law that applies to a scenario's arm with the book's gains scaled (:func:`robotadapt.studies.compare.lineup`,
as `robotadapt compare` runs them), the controls of a law (the gains it declares tunable, `tuned`, with their units and
the range `robotadapt tune` screens; the control period, torque limit, sensor noise and final time), the scenario a view
stands for and its run. Recent lineups and runs are kept, keyed by the view."""

from __future__ import annotations

import copy
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ..analysis.metrics import health_warnings, metrics
from ..report.figures import joint_types
from ..sim.result import SimulationResult
from ..studies.compare import Entry, lineup
from ..studies.scenarios import Scenario, available, load
from ..studies.scenarios.build import NESTED, constructor, setup
from ..studies.scenarios.loader import override, read, toml_value
from ..studies.tune import SPREAD
from ..validation import ConfigError
from .view import View, refuse_code

T = TypeVar("T")

#: a gain's unit at revolute joints and at prismatic ones (docs/keys.md); "per parameter": each φ_k's own
GAIN_UNITS = {"Lam": ("1/s", "1/s"), "alpha": ("1/s", "1/s"), "a": ("1/s", "1/s"), "sigma0": ("1/s", "1/s"),
              "Psi": ("1/s²", "1/s²"), "Kv": ("N·m·s/rad", "N·s/m"), "Kp": ("N·m/rad", "N/m"),
              "Ka": ("N·m/rad²", "N/m²"), "kd": ("N·m", "N"), "Gamma": ("per parameter",) * 2,
              "Gamma_k": ("per parameter",) * 2, "P0": ("per parameter",) * 2}


@dataclass(frozen=True)
class Control:
    """A field of the page: its scenario key, label, unit, the value the view runs (TOML text; "" for none) and the
    lineup's value (`default`). A gain that is a positive number or a list or matrix of numbers has a slider on a log
    scale over `span` (low, high): the value itself for a number, a factor of `default` for a list or matrix."""

    key: str
    label: str
    unit: str
    text: str
    default: Any
    span: tuple[float, float] | None = None

    @property
    def scalar(self) -> bool:
        return isinstance(self.default, int | float) and not isinstance(self.default, bool)


#: the settings beside the gains: (key, label, unit)
SETTINGS = (("simulation.t_final", "final time t_final", "s"),
            ("simulation.control_period", "control period (empty: continuous)", "s"),
            ("plant.torque_limit", "torque limit (empty: none)", "N·m"),
            ("plant.noise_q", "sensor noise σ_q (empty: none; needs a control period)", "rad"))


@dataclass(frozen=True, eq=False)
class Run:
    """A view's run: its scenario, result and the controller's model; its metrics (metrics.json's) and health warnings
    computed when first asked for (the page asks after the figures are painted: 4 ms of Example 6.3.1's run)."""

    scenario: Scenario
    result: SimulationResult

    @property
    def model(self) -> Any:
        return self.scenario.setup.controller.model

    @cached_property
    def metrics(self) -> dict[str, Any]:
        return metrics(self.result, self.model)

    @cached_property
    def warnings(self) -> list[str]:
        return health_warnings(self.metrics)


class _Recent:
    """The last `size` values by key, computed once each (the others wait for a value being computed)."""

    def __init__(self, size: int) -> None:
        self.size, self.items, self.lock = size, OrderedDict[Hashable, Any](), threading.Lock()

    def get(self, key: Hashable, make: Callable[[], T]) -> T:
        with self.lock:
            if key in self.items:
                self.items.move_to_end(key)
                return self.items[key]
            value = make()
            self.items[key] = value
            while len(self.items) > self.size:
                self.items.popitem(last=False)
            return value


def gain_keys(section: dict[str, Any], prefix: str = "controller", registry: str = "controller") -> list[str]:
    """The keys of a controller section's gains: those its law declares tunable (`tuned`, what `robotadapt compare --fair`
    tunes), its servo's, update law's and base's by theirs. Unlike tuning, the explorer sets a gain by rebuilding the
    scenario, so none is left out for being hard to differentiate."""
    tuned = getattr(constructor(registry, section.get("kind"), f"{prefix}.kind")[0], "tuned", ())
    return [f"{prefix}.{k}" for k in section if k in tuned] + [
        key for k, inner in NESTED.items() if isinstance(section.get(k), dict)
        for key in gain_keys(section[k], f"{prefix}.{k}", inner)]


def one_line(value: Any) -> str:
    """A value as a field shows it and `--set` reads it: TOML on one line (a list or a matrix too)."""
    if isinstance(value, list):
        return "[" + ", ".join(one_line(v) for v in value) + "]"
    return toml_value(value)


def _lookup(data: dict[str, Any], key: str) -> Any:
    """The value at a dotted key of a scenario's tables; None where there is none."""
    node: Any = data
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    return node


def _span(value: Any) -> tuple[float, float] | None:
    """The slider's range for a gain written `value`: `robotadapt tune`'s screen about it, value / SPREAD … value ·
    SPREAD (a factor 1/SPREAD … SPREAD of a list or matrix); None for a value that is not positive numbers."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    if isinstance(value, bool) or arr.size == 0 or arr.ndim > 2 or not np.all(np.isfinite(arr)):
        return None
    if arr.ndim == 0:
        return (float(arr) / SPREAD, float(arr) * SPREAD) if arr > 0 else None
    return (1 / SPREAD, SPREAD) if np.all(np.diag(arr) > 0 if arr.ndim == 2 else arr > 0) else None


class Catalogue:
    """The scenarios one explorer runs, their lineups and recent runs. `source` is the command line's scenario: a packaged
    name or a TOML file, the only file the explorer reads (by its name, which shadows a packaged scenario's)."""

    def __init__(self, source: str | Path) -> None:
        name, _ = read(source)
        packaged = available()
        self.default = name
        self.files = {} if str(source) in packaged else {name: source}
        self.names = list(dict.fromkeys([*self.files, *packaged]))
        self._lineups = _Recent(8)
        self._runs = _Recent(8)

    def source(self, name: str) -> str | Path:
        """What `load` reads for a scenario of the page; a ConfigError for any other name (a URL names no file)."""
        if name not in self.names:
            raise ConfigError("scenario", f"{name!r} is not a scenario of this explorer: the packaged ones (`robotadapt "
                              "list`) and the file named on its command line")
        return self.files.get(name, name)

    def lineup(self, view: View) -> tuple[dict[str, Entry], dict[str, str]]:
        """The lineup on the view's scenario with its settings (every assignment but the controller's): entries by name,
        the scenario's own controller first; the laws that do not apply, with why."""
        settings, _ = view.split()
        for assignment in settings:
            refuse_code(assignment)

        def make() -> tuple[dict[str, Entry], dict[str, str]]:
            entries, skipped = lineup(load(self.source(view.scenario), settings))
            return {e.name: e for e in sorted(entries, key=lambda e: not e.reference)}, skipped

        return self._lineups.get((view.scenario, tuple(settings)), make)

    def entry(self, view: View) -> Entry:
        """The view's law: its lineup entry (the scenario's own controller when the view names none)."""
        entries, skipped = self.lineup(view)
        if view.law is None:
            return next(iter(entries.values()))
        if view.law not in entries:
            why = f": {skipped[view.law]}" if view.law in skipped else f"; choose from {', '.join(entries)}"
            raise ConfigError("law", f"{view.law!r} does not apply to {view.scenario}{why}")
        return entries[view.law]

    def scenario(self, view: View) -> Scenario:
        """The scenario a view stands for: its law's entry with the controller's assignments, validated. What
        :attr:`Scenario.text` writes, `robotadapt run` reproduces."""
        entry = self.entry(view)
        _, assignments = view.split()
        data = copy.deepcopy(entry.scenario.data)
        for assignment in assignments:
            refuse_code(assignment)
            override(data, assignment)
        return Scenario(entry.scenario.name, data, setup(data))

    def controls(self, view: View) -> list[Control]:
        """The view's law's gains, then the settings (:data:`SETTINGS`), each with the value the view runs."""
        entry = self.entry(view)
        data = entry.scenario.data
        joints = joint_types(entry.scenario.setup.controller.model) or "R"
        out = []
        for key in gain_keys(data["controller"]):
            default = _lookup(data, key)
            units = GAIN_UNITS.get(key.rsplit(".", 1)[-1], ("—", "—"))
            unit = units[0] if set(joints) == {"R"} else units[1] if set(joints) == {"P"} else " or ".join(units)
            out.append(Control(key, key.removeprefix("controller."), unit, view.value(key) or one_line(default),
                               default, _span(default)))
        for key, label, unit in SETTINGS:
            default = _lookup(data, key)
            given = view.value(key)
            out.append(Control(key, label, unit, given if given is not None else
                               "" if default is None else one_line(default), default))
        return out

    def run(self, view: View) -> Run:
        """The view's run (a recent one when the same view ran before)."""

        def make() -> Run:
            scenario = self.scenario(view)
            return Run(scenario, scenario.run())

        return self._runs.get((view.scenario, view.law, view.sets), make)
