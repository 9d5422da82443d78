"""Desired trajectories: `traj(t) -> Reference(q_des, dq_des, ddq_des)`, each of shape `t.shape + (n,)`.

All are frozen dataclasses with per-joint vectors fixed at construction (use :func:`robotadapt.validation` helpers or the
`make` constructors to broadcast scalars). Angular frequencies `omega` are in rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np

from .arrays import array_namespace
from .pytree import Module
from .validation import ConfigError, as_array, as_scalar, as_vector

Array = Any


class Reference(NamedTuple):
    """Desired position, velocity and acceleration at some instants, each `(..., n)`."""

    q_des: Array
    dq_des: Array
    ddq_des: Array


class Trajectory(Protocol):
    """A desired trajectory of `n` joints."""

    @property
    def n(self) -> int:
        """The number of joints (read-only: a dataclass field or a property)."""

    def __call__(self, t: Array) -> Reference:
        """(q_d, q̇_d, q̈_d) at `t` (a scalar or an array of instants), each of shape `t.shape + (n,)`."""


def _t(t: Array) -> tuple[Any, Array]:
    xp = array_namespace(t) if hasattr(t, "shape") else np
    return xp, xp.asarray(t, dtype=xp.float64)[..., None]


@dataclass(frozen=True, eq=False)
class SumOfSines(Module):
    """q_des,i(t) = offset_i + Σ_k A_ki sin(ω_k t + φ_ki): a sinusoid per joint (one row) or a persistently exciting sum.

    `amplitude` and `phase` have shape `(k, n)`, `omega` shape `(k,)` or `(k, n)`, `offset` shape `(n,)`.
    `period` is 2π/ω for a single frequency and the common period of commensurate frequencies, else None.
    """

    array_api: ClassVar[bool] = True  # its own code is array API: a compiled loop evaluates it

    per_run: ClassVar[tuple[str, ...]] = ("amplitude", "omega", "phase", "offset")  # varies per run in one vectorized batch

    amplitude: Array
    omega: Array
    phase: Array
    offset: Array

    @property
    def n(self) -> int:
        return int(self.offset.shape[-1])

    @property
    def period(self) -> float | None:
        w = np.unique(np.abs(self.omega[self.amplitude != 0]))
        w = w[w > 0]
        if w.size == 0:
            return None
        base = w.min()
        ratios = w / base
        for den in range(1, 13):  # commensurate to a small rational: T = 2π den / ω_min
            if np.allclose(ratios * den, np.round(ratios * den), rtol=0, atol=1e-9):
                return float(2 * np.pi * den / base)
        return None

    def __call__(self, t: Array) -> Reference:
        xp, tt = _t(t)
        tt = tt[..., None, :]  # (..., 1, 1) against (k, n)
        arg = self.omega * tt + self.phase
        s, c = xp.sin(arg), xp.cos(arg)
        q = self.offset + xp.sum(self.amplitude * s, axis=-2)
        dq = xp.sum(self.amplitude * self.omega * c, axis=-2)
        ddq = -xp.sum(self.amplitude * self.omega**2 * s, axis=-2)
        return Reference(q, dq, ddq)

    @classmethod
    def make(cls, n: int, amplitude: Any, omega: Any, phase: Any = 0.0, offset: Any = 0.0) -> SumOfSines:
        """The same as :func:`sum_of_sines`."""
        return sum_of_sines(n, amplitude, omega, phase, offset)


def sum_of_sines(n: int, amplitude: Any, omega: Any, phase: Any = 0.0, offset: Any = 0.0) -> SumOfSines:
    """q_des,i(t) = offset_i + Σ_k A_ik sin(ω_k t + φ_ik), validated and broadcast.

    Parameters
    ----------
    n : int
        Number of joints.
    amplitude, phase : number, list or table
        With a single frequency (`omega` a number): a number, or a list of `n` (one per joint).
        With a list of `k` frequencies: a number, a list of `k` (one per frequency, the same on every joint), or a table
        `amplitude[joint][frequency]` of `n` rows of `k`. Amplitudes in rad, phases in rad.
    omega : number or list
        The angular frequency, or the list of the `k` frequencies (rad/s).
    offset : number or list
        Constant offset per joint (rad).
    """
    w = as_array(omega, "trajectory.omega")
    if w.ndim > 1 or w.size == 0:
        raise ConfigError("trajectory.omega", f"expected a number or a list of frequencies, got shape {w.shape}")
    per_frequency = w.ndim == 1
    w = w.reshape(-1)
    tables = [_term_table(value, w.shape[0], n, f"trajectory.{name}", per_frequency)
              for name, value in (("amplitude", amplitude), ("phase", phase))]
    return SumOfSines(tables[0], np.repeat(w[:, None], n, axis=1), tables[1], as_vector(offset, n, "trajectory.offset"))


def _term_table(value: Any, k: int, n: int, field: str, per_frequency: bool) -> Array:
    """A `(k, n)` table of terms from a number, a list (per frequency with a list of frequencies, else per joint) or an
    `n`×`k` table `[joint][frequency]`."""
    arr = as_array(value, field)
    if arr.ndim == 0:
        return np.full((k, n), float(arr))
    if arr.ndim == 1:
        size, what = (k, "frequency") if per_frequency else (n, "joint")
        if arr.shape[0] != size:
            raise ConfigError(field, f"a list gives one value per {what}: expected {size}, got {arr.shape[0]}"
                              + (" (with omega a list, a list here is per frequency; per joint: a table of "
                                 f"{n} rows of {k})" if per_frequency and arr.shape[0] == n else ""))
        return np.broadcast_to(arr[:, None] if per_frequency else arr[None, :], (k, n)).copy()
    if arr.shape != (n, k):
        hint = " (transpose it: rows are joints)" if arr.shape == (k, n) else ""
        raise ConfigError(field, f"a table is {field.rsplit('.', 1)[-1]}[joint][frequency]: {n} rows of {k}, got shape "
                          f"{arr.shape}{hint}")
    return arr.T.copy()


def fourier(n: int, period: Any, a: Any, b: Any, offset: Any = 0.0) -> SumOfSines:
    """The finite Fourier series of exciting trajectories (Swevers et al. 1997), per joint i:

    q_i(t) = offset_i + Σ_{l=1..K} a_il/(ω_f l) sin(ω_f l t) − b_il/(ω_f l) cos(ω_f l t),   ω_f = 2π/period,

    so q̇_i = Σ a_il cos(ω_f l t) + b_il sin(ω_f l t). `a`, `b`: tables `[joint][harmonic]` of n rows of K (rad/s), or a
    list of K shared by every joint. Each harmonic is the sinusoid √(a² + b²)/(ω_f l) · sin(ω_f l t + atan2(−b, a)).
    """
    T = as_scalar(period, "trajectory.period", positive=True)
    tables = [as_array(v, f"trajectory.{name}") for name, v in (("a", a), ("b", b))]
    if tables[0].ndim not in (1, 2) or tables[0].shape[-1] == 0:
        raise ConfigError("trajectory.a", f"expected a list of K harmonics or a table of {n} rows of K, got {a!r}")
    k = tables[0].shape[-1]
    A, B = (_term_table(v, k, n, f"trajectory.{name}", True) for name, v in (("a", tables[0]), ("b", tables[1])))
    w = 2 * np.pi / T * np.arange(1, k + 1)
    return SumOfSines(np.hypot(A, B) / w[:, None], np.repeat(w[:, None], n, axis=1), np.arctan2(-B, A),
                      as_vector(offset, n, "trajectory.offset"))


def sinusoid(n: int, amplitude: Any = 1.0, omega: Any = 1.0, phase: Any = 0.0, offset: Any = 0.0) -> SumOfSines:
    """q_des,i = offset_i + A_i sin(ω_i t + φ_i), per joint (the book's `sin t` is the default)."""
    def row(value: Any, name: str) -> Array:
        return as_vector(value, n, f"trajectory.{name}")[None, :]

    return SumOfSines(row(amplitude, "amplitude"), row(omega, "omega"), row(phase, "phase"),
                      as_vector(offset, n, "trajectory.offset"))


@dataclass(frozen=True, eq=False)
class ExponentialStep(Module):
    """q_des = start + (final − start)(1 − e^{−a t}): the book's non-exciting `1 − e^{−2t}` (Example 6.5.1)."""

    array_api: ClassVar[bool] = True  # its own code is array API: a compiled loop evaluates it

    final: Array
    rate: Array
    start: Array

    n = property(lambda self: int(self.final.shape[-1]))
    period = None

    def __call__(self, t: Array) -> Reference:
        xp, tt = _t(t)
        decay = xp.exp(-self.rate * tt)
        span = self.final - self.start
        return Reference(self.start + span * (1 - decay), span * self.rate * decay, -span * self.rate**2 * decay)


@dataclass(frozen=True, eq=False)
class Quintic(Module):
    """Point-to-point quintic from `q0` at `t0` to `q1` at `t1`, zero velocity and acceleration at both ends; held after."""

    array_api: ClassVar[bool] = True  # its own code is array API: a compiled loop evaluates it

    q0: Array
    q1: Array
    t0: float
    t1: float

    n = property(lambda self: int(self.q0.shape[-1]))
    period = None

    def __post_init__(self) -> None:
        if not self.t1 > self.t0:
            raise ConfigError("trajectory.t1", f"must be later than t0 = {self.t0:g}, got {self.t1:g}")

    def __call__(self, t: Array) -> Reference:
        xp, tt = _t(t)
        T = self.t1 - self.t0
        s = xp.clip((tt - self.t0) / T, 0.0, 1.0)
        pos = 10 * s**3 - 15 * s**4 + 6 * s**5
        vel = (30 * s**2 - 60 * s**3 + 30 * s**4) / T
        acc = (60 * s - 180 * s**2 + 120 * s**3) / T**2
        d = self.q1 - self.q0
        return Reference(self.q0 + d * pos, d * vel, d * acc)


@dataclass(frozen=True, eq=False)
class Constant(Module):
    """A set point: q_des = value, q̇_des = q̈_des = 0."""

    array_api: ClassVar[bool] = True  # its own code is array API: a compiled loop evaluates it

    value: Array

    n = property(lambda self: int(self.value.shape[-1]))
    period = None

    def __call__(self, t: Array) -> Reference:
        xp, tt = _t(t)
        q = self.value + 0.0 * tt
        return Reference(q, 0.0 * q, 0.0 * q)


def exponential_step(n: int, final: Any = 1.0, rate: Any = 2.0, start: Any = 0.0) -> ExponentialStep:
    return ExponentialStep(as_vector(final, n, "trajectory.final"), as_vector(rate, n, "trajectory.rate", positive=True),
                           as_vector(start, n, "trajectory.start"))


def quintic(n: int, q0: Any, q1: Any, t0: Any = 0.0, t1: Any = 1.0) -> Quintic:
    return Quintic(as_vector(q0, n, "trajectory.q0"), as_vector(q1, n, "trajectory.q1"),
                   as_scalar(t0, "trajectory.t0"), as_scalar(t1, "trajectory.t1"))


def constant(n: int, value: Any) -> Constant:
    return Constant(as_vector(value, n, "trajectory.value"))


def traceable(trajectory: Trajectory) -> bool:
    """Whether `trajectory` is one of the package's trajectories (here and in :mod:`robotadapt.task_trajectories`, each
    declaring `array_api`), written in the array API of `t`: a compiled program can evaluate it itself
    (:class:`robotadapt.sim.loop.RK4Step`). A user's is sampled in Python and fed."""
    return bool(vars(type(trajectory)).get("array_api", False))  # declared by the class itself, not inherited
