"""Repetitive (learning) control law of Sadegh, Horowitz, Kao & Tomizuka (docs/laws.md#repetitive, Table 7.2.2)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..arrays import array_namespace, matvec, quad
from ..pytree import Module
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_scalar, as_vector, scalar_gain
from .base import Array, Law, errors
from .registry import Contender

_MAX_TABLE_BYTES = 2.5e8  # beyond this, Y_d over one period is evaluated on line, not tabulated
_CHUNK = 4096  # instants per vectorized regressor call while tabulating


@dataclass(frozen=True, eq=False)
class PeriodicRegressorTable(Module):
    """Y_d = Y(q_d, q̇_d, q̇_d, q̈_d) (7.2.4) over one period on the half-step grid t = i·h, i = 0 … 2N − 1 (h = T/2N =
    dt/2, what RK4's stages visit); T-periodic (7.2.30), so read at t mod T for every t of the run."""

    h: float
    values: Array

    def lookup(self, t: Array) -> Array | None:
        """Y_d at `t` if every instant lies on the grid modulo the period (numpy), else None (the caller then
        evaluates on line)."""
        size = self.values.shape[0]
        period = size * self.h
        if isinstance(t, float | int):  # the hot path: one instant, plain arithmetic
            phase = t % period
            i = round(phase / self.h)
            return self.values[i % size] if abs(i * self.h - phase) <= 1e-9 else None
        if array_namespace(t) is not np:  # traced by the compiled backend: Y_d is evaluated inside the program
            return None
        phase = np.mod(np.asarray(t, dtype=float), period)
        k = np.rint(phase / self.h).astype(int)
        if not np.allclose(k * self.h, phase, rtol=0, atol=1e-9):
            return None
        return self.values[k % size]


@dataclass(frozen=True, eq=False)
class Repetitive(Law):
    """Repetitive control law (Table 7.2.2) for a T-periodic desired trajectory:

    r = ė + e,   τ = û_d(t) + k_v r + k_p e + k_a ‖e‖² r                                     (7.2.31)
    û_d(t) = û_d(t − T) + k_L r(t)                     (plain learning law, 7.2.32)
    û_d(t) = sat(û_d(t − T)) + k_L r(t)                (saturated form of Problem 7.2-4, with `u_min`, `u_max`)

    û_d learns the repeatable dynamics u_d(t) = Y_d φ (7.2.29): the torque and the learning law need no regressor and
    no model. û_d(t − T) is read from a delay line of N = T/dt samples (the step must divide the period) and held over
    each step; û_d = 0 on [−T, 0). With `rounded_delay` (what `robotadapt compare` sets to keep a scenario's step) a
    step that does not divide T is accepted and N = round(T/dt): the law is (7.2.32) with the delay T' = N·dt, within
    dt/2 of T, so u_d(t) − u_d(t − T') = O(|T − T'|·‖u̇_d‖) enters (7.2.34) each period, e → 0 becomes a residual of
    that order, and V's window integrals run over T'. The saturation bounds must contain u_d(t) along the trajectory.
    `period` defaults to the trajectory's own. Guarantee: e → 0, ė bounded (→ 0 with the saturated form).

    Lyapunov function (7.2.43), evaluated by :meth:`lyapunov` with the true φ (monitors only):

        V = ½ rᵀ M(q) r + ½ k_p eᵀe + (1/2k_L) ∫_{t−T}^{t} ũ_dᵀ ũ_d dσ,    ũ_d = u_d − û_d  (7.2.33)

    Its integral runs over the last period, which the logged samples would give only to the accuracy of the logging
    rate. With u_d = Y_d φ (7.2.29) and Y_d T-periodic (7.2.30) it splits into parts the law can carry without φ:

        (1/2k_L) ∫_{t−T}^{t} ‖ũ_d‖² dσ = φᵀ G φ / 2k_L − φᵀ w_Ydu(t) + w_uu(t),     G = ∫_0^T Y_dᵀ Y_d dσ,
        w_Ydu(t) = (1/k_L) ∫_{t−T}^{t} Y_dᵀ û_d dσ,     w_uu(t) = (1/2k_L) ∫_{t−T}^{t} ‖û_d‖² dσ.

    :meth:`prepare` computes G (Simpson's rule on the half-step grid: exact to round-off for a smooth periodic
    integrand); G holds no gain, so k_L may change after it (a traced k_L in tuning): every 1/k_L is taken where it
    is used. The state carries w = [w_Ydu, w_uu] and the current step's part of it, c (p + 1 values each):
    dc/dt = [Y_dᵀ û_d / k_L, ‖û_d‖² / 2k_L] with the û_d the torque uses (held + k_L r(σ) at every RK4 stage), and at
    the sample of step k the law moves the window, w ← w + c − c_{k−N}, c ← 0, where c_{k−N}, the part of the step one
    period earlier, is read from the delay line, which stores c next to û_d(t_k) (0 on [−T, 0), where û_d = 0). So at
    every sample instant t_k, where the log is, w is the integral over [t_k − T, t_k] to RK4's error on it, whatever
    the logging rate; V(0) = φᵀGφ / 2k_L, from the integral of ‖u_d‖² over [−T, 0). In the sampled-data loop the
    discrete rule sums c over the ticks (û_d and Y_d at the tick: the rectangle rule), and V is (7.2.43) to O(Ts) in
    the first period, to round-off after it. Y_d comes from a table over one period (:class:`PeriodicRegressorTable`,
    numpy) or is evaluated on line (compiled runs, off-grid instants); the torque does not use it. State
    x = [û_d(t_k − T) held (n), w (p + 1), c (p + 1)].

    The book's claim (7.2.44)–(7.2.49): dV/dt = −(k_v + k_L/2)‖r‖² − k_p‖e‖² − k_a‖e‖²‖r‖² + rᵀũ ≤ −λ₃‖[e, r]‖² when
    the gain conditions (7.2.22), (7.2.25), (7.2.48) hold, so V does not increase. The identity (7.2.45) uses
    û_d(t − T) at every instant; the law holds û_d(t_k − T) over the step, O(dt) from it, and dV/dt is off by as much.
    With the saturation (Problem 7.2-4), bounds that contain u_d give ‖u_d − sat(û_d(t − T))‖ ≤ ‖u_d − û_d(t − T)‖,
    so the same V satisfies (7.2.47).
    """

    kind = "repetitive"
    tuned = ("Kv", "Kp", "Ka", "kL")
    family = "7.2"
    lineup = (Contender("repetitive", "repetitive (learning)", "Table 7.2.2", "Example 7.2.2; T = the trajectory's period",
                        {"kind": "repetitive", "Kv": 50.0, "Kp": 50.0, "Ka": 50.0, "kL": 50.0}, rank=100),)

    model: RobotModel
    Kv: Any
    Kp: Any
    Ka: Any
    kL: Any
    period: Any = None
    u_min: Any = None
    u_max: Any = None
    gram: Any = field(default=None, metadata={"internal": True})  # G = ∫_0^T Y_dᵀY_d (no gain in it), from `prepare`
    table: PeriodicRegressorTable | None = field(default=None, metadata={"internal": True})
    rounded_delay: bool = False  # N = round(T/dt) (class docstring)

    def __post_init__(self) -> None:
        for name in ("Kv", "Kp", "Ka", "kL"):
            object.__setattr__(self, name, scalar_gain(getattr(self, name), f"controller.{name}"))
        if self.period is not None:
            object.__setattr__(self, "period", as_scalar(self.period, "controller.period", positive=True))
        if (self.u_min is None) != (self.u_max is None):
            raise ConfigError("controller.u_min", "give both u_min and u_max for the saturated law, or neither")
        if self.u_min is not None:
            lo = as_vector(self.u_min, self.model.n, "controller.u_min")
            hi = as_vector(self.u_max, self.model.n, "controller.u_max")
            if not np.all(lo < hi):
                raise ConfigError("controller.u_max", f"must exceed u_min component-wise, got {lo} and {hi}")
            object.__setattr__(self, "u_min", lo)
            object.__setattr__(self, "u_max", hi)

    @property
    def records(self) -> int:
        """The trailing entries of x only V's monitor reads (w and c): the divergence guard skips them."""
        return 2 * (self.model.p + 1)

    @property
    def state_names(self) -> tuple[str, ...]:
        n, names = self.model.n, self.model.param_names
        window = tuple(f"w_Ydu_{name}" for name in names) + ("w_uu",)
        return tuple(f"u_hat_past{i + 1}" for i in range(n)) + window + tuple(f"step_{name}" for name in window)

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        """û_d = 0 on [−T, 0): nothing held, nothing learnt in the window (w = 0), no increment yet (c = 0)."""
        return np.zeros(self.model.n + 2 * (self.model.p + 1))

    def phi_hat(self, x: Array) -> Array:
        """No parameter estimate: the law learns a signal, not φ."""
        return x[..., :0]

    def prepare(self, trajectory: Any, dt: float, t_final: float) -> Repetitive:
        """Take the period from the trajectory when none is given; check that the trajectory repeats with it (7.2.30)
        and that the step divides it (or, with `rounded_delay`, is at most 2T); tabulate Y_d over one period on the
        half-step grid and compute G for V."""
        declares = hasattr(trajectory, "period")  # a trajectory class without the attribute: trust `period`
        own: float | None = trajectory.period if declares else None
        if declares and own is None:
            raise ConfigError("controller.period", "the desired trajectory is not periodic: the repetitive law needs "
                              "q_d(t) = q_d(t − T) (7.2.30)")
        period: float | None = self.period if self.period is not None else own
        if period is None:
            raise ConfigError("controller.period", "give controller.period: the trajectory does not say its period")
        if own is not None and abs(period / own - round(period / own)) > 1e-9 * period / own:
            raise ConfigError("controller.period", f"T = {period:.10g} s is not a multiple of the trajectory's period "
                              f"{own:.10g} s")
        steps = period / dt
        if abs(steps - round(steps)) > 1e-6 * steps and not (self.rounded_delay and round(steps) >= 1):
            raise ConfigError("simulation.dt", f"the period T = {period:.10g} s must be a whole number of steps; "
                              f"use dt = T/N, e.g. dt = {period / max(round(steps), 1):.17g}")
        n_half, p = 2 * round(steps), self.model.p
        h = period / n_half
        keep = 8.0 * n_half * self.model.n * p <= _MAX_TABLE_BYTES
        gram, chunks = np.zeros((p, p)), []
        for start in range(0, n_half, _CHUNK):
            i = np.arange(start, min(start + _CHUNK, n_half))
            ref = trajectory(h * i)
            Yd = np.asarray(self.model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des), dtype=float)
            weight = np.where(i % 2 == 0, 1.0, 2.0) * (2.0 * h / 3.0)  # Simpson, with Y_d(T) = Y_d(0)
            gram = gram + np.einsum("k,kni,knj->ij", weight, Yd, Yd)
            if keep:
                chunks.append(Yd)
        table = PeriodicRegressorTable(h, np.concatenate(chunks)) if keep else None
        return replace(self, period=period, gram=gram, table=table)

    def delay_line(self, dt: float, q0: Array, dq0: Array) -> Array:
        """û_d on [−T, 0) and the steps' increments of w there: zeros, N = T/dt (rounded) samples of n + p + 1
        values."""
        return np.zeros((round(self.period / dt), self.model.n + self.model.p + 1))

    def desired_regressor(self, t: Array, ref: Reference) -> Array:
        """Y_d(q_d, q̇_d, q̈_d) (7.2.4), for V's window integrals only: from the table when `t` is on its grid, else
        evaluated."""
        if self.table is not None:
            Yd = self.table.lookup(t)
            if Yd is not None:
                return Yd
        return self.model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)

    def _parts(self, x: Array) -> tuple[Array, Array, Array]:
        """(û_d held, w, c) of the state x."""
        n, m = self.model.n, self.model.p + 1
        return x[..., :n], x[..., n : n + m], x[..., n + m :]

    def sample(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, past: Array) -> tuple[Array, Array]:
        """Hold sat(û_d(t − T)) for this step; store û_d(t) = that + k_L r(t) and the last step's increment c of w;
        move the window: w ← w + c − (the increment stored one period ago), c ← 0 (class docstring). Pure (array
        API): the simulator keeps the line in its carried state, numpy or compiled."""
        n = self.model.n
        _, w, c = self._parts(x)
        xp = array_namespace(x, past)
        u_past, c_past = past[..., :n], past[..., n:]
        held = u_past if self.u_min is None else xp.clip(u_past, self.u_min, self.u_max)
        u_hat = held + self.kL * self.filtered_error(t, x, q, dq, ref)
        return xp.concatenate([held, (w + c) - c_past, 0.0 * c], axis=-1), xp.concatenate([u_hat, c], axis=-1)

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        e, de = errors(q, dq, ref)
        return de + e

    def learned(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """û_d(t) = (held past value) + k_L r(t)."""
        return x[..., : self.model.n] + self.kL * self.filtered_error(t, x, q, dq, ref)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        e, de = errors(q, dq, ref)
        r = de + e
        u_hat = x[..., : self.model.n] + self.kL * r
        tau = u_hat + (self.Kv + self.Ka * (e * e).sum(axis=-1, keepdims=True)) * r + self.Kp * e
        return tau, self._rate(t, x, u_hat, ref)

    def _rate(self, t: Array, x: Array, u_hat: Array, ref: Reference) -> Array:
        """dx/dt = [0 (û_d held), 0 (w, moved at the samples), dc/dt = [Y_dᵀ û_d / k_L, ‖û_d‖² / 2k_L]]."""
        Yd = self.desired_regressor(t, ref)
        xp = array_namespace(x, u_hat)
        if xp is np:  # the hot path: fill a fresh array (numpy only; traced code concatenates, without writes)
            m = self.model.p + 1
            dx = np.zeros(u_hat.shape[:-1] + (x.shape[-1],))
            dx[..., -m:-1] = (u_hat @ Yd if Yd.ndim == 2 else matvec(Yd.mT, u_hat)) / self.kL
            dx[..., -1] = np.vecdot(u_hat, u_hat) / (2.0 * self.kL)
            return dx
        dc = xp.concatenate([matvec(Yd.mT, u_hat) / self.kL,
                             (u_hat * u_hat).sum(axis=-1, keepdims=True) / (2.0 * self.kL)], axis=-1)
        return xp.concatenate([0.0 * u_hat, 0.0 * dc, dc], axis=-1)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """V of (7.2.43) with the true φ: ½ rᵀ M r + ½ k_p eᵀe + φᵀGφ / 2k_L − φᵀ w_Ydu + w_uu (class docstring), at
        the sample instants (where the log is)."""
        if self.gram is None:
            raise ConfigError("controller", "V of the repetitive law needs G from prepare(trajectory, dt, t_final)")
        e, de = errors(q, dq, ref)
        r = de + e
        _, w, _ = self._parts(x)
        p = self.model.p
        M = self.model.mass_matrix(q, phi)
        learning = quad(phi, self.gram) / (2.0 * self.kL) - (phi * w[..., :p]).sum(axis=-1) + w[..., p]
        return 0.5 * (r * matvec(M, r)).sum(axis=-1) + 0.5 * self.Kp * (e * e).sum(axis=-1) + learning
