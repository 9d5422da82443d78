"""Gain conditions of §7.2: the bounding constants ζ1…ζ4 of (7.2.9) estimated for an arm, a parameter vector and a
desired trajectory, and the checks (7.2.22), (7.2.25), (7.2.26) (DCAL) and (7.2.48) (repetitive law).

The ζ_i are not unique and the book never computes them. Here they are *estimated*: errors e and filtered errors r are
sampled in a ball around the desired trajectory (‖e‖ ≤ radius, ‖r‖ ≤ radius, along one period or the run), the mismatch
Ỹ = Y(q, q̇, q̇_d + e, q̈_d + ė) φ − Y_d φ (7.2.10) is evaluated with q = q_d − e, ė = r − e, and a ζ ≥ 0 is *admissible*
when ‖Ỹ‖ ≤ ζ1‖e‖ + ζ2‖e‖² + ζ3‖r‖ + ζ4‖r‖‖e‖ at every sample. Any admissible ζ proves stability, so the gains are
*certified* when one admissible ζ meets every condition at once; `certify` decides this by one linear program. A
verdict holds for the sampled ball, not as a proof, and "not certified" means no sampled-admissible ζ works, not that
the closed loop is unstable (the conditions are sufficient only).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..robots.base import RobotModel
from ..validation import ConfigError

Zeta = tuple[float, float, float, float]


@dataclass(frozen=True)
class GainReport:
    """`certified`: some admissible ζ meets every condition; `zeta` is that ζ, else the least-sum one (see `certify`).
    `margin` is the optimal common relative margin s; each condition's "holds" is for the reported ζ."""

    zeta: Zeta
    radius: float
    samples: int
    conditions: dict[str, dict[str, Any]]
    certified: bool
    margin: float

    def as_dict(self) -> dict[str, Any]:
        return {"certified": self.certified, "zeta": list(self.zeta), "margin": self.margin, "radius": self.radius,
                "samples": self.samples, "conditions": self.conditions,
                "note": "certified: one zeta bounds the mismatch (7.2.9) at every sampled error and meets every gain "
                        "condition; zeta is that one, else the least-sum one. A verdict holds for the sampled ball, "
                        "not as a proof; 'not certified' does not mean unstable"}


def _mismatch(model: RobotModel, phi: np.ndarray, ref: Any, e: np.ndarray, r: np.ndarray) -> np.ndarray:
    """‖Ỹ‖ of (7.2.10) for sampled errors (leading axes shared with `ref`)."""
    de = r - e
    q, dq = ref.q_des - e, ref.dq_des - de
    Y = model.regressor(q, dq, ref.dq_des + e, ref.ddq_des + de)
    Yd = model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)
    return np.linalg.norm((Y - Yd) @ phi, axis=-1)


def sample_bound(model: RobotModel, phi: np.ndarray, trajectory: Any, t_span: float, radius: float = 1.0,
                 samples: int = 4000, rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sampled (t, e, r) with ‖e‖, ‖r‖ ≤ `radius`: features (N, 4) = (‖e‖, ‖e‖², ‖r‖, ‖r‖‖e‖) of (7.2.9), y = ‖Ỹ‖ (N,)."""
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
    return np.stack([ne, ne**2, nr, nr * ne], axis=-1), y


COST = np.array([1.0, 1.25, 1.0, 1.25])  # ζ1 + 1.25 ζ2 + ζ3 + 1.25 ζ4: the sum of the conditions' right-hand sides


def fit_zeta(features: np.ndarray, y: np.ndarray) -> Zeta:
    """The admissible ζ of (7.2.9) minimising the sum of the conditions' right-hand sides, ζ1 + 1.25 ζ2 + ζ3 + 1.25 ζ4."""
    from scipy.optimize import linprog

    sol = linprog(COST, A_ub=-features, b_ub=-y, bounds=[(0, None)] * 4, method="highs")
    if not sol.success:
        raise ConfigError("gains", f"could not fit the bound (7.2.9): {sol.message}")
    return tuple(float(z) for z in sol.x)  # type: ignore[return-value]


def estimate_zeta(model: RobotModel, phi: np.ndarray, trajectory: Any, t_span: float, radius: float = 1.0,
                  samples: int = 4000, rng: np.random.Generator | None = None) -> Zeta:
    """Estimate ζ1…ζ4 of (7.2.9): `fit_zeta` over `sample_bound`'s samples (one admissible ζ, not the certificate)."""
    return fit_zeta(*sample_bound(model, phi, trajectory, t_span, radius, samples, rng))


def _rows(Kv: float, Kp: float, Ka: float, kL: float | None) -> dict[str, tuple[str, float, np.ndarray]]:
    """Each condition as (text, gain g, c) with the condition g > c·ζ."""
    rows = {
        "7.2.22": ("k_a > ζ2 + ζ4", Ka, [0.0, 1.0, 0.0, 1.0]),
        "7.2.25": ("k_p > ζ1/2 + ζ2/4", Kp, [0.5, 0.25, 0.0, 0.0]),
    }
    if kL is None:
        rows["7.2.26"] = ("k_v > ζ1/2 + ζ3 + ζ4/4", Kv, [0.5, 0.0, 1.0, 0.25])
    else:
        rows["7.2.48"] = ("k_v + k_L/2 > ζ1/2 + ζ3 + ζ4/4", Kv + kL / 2, [0.5, 0.0, 1.0, 0.25])
    return {eq: (text, float(g), np.array(c)) for eq, (text, g, c) in rows.items()}


def check(zeta: Zeta, Kv: float, Kp: float, Ka: float, kL: float | None = None) -> dict[str, dict[str, Any]]:
    """Evaluate the gain conditions at one ζ; (7.2.48) replaces (7.2.26) for the repetitive law (k_L given)."""
    z = np.asarray(zeta, dtype=float)
    return {eq: {"condition": text, "gain": g, "bound": float(c @ z), "holds": bool(g > float(c @ z))}
            for eq, (text, g, c) in _rows(Kv, Kp, Ka, kL).items()}


def certify(features: np.ndarray, y: np.ndarray, Kv: float, Kp: float, Ka: float,
            kL: float | None = None) -> tuple[bool, Zeta, float]:
    """Is there a ζ ≥ 0 meeting (7.2.9) at every sample (features ζ ≥ y) and (7.2.22), (7.2.25), (7.2.26) or (7.2.48)?

    A linear program (HiGHS) over (ζ, s): maximise the common relative margin s ≤ 1 with g_k − c_k·ζ ≥ s g_k for
    every condition k (g_k its gain, c_k·ζ its bound). The strict inequalities hold together iff the optimal s > 0;
    the gains are certified when s > 0 and the exact check of each condition at the returned ζ agrees. Among the ζ
    with the optimal margin, a second program picks the least ζ1 + 1.25 ζ2 + ζ3 + 1.25 ζ4. Returns (certified, ζ, s):
    ζ certifies when certified, else it is `fit_zeta`'s (a representative; s < 0 then says that multiplying every gain
    by more than 1 − s would certify). Raises ConfigError when a program fails."""
    from scipy.optimize import linprog

    rows = _rows(Kv, Kp, Ka, kL)
    C = np.array([c for _, _, c in rows.values()])
    g = np.array([gain for _, gain, _ in rows.values()])
    A_ub = np.block([[-features, np.zeros((len(y), 1))], [C, g[:, None]]])
    b_ub = np.concatenate([-np.asarray(y, dtype=float), g])
    box: list[tuple[float | None, float | None]] = [(0, None)] * 4
    sol = linprog([0.0, 0.0, 0.0, 0.0, -1.0], A_ub=A_ub, b_ub=b_ub, bounds=[*box, (None, 1.0)], method="highs")
    if not sol.success:
        raise ConfigError("gains", f"could not solve for ζ of (7.2.9) with the gain conditions: {sol.message}")
    margin = float(sol.x[4])
    least = linprog([*COST, 0.0], A_ub=A_ub, b_ub=b_ub, bounds=[*box, (margin - 1e-6 * abs(margin), 1.0)],
                    method="highs")
    for x in ([least.x] if least.success else []) + [sol.x]:
        zeta: Zeta = tuple(float(z) for z in x[:4])  # type: ignore[assignment]
        if margin > 0 and all(c["holds"] for c in check(zeta, Kv, Kp, Ka, kL).values()):
            return True, zeta, margin
    return False, fit_zeta(features, y), margin


def gain_report(controller: Any, phi: np.ndarray, trajectory: Any, t_span: float, radius: float = 1.0,
                samples: int = 4000) -> GainReport:
    """Sample (7.2.9) and `certify` the gain conditions of a DCAL or repetitive controller."""
    from ..controllers.dcal import DCAL
    from ..controllers.repetitive import Repetitive

    if not isinstance(controller, DCAL | Repetitive):
        raise ConfigError("controller.kind", "gain conditions (7.2.22)–(7.2.48) are defined for 'dcal' and 'repetitive'")
    period = getattr(trajectory, "period", None)
    span = period if period is not None else t_span
    features, y = sample_bound(controller.model, phi, trajectory, span, radius, samples)
    kL = controller.kL if isinstance(controller, Repetitive) else None
    gains = (controller.Kv, controller.Kp, controller.Ka, kL)
    certified, zeta, margin = certify(features, y, *gains)
    return GainReport(zeta, radius, samples, check(zeta, *gains), certified, margin)
