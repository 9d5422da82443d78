"""Saving a run: `result.npz`, `metrics.json` and the scenario that produced it, each written atomically."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis.metrics import metrics
from ..files import atomic_write, writable_dir
from ..sim.result import SimulationResult


def save_result(result: SimulationResult, directory: str | os.PathLike[str], scenario_text: str | None = None,
                model: Any = None) -> Path:
    """Write `result.npz` (the arrays of the run, and `x_names`, the name of each column of the controller's state
    `x`), `metrics.json` (:func:`robotadapt.analysis.metrics.metrics`, in base parameters too when the controller's
    `model` is given and has unidentifiable directions) and, if given, `scenario.toml` into `directory`, each
    atomically; returns the folder."""
    out = writable_dir(directory)
    arrays: dict[str, Any] = {**result.arrays(), "x_names": np.array(result.state_names, dtype=str)}
    atomic_write(out / "result.npz", lambda f: np.savez_compressed(f, **arrays), binary=True)
    atomic_write(out / "metrics.json", lambda f: json.dump(metrics(result, model), f, indent=2))
    if scenario_text is not None:
        atomic_write(out / "scenario.toml", lambda f: f.write(scenario_text))
    return out
