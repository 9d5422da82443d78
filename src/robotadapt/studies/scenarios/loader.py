"""Scenario files: reading, `--set` overrides, the packaged catalogue (DESIGN "Scenarios").

A scenario is a TOML file with a one-line `description` and the sections `[robot]`, `[plant]`, `[trajectory]`,
`[controller]` and `[simulation]`. The book's examples ship inside the package; `robotadapt list` shows them.
"""

from __future__ import annotations

import copy
import difflib
import sys
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import tomli_w

from ...validation import ConfigError
from .build import Setup, setup

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SECTIONS = ("robot", "plant", "trajectory", "controller", "simulation")
TOP_KEYS = ("description", "notes", "study")


def toml_value(value: Any) -> str:
    """One TOML value on one line; a table as an inline table (`{kind = "pd", Lam = 5}`)."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{tomli_w.dumps({k: 0}).split(' = ')[0]} = {toml_value(v)}" for k, v in value.items()) + "}"
    return tomli_w.dumps({"v": value})[4:].strip()


def assignment(key: str, value: Any) -> str:
    """`key=value` with the value written as TOML (what `--set` parses)."""
    return f"{key}={toml_value(value)}"



@dataclass(frozen=True, eq=False)
class Scenario:
    """A parsed, validated scenario: `data` is the TOML content after overrides, `setup` the objects built from it."""

    name: str
    data: dict[str, Any]
    setup: Setup

    @property
    def description(self) -> str:
        return str(self.data.get("description", ""))

    @property
    def study(self) -> dict[str, list[Any]]:
        """The `[study]` table: dotted keys → values to try one at a time around this setting."""
        return dict(self.data.get("study", {}))

    def variant(self, assignment: str) -> Scenario:
        """This scenario with one more `section.key=value` override (validated), without its study."""
        data = copy.deepcopy(self.data)
        data.pop("study", None)
        override(data, assignment)
        return Scenario(f"{self.name} [{assignment}]", data, setup(data))

    @property
    def text(self) -> str:
        """The resolved scenario as TOML (what a run saves as scenario.toml): every value the run used, the
        constructors' defaults included, so that running the file again reproduces the run if a default changes.
        An array is one line (a matrix too long for one: a line per row), its numbers written as Python's repr,
        which reads back to the very same float."""

        def key(k: str) -> str:
            return tomli_w.dumps({k: 0}).rsplit(" = ", 1)[0]  # bare where it can be, else quoted

        def value(v: Any) -> str:
            if isinstance(v, list | tuple):
                items = [value(x) for x in v]
                line = "[" + ", ".join(items) + "]"
                nested = any(isinstance(x, list | tuple) for x in v)
                return "[\n" + "".join(f"    {item},\n" for item in items) + "]" if nested and len(line) > 100 else line
            if isinstance(v, dict):
                return "{" + ", ".join(f"{key(k)} = {value(x)}" for k, x in v.items()) + "}"
            return toml_value(v)

        def table(data: dict[str, Any], name: str) -> list[str]:
            lines = [f"{key(k)} = {value(v)}" for k, v in data.items() if not isinstance(v, dict)]
            subtables = [(k, v) for k, v in data.items() if isinstance(v, dict)]
            if name and (lines or not subtables):
                lines.insert(0, f"[{name}]")
            for k, v in subtables:
                lines += [""] * bool(lines) + table(v, f"{name}.{key(k)}" if name else key(k))
            return lines

        return "\n".join(table(self.setup.data or self.data, "")) + "\n"

    def run(self, progress: bool = False) -> Any:
        """Simulate this scenario; returns a :class:`~robotadapt.sim.result.SimulationResult`."""
        from ...sim.simulation import simulate

        s = self.setup
        return simulate(s.plant, s.controller, s.trajectory, t_final=s.t_final, integrator=s.integrator, q0=s.q0,
                        dq0=s.dq0, log_every=s.log_every, max_state=s.max_state, progress=progress,
                        info={"scenario": self.name, "description": self.description})


def _packaged() -> dict[str, Any]:
    folder = resources.files(__package__)
    return {p.name[: -len(".toml")]: p for p in folder.iterdir() if p.name.endswith(".toml")}


def available() -> dict[str, str]:
    """Packaged scenario names → one-line descriptions, sorted by name."""
    out = {}
    for name, path in sorted(_packaged().items()):
        out[name] = str(tomllib.loads(path.read_text(encoding="utf-8")).get("description", ""))
    return out


def extras(data: dict[str, Any]) -> list[str]:
    """The optional extras a scenario's data need (`pip install 'robotadapt[...]'`): `urdf` for a robot read from a
    URDF or example-robot-data (Pinocchio's parser), `mujoco` for MuJoCo as the plant, `symbolic` for a sympy model."""
    robot, plant = data.get("robot", {}), data.get("plant", {})
    need = []
    if robot.get("kind") in ("urdf", "example_robot"):
        need.append("urdf")
    if robot.get("model") == "sympy":
        need.append("symbolic")
    if isinstance(plant, dict) and plant.get("engine") == "mujoco":
        need.append("mujoco")
    return need


def needs() -> dict[str, list[str]]:
    """Packaged scenario names → the extras each needs (none: the core)."""
    return {name: extras(tomllib.loads(path.read_text(encoding="utf-8"))) for name, path in sorted(_packaged().items())}


def book_scenarios() -> list[str]:
    """The packaged scenarios named example-* and problem-*, in order."""
    return [name for name in available() if name.startswith(("example-", "problem-"))]


def parse(text: str, origin: str) -> dict[str, Any]:
    """Parse TOML text into a dict, or a ConfigError naming `origin`."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("scenario", f"{origin} is not valid TOML: {exc}") from None
    for key in data:
        if key not in SECTIONS + TOP_KEYS:
            raise ConfigError(key, f"unknown section or key in {origin}; a scenario has {', '.join(SECTIONS + TOP_KEYS)}")
    return data


def _files_relative_to(data: dict[str, Any], folder: Path) -> dict[str, Any]:
    """A relative `path` of a robot (a URDF file) and a relative `phi_hat0 = {file = …}` in a scenario file are
    relative to that file's folder."""
    plant, controller = data.get("plant"), data.get("controller")
    for section, key in ((data.get("robot"), "path"), (plant.get("robot") if isinstance(plant, dict) else None, "path"),
                         (controller.get("phi_hat0") if isinstance(controller, dict) else None, "file")):
        if isinstance(section, dict) and isinstance(section.get(key), str) and not Path(section[key]).is_absolute():
            section[key] = str(folder / section[key])
    return data


def read(name_or_path: str | Path) -> tuple[str, dict[str, Any]]:
    """Find a scenario by packaged name or file path and parse it."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ConfigError("scenario", f"no such file: {str(path)!r}") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError("scenario", f"cannot read {str(path)!r}: {exc}") from None
        return path.stem, _files_relative_to(parse(text, str(path)), path.parent)
    packaged = _packaged()
    if str(name_or_path) not in packaged:
        close = difflib.get_close_matches(str(name_or_path), list(packaged), n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ConfigError("scenario", f"unknown scenario {str(name_or_path)!r}{hint}; `robotadapt list` shows them all")
    name = str(name_or_path)
    return name, parse(packaged[name].read_text(encoding="utf-8"), name)


def parse_value(text: str) -> Any:
    """A `--set` value: any TOML value (`20`, `[10, 20]`, `"rk4"`, `true`), else the bare text as a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def override(data: dict[str, Any], assignment: str) -> None:
    """Apply one `section.key=value` (any depth: `plant.disturbance.amplitude=2`) to `data` in place; a whole section
    can be replaced by an inline table: `trajectory={kind = "exponential_step", final = 1, rate = 2}`."""
    key, sep, value = assignment.partition("=")
    parts = key.strip().split(".")
    parsed = parse_value(value.strip())
    if not sep or not all(parts) or (len(parts) < 2 and not isinstance(parsed, dict)):
        raise ConfigError("--set", "expected section.key=value (e.g. controller.Kv=20) or section={...}, "
                          f"got {assignment!r}")
    if parts[0] not in SECTIONS:
        raise ConfigError(parts[0], f"unknown section in --set {assignment!r}; sections are {', '.join(SECTIONS)}")
    if len(parts) == 1:
        data[parts[0]] = parsed
        return
    node = data.setdefault(parts[0], {})
    if not isinstance(node, dict):
        raise ConfigError(parts[0], f"must be a table [{parts[0]}], got {node!r}")
    for part in parts[1:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ConfigError(".".join(parts[:-1]), f"is a value, not a table, in --set {assignment!r}")
    node[parts[-1]] = parsed


def _check_study(data: dict[str, Any]) -> None:
    study = data.get("study", {})
    if not isinstance(study, dict):
        raise ConfigError("study", "expected a table of \"section.key\" = [values to try]")
    for key, values in study.items():
        if not isinstance(values, list) or not values:
            raise ConfigError(f"study.{key}", f"expected a non-empty list of values to try, got {values!r}")
        for value in values:  # each variant must build: errors name the study key
            trial = copy.deepcopy(data)
            trial.pop("study")
            try:
                override(trial, assignment(key, value))
                setup(trial)
            except ConfigError as exc:
                raise ConfigError(f"study.{key}", f"value {value!r} does not build: {exc}") from None


def load(name_or_path: str | Path, overrides: tuple[str, ...] | list[str] = ()) -> Scenario:
    """Read a scenario, apply `section.key=value` overrides, and validate every field by building it."""
    name, data = read(name_or_path)
    for item in overrides:
        override(data, item)
    scenario = Scenario(name, data, setup(data))
    _check_study(data)
    return scenario
