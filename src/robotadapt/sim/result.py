"""The record of one closed-loop run: time-major arrays, named views and the status (arrays only: metrics come from
:mod:`robotadapt.analysis`, files and figures from :mod:`robotadapt.report`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .status import Status

Array = np.ndarray


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Arrays are time-major: `q[k]` is the joint position at `t[k]`; `x` is the controller state, `phi_hat` the
    estimate it holds, `V` the controller's Lyapunov function (None where the theory defines none), `r` its filtered
    error. `phi` is the true parameter vector when the controller's model matches the plant's, else None.
    `status` is a :class:`~robotadapt.sim.status.Status` record (code, t, reason) that reads ``"ok"`` or
    ``"diverged at t=… s: reason"``. `passivity` is the running integral ∫₀ᵗ −rᵀ Z φ̃ dσ of
    (6.4.4) for controllers with a regressor, when the truth is known: carried in the integrated state (RK4 at every
    step; the sum over the ticks in sampled-data runs), read at the logged instants (docs/monitors.md).
    `monitors` holds signals that need the controller (robotadapt.sim.outputs.controller_series): V_φ(t), λ_min(P⁻¹(t)).

    What to do with one — its metrics (`robotadapt.metrics`), saving (`robotadapt.save_result`), figures
    (`robotadapt.save_figures`) — on an arm of your own: docs/own-arm.md."""

    t: Array
    q: Array
    dq: Array
    x: Array
    q_des: Array
    dq_des: Array
    ddq_des: Array
    tau: Array
    V: Array | None
    r: Array | None
    phi_hat: Array
    phi: Array | None
    param_names: tuple[str, ...]
    state_names: tuple[str, ...]
    status: Status
    wall_time: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    passivity: Array | None = None
    monitors: dict[str, Array] = field(default_factory=dict)
    #: metrics folded at every step or tick of a fixed-step run, whatever its logging interval (robotadapt.sim.running)
    running: dict[str, Any] | None = None
    #: (e, ė) of a task-space law stacked, `(T, 2, m)`: x_d − x(q) and ẋ_d − J q̇ (its `q_des`, `dq_des`, `ddq_des`
    #: then hold x_d, ẋ_d, ẍ_d); None: e = q_des − q
    errors: Array | None = None

    def __repr__(self) -> str:
        """One line: status, samples, time span, joints, parameters and the final |e| (the arrays: `arrays()`)."""
        t, n = self.t, self.q.shape[-1] if self.q.ndim else 0
        span = f"t = {t[0]:.4g} … {t[-1]:.4g} s" if t.size else "no samples"
        names = ", ".join(self.param_names[:4]) + (", …" if len(self.param_names) > 4 else "")
        final = "[" + ", ".join(f"{v:.3g}" for v in np.abs(self.e[-1])) + "]" if t.size else "—"
        return (f"SimulationResult(status={self.status!r}, {t.size} samples, {span}, {n} joints, "
                f"{len(self.param_names)} parameters ({names}), final |e| = {final})")

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def space(self) -> str:
        """Where the tracking error lives: "joint" (e = q_des − q, rad) or "task" (e = x_d − x, m)."""
        return "joint" if self.errors is None else "task"

    @property
    def e(self) -> Array:
        """Tracking error e = q_des − q (a task-space law's x_d − x)."""
        return self.q_des - self.q if self.errors is None else self.errors[..., 0, :]

    @property
    def de(self) -> Array:
        """Velocity error ė = q̇_des − q̇ (a task-space law's ẋ_d − ẋ)."""
        return self.dq_des - self.dq if self.errors is None else self.errors[..., 1, :]

    @property
    def phi_true(self) -> Array | None:
        """The true φ at each sample, `(T, p)`, when known: its history when it changed during the run (a payload)."""
        if self.phi is None:
            return None
        return self.monitors.get("phi_true", np.broadcast_to(self.phi, self.phi_hat.shape))

    @property
    def phi_err(self) -> Array | None:
        """φ̃(t) = φ(t) − φ̂(t) when the truth is known."""
        truth = self.phi_true
        return None if truth is None else truth - self.phi_hat

    def arrays(self) -> dict[str, Array]:
        """Every array of the run by name (what :func:`robotadapt.report.files.save_result` writes to result.npz)."""
        out = {name: getattr(self, name) for name in ("t", "q", "dq", "q_des", "dq_des", "ddq_des", "tau", "x",
                                                         "phi_hat", "e", "de")}
        out["V"] = np.full(self.t.shape, np.nan) if self.V is None else self.V
        if self.r is not None:
            out["r"] = self.r
        if self.phi is not None:
            out["phi"] = self.phi
        if self.passivity is not None:
            out["passivity"] = self.passivity
        out.update(self.monitors)
        return out
