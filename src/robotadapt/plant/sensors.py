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
`np.random.default_rng(seed)`, in the order tick 0 (n_q,0 then n_q̇,0, each only if set), tick 1, …: the same seed gives the
same run bit for bit. The loop draws them ahead, a block of ticks at a time (:meth:`Sensor.noise`; one draw of many numbers
is the same stream as many draws of one), and hands each tick its row, so the numpy and the compiled loops see the same
numbers. At k = 0 the arm's initial velocity is known: the first difference and the filter start from q̇(0)
(q_m,−1 = q_m,0 − Ts q̇(0), v_{−1} = q̇(0)), and q̈_m,0 = 0.

The sensor is pure: the measurement path's state (q_m,k−1, v_k−1, q̇_m,k−1 and whether k = 0) comes in and goes out,
`(q_m, q̇_m, q̈_m), state = sensor.measure(state, q, q̇, noise, Ts)`, written against the array API of its inputs (numpy,
or JAX inside the compiled loop).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import array_namespace
from ..pytree import Module, host
from ..validation import ConfigError, as_scalar, as_vector

Array = Any
VELOCITY = ("exact", "difference", "filter")
State = tuple[Array, Array, Array, Array]  # (q_m,k−1, v_k−1, q̇_m,k−1, k = 0)


@dataclass(frozen=True, eq=False)
class Sensor(Module):
    """Encoder resolution, velocity estimate, noise and its seed (module docstring); None: that effect is absent."""

    n: int
    encoder_resolution: Any = None
    velocity: str = "exact"
    velocity_cutoff: Any = None
    noise_q: Any = None
    noise_dq: Any = None
    seed: int = host(0)  # read by the feed on the host only: runs that differ in it share one program

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

    def start(self, q0: Array, dq0: Array, Ts: float) -> State:
        """The measurement path's state before tick 0, from the initial state (module docstring)."""
        xp = array_namespace(q0, dq0)
        if xp is np:
            q0, dq0 = np.asarray(q0, dtype=float), np.asarray(dq0, dtype=float)
        return self.quantize(q0) - Ts * dq0, dq0, xp.zeros(self.n), xp.asarray(True)

    def first_measurement(self, q0: Array, dq0: Array, Ts: float) -> tuple[Array, Array]:
        """(q_m, q̇_m) at tick 0 from the initial state: the run's first draws, as the run itself makes them (the draws
        of a block are those of the ticks one after another)."""
        (q_m, dq_m, _), _ = self.measure(self.start(q0, dq0, Ts), q0, dq0, self.noise(self.generator(), 1)[0], Ts)
        return q_m, dq_m

    def generator(self) -> np.random.Generator:
        """The run's random generator, from `seed`."""
        return np.random.default_rng(self.seed)

    def noise(self, rng: np.random.Generator, count: int) -> Array:
        """The standard normal draws of the next `count` ticks from `rng`, shape `(count, 2, n)`: row 0 for q, row 1
        for q̇, zeros for a noise that is not set (nothing drawn for it), in the order of the module docstring."""
        sources = (self.noise_q is not None, self.noise_dq is not None)
        draws = iter(np.moveaxis(rng.standard_normal((count, sum(sources), self.n)), 1, 0))
        return np.stack([next(draws) if on else np.zeros((count, self.n)) for on in sources], axis=1)

    def coefficient(self, Ts: float) -> float:
        """The velocity filter's a = exp(−2π f_c Ts) (0 without a filter)."""
        return 0.0 if self.velocity_cutoff is None else float(np.exp(-2 * np.pi * self.velocity_cutoff * Ts))

    def quantize(self, q: Array) -> Array:
        """Δ round(q/Δ), or q itself without an encoder (ties to even)."""
        if self.encoder_resolution is None:
            return q
        return self.encoder_resolution * array_namespace(q).round(q / self.encoder_resolution)

    def measure(self, state: State, q: Array, dq: Array, noise: Array, Ts: float) -> tuple[tuple[Array, Array, Array],
                                                                                           State]:
        """((q_m, q̇_m, q̈_m), next state) at this tick from the true (q, q̇) and the tick's draws `noise` `(2, n)`."""
        xp = array_namespace(q, dq)
        q_prev, v_prev, dq_prev, first = state
        q_m = self.quantize(q)
        if self.noise_q is not None:
            q_m = q_m + self.noise_q * noise[0]
        v = dq
        if self.velocity != "exact":
            v = (q_m - q_prev) / Ts
            if self.velocity == "filter":
                a = self.coefficient(Ts)
                v = a * v_prev + (1.0 - a) * v
        dq_m = v if self.noise_dq is None else v + self.noise_dq * noise[1]
        ddq_m = xp.where(first, 0.0, (dq_m - dq_prev) / Ts)
        return (q_m, dq_m, ddq_m), (q_m, v, dq_m, xp.zeros_like(first))

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
