"""Import paths of the first release, kept working: each old module name is the module it moved to (docs/architecture.md).

A finder at the front of `sys.meta_path` answers only the old names (no real module has them), by importing the new
module and registering it under the old name too; nothing here is imported eagerly.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from types import ModuleType

MOVED = {"simulation": "sim", "batch": "sim.batch", "result": "sim.result", "compiled": "sim.compiled",
         "sampled": "sim.sampled", "adaptation": "controllers.adaptation", "actuators": "plant.actuators",
         "sensors": "plant.sensors", "unmodeled": "plant.unmodeled", "monitors": "analysis.monitors",
         "excitation": "analysis.excitation", "gains": "analysis.gains", "scenarios": "studies.scenarios",
         "study": "studies.study", "sweep": "studies.sweep", "plotting": "report.figures",
         "sweep_plot": "report.sweep_figures"}


def new_name(name: str) -> str | None:
    """The module `name` (robotadapt.OLD[.rest]) now lives at, or None."""
    parts = name.split(".")
    if len(parts) < 2 or parts[0] != "robotadapt" or parts[1] not in MOVED:
        return None
    return ".".join(["robotadapt", MOVED[parts[1]], *parts[2:]])


class MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, fullname: str, path: object, target: object = None) -> importlib.machinery.ModuleSpec | None:
        return None if new_name(fullname) is None else importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        return importlib.import_module(new_name(spec.name) or spec.name)

    def exec_module(self, module: ModuleType) -> None:
        """The new module ran when it was imported."""


def install() -> None:
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())
