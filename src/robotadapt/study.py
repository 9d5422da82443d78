"""One-at-a-time studies around a scenario: each `[study]` key is varied over its values with the rest held at the
scenario's setting (e.g. Problem 6.6-2: the effect of P(0) and of the filter pole a)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import tomli_w

if TYPE_CHECKING:
    from .result import SimulationResult
    from .scenarios import Scenario


@dataclass(frozen=True, eq=False)
class StudyRun:
    key: str
    value: Any
    result: SimulationResult


def toml_value(value: Any) -> str:
    """One TOML value on one line; a table as an inline table (`{kind = "pd", Lam = 5}`)."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{tomli_w.dumps({k: 0}).split(' = ')[0]} = {toml_value(v)}" for k, v in value.items()) + "}"
    return tomli_w.dumps({"v": value})[4:].strip()


def assignment(key: str, value: Any) -> str:
    """`key=value` with the value written as TOML (what `--set` parses)."""
    return f"{key}={toml_value(value)}"


def run_study(scenario: Scenario, progress: bool = False) -> dict[str, list[StudyRun]]:
    """Simulate every variant of the scenario's study, grouped by the varied key."""
    return {key: [StudyRun(key, value, scenario.variant(assignment(key, value)).run(progress)) for value in values]
            for key, values in scenario.study.items()}


def summary(runs: dict[str, list[StudyRun]]) -> dict[str, list[dict[str, Any]]]:
    """The metrics of every variant, JSON-ready."""
    return {key: [{"value": run.value, **run.result.metrics()} for run in group] for key, group in runs.items()}
