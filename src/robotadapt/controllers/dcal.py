"""Desired compensation adaptation law of Sadegh & Horowitz (docs/laws.md#dcal, Table 7.2.1)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace, matvec
from ..grid import steps
from ..pytree import Module
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, scalar_gain
from .base import Array, EstimateState, errors
from .registry import Contender

_MAX_TABLE_BYTES = 2e9


@dataclass(frozen=True, eq=False)
class DesiredRegressorTable(Module):
    """Y_d sampled on the half-step grid t = k·h of a fixed-step run (h = dt/2, what RK4's stages visit)."""

    h: float
    values: Array

    def lookup(self, t: Array) -> Array | None:
        """Y_d at `t` if every instant lies on the grid, else None (the caller then evaluates on line)."""
        if isinstance(t, float | int):  # the hot path: one instant, plain arithmetic
            i = round(t / self.h)
            return self.values[i] if 0 <= i < self.values.shape[0] and abs(i * self.h - t) <= 1e-9 else None
        if array_namespace(t) is not np:  # traced by the compiled backend: Y_d is evaluated inside the program
            return None
        k = np.rint(np.asarray(t) / self.h).astype(int)
        if np.any(k < 0) or np.any(k >= self.values.shape[0]) or not np.allclose(k * self.h, t, rtol=0, atol=1e-9):
            return None
        return self.values[k]


@dataclass(frozen=True, eq=False)
class DCAL(EstimateState):
    """Desired compensation adaptation law (Table 7.2.1):

    r = ė + e                                                (7.2.6)
    τ = Y_d φ̂ + k_v r + k_p e + k_a ‖e‖² r                  (7.2.5),  Y_d = Y(q_d, q̇_d, q̇_d, q̈_d)   (7.2.4)
    dφ̂/dt = Γ Y_dᵀ r                                         (7.2.7)
    V = ½ rᵀ M r + ½ k_p eᵀe + ½ φ̃ᵀ Γ⁻¹ φ̃                   (7.2.14)

    Y_d depends only on the desired trajectory, so with `precompute = true` it is tabulated before the run on the
    simulation grid and read, not evaluated, on line (the point of §7.2). V is non-increasing when the gain conditions
    (7.2.22), (7.2.25), (7.2.26) hold. `k_v, k_p, k_a` are scalars, as in the book's analysis. `adaptation = "natural"`
    with `gamma`: the natural law on b = Y_dᵀ r, its divergence in V (docs/natural.md); `adaptation = "pullback"` with
    `gamma` and `phi_ref` (default φ̂(0)): the constant pullback metric on the same b, its quadratic form in V.
    """

    per_run: ClassVar[tuple[str, ...]] = ("phi_hat0",)  # varies per run in one vectorized batch

    kind = "dcal"
    tuned = ("Kv", "Kp", "Ka", "Gamma")
    family = "7.2"
    lineup = (Contender("dcal", "DCAL", "Table 7.2.1", "Example 7.2.1",
                        {"kind": "dcal", "Kv": 50.0, "Kp": 50.0, "Ka": 50.0, "Gamma": 20.0, "precompute": True}, rank=90,
                        book_kv="Examples 7.2.1–7.2.2"),)

    model: RobotModel
    Kv: Any
    Kp: Any
    Ka: Any
    Gamma: Any = None
    phi_hat0: Any = None
    precompute: bool = False
    table: DesiredRegressorTable | None = field(default=None, metadata={"internal": True})
    adaptation: str = "euclidean"
    gamma: Any = None
    phi_ref: Any = None

    def __post_init__(self) -> None:
        for name in ("Kv", "Kp", "Ka"):
            object.__setattr__(self, name, scalar_gain(getattr(self, name), f"controller.{name}"))
        if not isinstance(self.precompute, bool):
            raise ConfigError("controller.precompute", f"expected true or false, got {self.precompute!r}")
        self.adapts()

    def prepare(self, trajectory: Any, dt: float, t_final: float) -> DCAL:
        """With `precompute`, tabulate Y_d at every RK4 stage instant of the run (half steps up to t_final)."""
        if not self.precompute:
            return self
        n_half = 2 * steps(t_final, dt) + 1
        nbytes = 8.0 * n_half * self.model.n * self.model.p
        if nbytes > _MAX_TABLE_BYTES:
            raise ConfigError("controller.precompute", f"the Y_d table would take {nbytes / 1e9:.1f} GB; "
                              "use precompute = false or a coarser dt")
        ref = trajectory(0.5 * dt * np.arange(n_half))
        return replace(self, table=DesiredRegressorTable(0.5 * dt, self._evaluate(ref)))

    def _evaluate(self, ref: Reference) -> Array:
        return self.model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)

    def desired_regressor(self, t: Array, ref: Reference) -> Array:
        """Y_d(q_d, q̇_d, q̈_d) (7.2.4): from the table when precomputed and `t` is on its grid, else evaluated."""
        if self.table is not None:
            Yd = self.table.lookup(t)
            if Yd is not None:
                return Yd
        return self._evaluate(ref)

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        e, de = errors(q, dq, ref)
        return de + e

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        e, de = errors(q, dq, ref)
        r = de + e
        Yd = self.desired_regressor(t, ref)
        tau = matvec(Yd, self.phi_hat(x)) + (self.Kv + self.Ka * (e * e).sum(axis=-1, keepdims=True)) * r + self.Kp * e
        return tau, self.geometry.rate(x, matvec(Yd.mT, r))

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """V of (7.2.14) with the true φ."""
        e, de = errors(q, dq, ref)
        r = de + e
        M = self.model.mass_matrix(q, phi)
        return 0.5 * (r * matvec(M, r)).sum(axis=-1) + 0.5 * self.Kp * (e * e).sum(axis=-1) + self.geometry.lyapunov(
            x, phi)
