"""The measurement path: what a sampled-data controller sees of (q, q̇) at its ticks k = 0, 1, … (period Ts).

    q_m,k  = Δ round(q_k / Δ) + n_q,k                        encoder of resolution Δ (rad or m per count), then noise
    q̇_m,k = q̇_k + n_q̇,k                                    `velocity = "exact"` (a tachometer)
           = (q_m,k − q_m,k−1)/Ts + n_q̇,k                    `velocity = "difference"` (backward difference)
           = v_k + n_q̇,k,  v_k = a v_{k−1} + (1 − a)(q_m,k − q_m,k−1)/Ts,  a = exp(−2π f_c Ts)
                                                              `velocity = "filter"`: the difference through a
                                                              first-order low-pass of cutoff f_c (Hz), exact for a
                                                              difference held over the period
    q̈_m,k = (q̇_m,k − q̇_m,k−1)/Ts                           for controllers with acceleration feedback (Table 6.2.1)

n_q, n_q̇ are independent normal draws of standard deviation `noise_q`, `noise_dq` (per joint or one for all), from
`np.random.default_rng(seed)`: the same seed gives the same run bit for bit. At k = 0 the arm's initial velocity is known:
the first difference and the filter start from q̇(0) (q_m,−1 = q_m,0 − Ts q̇(0), v_{−1} = q̇(0)), and q̈_m,0 = 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..validation import ConfigError, as_scalar, as_vector

Array = Any
VELOCITY = ("exact", "difference", "filter")


@dataclass(frozen=True, eq=False)
class Sensor:
    """Encoder resolution, velocity estimate, noise and its seed (module docstring); None: that effect is absent."""

    n: int
    encoder_resolution: Any = None
    velocity: str = "exact"
    velocity_cutoff: Any = None
    noise_q: Any = None
    noise_dq: Any = None
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("encoder_resolution", "noise_q", "noise_dq"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, as_vector(getattr(self, name), self.n, f"plant.{name}", positive=True))
        if self.velocity not in VELOCITY:
            raise ConfigError("plant.velocity", f"expected one of {', '.join(VELOCITY)}; got {self.velocity!r}")
        if (self.velocity == "filter") != (self.velocity_cutoff is not None):
            raise ConfigError("plant.velocity_cutoff", "give the cutoff (Hz) exactly when velocity = 'filter'")
        if self.velocity_cutoff is not None:
            object.__setattr__(self, "velocity_cutoff",
                               as_scalar(self.velocity_cutoff, "plant.velocity_cutoff", positive=True))
        seed = self.seed
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ConfigError("plant.seed", f"expected a whole number ≥ 0, got {seed!r}")

    def start(self, q0: Array, dq0: Array, Ts: float) -> Measurement:
        """The running measurement path of one run, from the initial state."""
        q_m = self._quantize(np.asarray(q0, dtype=float))
        dq0 = np.asarray(dq0, dtype=float)
        a = 0.0 if self.velocity_cutoff is None else float(np.exp(-2 * np.pi * self.velocity_cutoff * Ts))
        return Measurement(self, Ts, a, np.random.default_rng(self.seed), q_m - Ts * dq0, dq0, None)

    def _quantize(self, q: Array) -> Array:
        if self.encoder_resolution is None:
            return q
        return self.encoder_resolution * np.round(q / self.encoder_resolution)

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {"velocity": self.velocity}
        if self.velocity_cutoff is not None:
            out["velocity_cutoff"] = self.velocity_cutoff
        for name in ("encoder_resolution", "noise_q", "noise_dq"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name).tolist()
        if self.noise_q is not None or self.noise_dq is not None:
            out["seed"] = int(self.seed)
        return out


@dataclass
class Measurement:
    """The state of one run's measurement path: the random generator and the previous samples (owned by the loop)."""

    sensor: Sensor
    Ts: float
    a: float
    rng: np.random.Generator
    q_prev: Array
    v_prev: Array
    dq_prev: Array | None

    def __call__(self, q: Array, dq: Array) -> tuple[Array, Array, Array]:
        """(q_m, q̇_m, q̈_m) at this tick from the true (q, q̇)."""
        s = self.sensor
        q_m = s._quantize(q)
        if s.noise_q is not None:
            q_m = q_m + s.noise_q * self.rng.standard_normal(s.n)
        if s.velocity == "exact":
            v = dq
        else:
            v = (q_m - self.q_prev) / self.Ts
            if s.velocity == "filter":
                v = self.a * self.v_prev + (1.0 - self.a) * v
        self.q_prev, self.v_prev = q_m, v
        dq_m = v if s.noise_dq is None else v + s.noise_dq * self.rng.standard_normal(s.n)
        ddq_m = np.zeros(s.n) if self.dq_prev is None else (dq_m - self.dq_prev) / self.Ts
        self.dq_prev = dq_m
        return q_m, dq_m, ddq_m
