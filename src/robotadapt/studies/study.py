"""One-at-a-time studies around a scenario: each `[study]` key is varied over its values with the rest held at the
scenario's setting (e.g. Problem 6.6-2: the effect of P(0) and of the filter pole a)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..analysis.metrics import metrics
from .scenarios.loader import assignment

if TYPE_CHECKING:
    from ..sim.result import SimulationResult
    from .scenarios import Scenario


@dataclass(frozen=True, eq=False)
class StudyRun:
    key: str
    value: Any
    result: SimulationResult


def run_study(scenario: Scenario, progress: bool = False) -> dict[str, list[StudyRun]]:
    """Simulate every variant of the scenario's study, grouped by the varied key."""
    return {key: [StudyRun(key, value, scenario.variant(assignment(key, value)).run(progress)) for value in values]
            for key, values in scenario.study.items()}


def summary(runs: dict[str, list[StudyRun]]) -> dict[str, list[dict[str, Any]]]:
    """The metrics of every variant, JSON-ready."""
    return {key: [{"value": run.value, **metrics(run.result)} for run in group] for key, group in runs.items()}
