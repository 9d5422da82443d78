"""Gain conditions of §7.2: the bounding constants ζ1…ζ4 of (7.2.9) estimated for an arm, a parameter vector and a
desired trajectory, and the checks (7.2.22), (7.2.25), (7.2.26) (DCAL) and (7.2.48) (repetitive law).

The ζ_i are not unique and the book never computes them. Here they are *estimated*: errors e and filtered errors r are
sampled in a ball around the desired trajectory (‖e‖ ≤ radius, ‖r‖ ≤ radius, along one period or the run), the mismatch
Ỹ = Y(q, q̇, q̇_d + e, q̈_d + ė) φ − Y_d φ (7.2.10) is evaluated with q = q_d − e, ė = r − e, and the smallest
non-negative ζ with ‖Ỹ‖ ≤ ζ1‖e‖ + ζ2‖e‖² + ζ3‖r‖ + ζ4‖r‖‖e‖ at every sample is found by a linear program. Since any
valid ζ proves stability, the program picks the set most favourable to the conditions: it minimises the sum of their
right-hand sides, ζ1 + 1.25 ζ2 + ζ3 + 1.25 ζ4. A verdict therefore holds for the sampled ball, not as a proof.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .robots.base import RobotModel
from .validation import ConfigError


@dataclass(frozen=True)
class GainReport:
    zeta: tuple[float, float, float, float]
    radius: float
    samples: int
    conditions: dict[str, dict[str, Any]]

    @property
    def all_hold(self) -> bool:
        return all(c["holds"] for c in self.conditions.values())

    def as_dict(self) -> dict[str, Any]:
        return {"zeta": list(self.zeta), "radius": self.radius, "samples": self.samples,
                "conditions": self.conditions, "all_hold": self.all_hold,
                "note": "zeta estimated by sampling errors in a ball; a verdict holds for that ball, not as a proof"}


def _mismatch(model: RobotModel, phi: np.ndarray, ref: Any, e: np.ndarray, r: np.ndarray) -> np.ndarray:
    """‖Ỹ‖ of (7.2.10) for sampled errors (leading axes shared with `ref`)."""
    de = r - e
    q, dq = ref.q_des - e, ref.dq_des - de
    Y = model.regressor(q, dq, ref.dq_des + e, ref.ddq_des + de)
    Yd = model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)
    return np.linalg.norm((Y - Yd) @ phi, axis=-1)


def estimate_zeta(model: RobotModel, phi: np.ndarray, trajectory: Any, t_span: float, radius: float = 1.0,
                  samples: int = 4000, rng: np.random.Generator | None = None) -> tuple[float, float, float, float]:
    """Estimate ζ1…ζ4 of (7.2.9) by a linear program over sampled (t, e, r) with ‖e‖, ‖r‖ ≤ `radius`."""
    from scipy.optimize import linprog

    rng = np.random.default_rng(0) if rng is None else rng
    n = model.n
    t = rng.uniform(0.0, t_span, samples)

    def ball() -> np.ndarray:
        d = rng.normal(size=(samples, n))
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return d * radius * rng.uniform(0.0, 1.0, (samples, 1)) ** (1.0 / n)

    e, r = ball(), ball()
    y = _mismatch(model, phi, trajectory(t), e, r)
    ne, nr = np.linalg.norm(e, axis=-1), np.linalg.norm(r, axis=-1)
    features = np.stack([ne, ne**2, nr, nr * ne], axis=-1)
    cost = np.array([1.0, 1.25, 1.0, 1.25])  # sum of the right-hand sides of (7.2.22), (7.2.25), (7.2.26)
    sol = linprog(cost, A_ub=-features, b_ub=-y, bounds=[(0, None)] * 4, method="highs")
    if not sol.success:
        raise ConfigError("gains", f"could not fit the bound (7.2.9): {sol.message}")
    return tuple(float(z) for z in sol.x)  # type: ignore[return-value]


def check(zeta: tuple[float, float, float, float], Kv: float, Kp: float, Ka: float,
          kL: float | None = None) -> dict[str, dict[str, Any]]:
    """Evaluate the gain conditions; (7.2.48) replaces (7.2.26) for the repetitive law (k_L given)."""
    z1, z2, z3, z4 = zeta
    rows = {
        "7.2.22": ("k_a > ζ2 + ζ4", Ka, z2 + z4),
        "7.2.25": ("k_p > ζ1/2 + ζ2/4", Kp, z1 / 2 + z2 / 4),
    }
    if kL is None:
        rows["7.2.26"] = ("k_v > ζ1/2 + ζ3 + ζ4/4", Kv, z1 / 2 + z3 + z4 / 4)
    else:
        rows["7.2.48"] = ("k_v + k_L/2 > ζ1/2 + ζ3 + ζ4/4", Kv + kL / 2, z1 / 2 + z3 + z4 / 4)
    return {eq: {"condition": text, "gain": float(lhs), "bound": float(rhs), "holds": bool(lhs > rhs)}
            for eq, (text, lhs, rhs) in rows.items()}


def gain_report(controller: Any, phi: np.ndarray, trajectory: Any, t_span: float, radius: float = 1.0,
                samples: int = 4000) -> GainReport:
    """ζ estimates and the conditions for a DCAL or repetitive controller."""
    from .controllers.dcal import DCAL
    from .controllers.repetitive import Repetitive

    if not isinstance(controller, DCAL | Repetitive):
        raise ConfigError("controller.kind", "gain conditions (7.2.22)–(7.2.48) are defined for 'dcal' and 'repetitive'")
    period = getattr(trajectory, "period", None)
    span = period if period is not None else t_span
    zeta = estimate_zeta(controller.model, phi, trajectory, span, radius, samples)
    kL = controller.kL if isinstance(controller, Repetitive) else None
    return GainReport(zeta, radius, samples, check(zeta, controller.Kv, controller.Kp, controller.Ka, kL))
