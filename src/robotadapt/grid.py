"""The run grid: the one place that turns a run's length into steps and logged instants.

A fixed-step run (RK4 steps of `dt`, or sampled-data ticks of the control period Ts) of length t_final takes

    n = ⌈t_final / h − 10⁻⁹⌉                                                           (the one rounding)

steps of h: the fewest whole steps that reach t_final, where a t_final within 10⁻⁹ of a step of a whole number of
steps is that number (floating-point division of 10.0 by 0.001 gives 10000.000000000002). The run's states are those
at t_k = k·h, k = 0 … n, so its last instant is n·h ≥ t_final (t_final = 1.0005 s with dt = 1 ms: 1001 steps, the
last state at 1.001 s). It logs every `log_every`-th of them: k = 0, log_every, 2·log_every, … ≤ n. Every engine
(numpy, JAX, C, sampled-data, batches, the error-controlled integrators' samples, the gradient rollout, sweeps,
tuning and the comparison) asks this grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

ROUNDING = 1e-9  # of a step: a t_final this close to a whole number of steps is that number


def steps(t_final: float, h: float) -> int:
    """n = ⌈t_final/h − 10⁻⁹⌉: the number of steps of h a run of length t_final takes (module docstring)."""
    return max(0, math.ceil(t_final / h - ROUNDING))


@dataclass(frozen=True)
class Grid:
    """The instants of a run: steps of `h` up to t_final, logged every `log_every` steps (module docstring)."""

    h: float
    t_final: float
    log_every: int = 1

    @classmethod
    def of(cls, integrator: Any, t_final: float, log_every: int = 1) -> Grid:
        """The grid of a fixed-step integrator's run: its control period for sampled-data control, else its `dt` (an
        error-controlled integrator's `dt` is the spacing of its samples)."""
        h = getattr(integrator, "control_period", None) or integrator.dt
        return cls(float(h), float(t_final), log_every)

    @property
    def n(self) -> int:
        """The number of steps."""
        return steps(self.t_final, self.h)

    @property
    def end(self) -> float:
        """The last instant n·h (≥ t_final, by less than one step)."""
        return self.n * self.h

    @property
    def samples(self) -> int:
        """How many instants are logged: k = 0, log_every, … ≤ n."""
        return self.n // self.log_every + 1

    def times(self, count: int | None = None) -> np.ndarray:
        """The logged instants k·log_every·h, the first `count` of them (default: all)."""
        return self.h * (self.log_every * np.arange(self.samples if count is None else count))
