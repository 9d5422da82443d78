"""Laws that drive the hand, not the joints (docs/task-space.md): the reference holds the hand's desired position
x_d, ẋ_d, ẍ_d (m coordinates: the x–y plane of a planar arm, else space; :mod:`robotadapt.task_trajectories`), and the
hand frame is the last link's, offset by `tool` (metres, in that link's frame).

- :class:`TaskSlotineLi`, Slotine & Li's law in Cartesian coordinates (Slotine & Li, "Adaptive manipulator control:
  a case study", IEEE TAC 33(11), 1988; Niemeyer & Slotine, IJRR 10(5), 1991), with every update law the joint-space
  Slotine–Li takes (Euclidean, natural, pullback);
- :class:`AdaptiveJacobian`, Cheah, Liu & Slotine's adaptive Jacobian law for unknown kinematics and dynamics
  ("Adaptive tracking control for robots with unknown kinematic and dynamic properties", IJRR 25(3), 2006);
- :class:`OperationalSpace`, Khatib's operational-space control with a fixed model, the non-adaptive baseline
  (IEEE J. Robotics and Automation 3(1), 1987).

The pseudo-inverse is damped, J⁺ = Jᵀ(J Jᵀ + λ² I)⁻¹ (`damping` λ in metres; 0: the exact right inverse), and its
time derivative is exact for every λ: d(J⁺)/dt = J̇ᵀA⁻¹ − JᵀA⁻¹(J̇Jᵀ + JJ̇ᵀ)A⁻¹, A = JJᵀ + λ²I. A redundant arm's
null space holds a posture: q̇_r gains N k_n (q_0 − q), N = I − J⁺J.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, cast

import numpy as np

from ..arrays import array_namespace, matvec
from ..robots.base import RobotModel
from ..robots.hand import TaskKinematics
from ..trajectories import Reference
from ..validation import ConfigError, as_gain, as_scalar, as_vector
from .base import Array, EstimateState, FixedEstimate, Law, estimate, freeze, gains, inverse
from .registry import Contender


def _mm(A: Array, B: Array) -> Array:
    return A @ B


class Task(Law):
    """What every task-space law shares: the hand (:meth:`TaskKinematics.hand` of the law's model, offset by `tool`), its m
    position rows (`model.task_axes`), the damped pseudo-inverse and the posture of a redundant arm; the tracking error
    the run's metrics measure is x_d − x(q) (metres)."""

    space: ClassVar[str] = "task"

    model: RobotModel
    tool: Any
    damping: Any
    posture: Any
    Kn: Any

    def checks_task(self) -> None:
        """Validate `tool` (3 metres), `damping` λ ≥ 0 (metres), `posture` (n angles; default zeros) and `Kn` ≥ 0."""
        freeze(self, tool=None if self.tool is None else as_vector(self.tool, 3, "controller.tool", broadcast=False),
               damping=np.asarray(as_scalar(self.damping, "controller.damping", nonnegative=True)),
               posture=as_vector(0.0 if self.posture is None else self.posture, self.model.n, "controller.posture"),
               Kn=np.asarray(as_scalar(self.Kn, "controller.Kn", nonnegative=True)))
        if not callable(getattr(self.model, "hand", None)):
            raise ConfigError("robot", f"{type(self.model).__name__} has no hand frame for a task-space law: use an arm "
                              "that has one (the book's arms, a DH table, a URDF)")

    @property
    def arm(self) -> TaskKinematics:
        """The model, as the arm with a hand frame its construction checked it is."""
        return cast(TaskKinematics, self.model)

    @property
    def error_size(self) -> int:
        return len(self.arm.task_axes)

    def monitors(self, x: Array, q: Array) -> dict[str, Array]:
        """`hand_sigma_min`: the smallest singular value of the hand's m×n Jacobian J(q) at the logged instants (m/rad):
        near 0 the arm passes a singularity, where J⁺ is held finite by the damping λ only (metrics.json says when)."""
        J = np.asarray(self.kinematics(q, np.zeros_like(q))[1])
        return {"hand_sigma_min": np.linalg.svd(J, compute_uv=False)[..., -1]}

    def kinematics(self, q: Array, dq: Array) -> tuple[Array, Array, Array]:
        """(x, J, J̇): the hand's m position coordinates, their Jacobian and its derivative, `(..., m)`, `(..., m, n)`."""
        hand = self.arm.hand(q, dq, self.tool)
        m = self.error_size
        return hand.p[..., :m], hand.J[..., :m, :], hand.dJ[..., :m, :]

    def tracking_error(self, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        x, J, _ = self.kinematics(q, dq)
        return ref.q_des - x, ref.dq_des - matvec(J, dq)

    def reference(self, q: Array, dq: Array, J: Array, dJ: Array, v: Array, dv: Array) -> tuple[Array, Array]:
        """(q̇_r, q̈_r) for a task reference velocity v and its derivative dv: q̇_r = J⁺v + N k_n (q_0 − q) and its exact
        time derivative (module docstring), N = I − J⁺J."""
        xp = array_namespace(J)
        m, n = J.shape[-2], J.shape[-1]
        A = _mm(J, J.mT) + self.damping**2 * xp.eye(m)
        Ai = inverse(A)
        P = _mm(J.mT, Ai)
        dP = _mm(dJ.mT, Ai) - _mm(_mm(P, _mm(dJ, J.mT) + _mm(J, dJ.mT)), Ai)
        N = xp.eye(n) - _mm(P, J)
        dN = -(_mm(dP, J) + _mm(P, dJ))
        w = self.Kn * (self.posture - q)
        return matvec(P, v) + matvec(N, w), matvec(dP, v) + matvec(P, dv) + matvec(dN, w) - self.Kn * matvec(N, dq)


@dataclass(frozen=True, eq=False)
class TaskSlotineLi(Task, EstimateState):
    """Slotine–Li in Cartesian coordinates (Slotine & Li 1988, Niemeyer & Slotine 1991; docs/task-space.md):

    x_e = x_d − x,  ẋ_r = ẋ_d + Λ x_e,  ẍ_r = ẍ_d + Λ(ẋ_d − J q̇)
    q̇_r = J⁺ ẋ_r + N k_n (q_0 − q),  q̈_r = d/dt q̇_r           s = q̇_r − q̇
    τ = Y(q, q̇, q̇_r, q̈_r) φ̂ + K_v s,  dφ̂/dt = Γ Yᵀ s         (the joint law (6.3.14), (6.3.16) on s)
    V = ½ sᵀ M s + ½ φ̃ᵀ Γ⁻¹ φ̃,  dV/dt = −sᵀ K_v s

    Λ is m×m (per task coordinate, 1/s), K_v n×n (N·m·s). s → 0 gives ẋ_e = −Λ x_e (λ = 0), so x_e → 0 while J has
    full row rank; `adaptation = "natural"` / `"pullback"` as for :class:`InertiaRelated`."""

    per_run: ClassVar[tuple[str, ...]] = ("Lam", "Kv", "Gamma", "phi_hat0")

    kind = "task_slotine_li"
    tuned = ("Lam", "Kv", "Gamma")
    lineup = (Contender("task_slotine_li", "task-space Slotine–Li", "Slotine & Li 1988", "task-circle-2link",
                        {"kind": "task_slotine_li", "Lam": 5.0, "Kv": 10.0, "Gamma": 5.0}, rank=210),)

    model: RobotModel
    Lam: Any
    Kv: Any
    Gamma: Any = None
    phi_hat0: Any = None
    adaptation: str = "euclidean"
    gamma: Any = None
    phi_ref: Any = None
    tool: Any = None
    damping: Any = 1e-3
    posture: Any = None
    Kn: Any = 0.0

    def __post_init__(self) -> None:
        self.checks_task()
        freeze(self, Lam=as_gain(self.Lam, self.error_size, "controller.Lam"))
        gains(self, ("Kv",), self.model.n)
        self.adapts()

    def references(self, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array, Array]:
        """(q̇_r, q̈_r, s)."""
        x, J, dJ = self.kinematics(q, dq)
        e, de = ref.q_des - x, ref.dq_des - matvec(J, dq)
        v, dv = ref.dq_des + matvec(self.Lam, e), ref.ddq_des + matvec(self.Lam, de)
        dq_r, ddq_r = self.reference(q, dq, J, dJ, v, dv)
        return dq_r, ddq_r, dq_r - dq

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        return self.references(q, dq, ref)[2]

    def regressor(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        """(Y(q, q̇, q̇_r, q̈_r), s): M ṡ + V_m s = Y φ − τ, the passivity output of (6.4.4) with s for r."""
        dq_r, ddq_r, s = self.references(q, dq, ref)
        return self.model.regressor(q, dq, dq_r, ddq_r), s

    def regressor_products(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference,
                           phi: Array) -> tuple[Array, Array, Array]:
        dq_r, ddq_r, s = self.references(q, dq, ref)
        return (*self.model.regressor_products(q, dq, dq_r, ddq_r, phi, s), s)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        Yphi, Yts, s = self.regressor_products(t, x, q, dq, ref, self.phi_hat(x))
        return Yphi + matvec(self.Kv, s), self.geometry.rate(x, Yts)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        s = self.filtered_error(t, x, q, dq, ref)
        return 0.5 * (s * matvec(self.model.mass_matrix(q, phi), s)).sum(axis=-1) + self.geometry.lyapunov(x, phi)


@dataclass(frozen=True, eq=False)
class AdaptiveJacobian(Task):
    """Cheah, Liu & Slotine's adaptive Jacobian law (IJRR 25(3), 2006; docs/task-space.md): the kinematics linear in
    kinematic parameters θ_k (link lengths, a tool offset: `unknown` names them, :meth:`TaskKinematics.kinematic_names`),
    ẋ = J(q, θ_k) q̇ = Y_k(q, q̇) θ_k (+ the known part), estimated with θ̂_k while φ̂ adapts:

    Δx = x − x_d (x measured),  ẋ̂ = Ĵ q̇ = J(q, θ̂_k) q̇,  Δẋ̂ = ẋ̂ − ẋ_d
    ẋ_r = ẋ_d − α Δx,  ẍ_r = ẍ_d − α Δẋ (ẋ measured),  q̇_r = Ĵ⁺ ẋ_r + N k_n (q_0 − q),  q̈_r = d/dt q̇_r,  s = q̇ − q̇_r
    τ = −Ĵᵀ (K_v Δẋ̂ + K_p Δx) − K_s s + Y(q, q̇, q̇_r, q̈_r) φ̂
    dφ̂/dt = −Γ Yᵀ s,   dθ̂_k/dt = Γ_k Y_kᵀ (K_p + α K_v) Δx
    V = ½ sᵀ M s + ½ φ̃ᵀ Γ⁻¹ φ̃ + ½ θ̃_kᵀ Γ_k⁻¹ θ̃_k + ½ Δxᵀ (K_p + α K_v) Δx
    dV/dt = −Δẋ̂ᵀ K_v Δẋ̂ − α Δxᵀ K_p Δx − sᵀ K_s s ≤ 0   (λ = 0: Ĵ s = Δẋ̂ + α Δx)

    The update of θ̂_k reads positions only; q̈_r, the exact derivative of q̇_r (so that the dynamics' regressor is
    exact and V's derivative is the one above), reads the hand's velocity ẋ (a differentiated position measurement;
    here the arm's own ẋ = J q̇). α (1/s) is a scalar, K_v and K_p m×m, K_s n×n (default 0: a redundant arm's
    null-space motion is then damped by nothing but the posture). State x = (φ̂, θ̂_k)."""

    kind = "adaptive_jacobian"
    tuned = ("alpha", "Kv", "Kp", "Gamma", "Gamma_k")
    lineup = (Contender("adaptive_jacobian", "adaptive Jacobian", "Cheah, Liu & Slotine 2006", "task-jacobian-2link",
                        {"kind": "adaptive_jacobian", "alpha": 5.0, "Kv": 20.0, "Kp": 100.0, "Ks": 1.0,
                         "Gamma": 5.0, "Gamma_k": 2.0, "theta_hat0": {"scale": 0.8}}, rank=220),)

    model: RobotModel
    alpha: Any
    Kv: Any
    Kp: Any
    Gamma: Any
    Gamma_k: Any
    phi_hat0: Any = None
    theta_hat0: Any = None
    unknown: tuple[str, ...] | None = None
    Ks: Any = 0.0
    tool: Any = None
    damping: Any = 0.0
    posture: Any = None
    Kn: Any = 0.0

    def __post_init__(self) -> None:
        self.checks_task()
        names = self.arm.kinematic_names(self.tool)
        unknown = names if self.unknown is None else tuple(self.unknown)
        for name in unknown:
            if name not in names:
                raise ConfigError("controller.unknown", f"{name!r} is no kinematic parameter of this arm; it has "
                                  f"{', '.join(names)}")
        m, n, k = self.error_size, self.model.n, len(unknown)
        theta_hat0 = self.theta_hat0
        if isinstance(theta_hat0, dict) and set(theta_hat0) == {"scale"}:  # {scale = 0.8}: 20 % short of the arm's
            values = np.asarray(self.arm.kinematic_values(self.tool), dtype=float)
            theta_hat0 = as_scalar(theta_hat0["scale"], "controller.theta_hat0.scale") * values[
                [names.index(name) for name in unknown]]
        elif theta_hat0 is None or isinstance(theta_hat0, dict):
            raise ConfigError("controller.theta_hat0", f"required: the initial kinematic estimate, {k} values "
                              f"({', '.join(unknown)}; metres), or {{scale = s}} for s times the arm's")
        freeze(self, unknown=unknown, alpha=np.asarray(as_scalar(self.alpha, "controller.alpha", positive=True)),
               Kv=as_gain(self.Kv, m, "controller.Kv"), Kp=as_gain(self.Kp, m, "controller.Kp"),
               Ks=as_gain(self.Ks, n, "controller.Ks", semidefinite=True),
               Gamma=as_gain(self.Gamma, self.model.p, "controller.Gamma"),
               Gamma_k=as_gain(self.Gamma_k, k, "controller.Gamma_k"),
               theta_hat0=as_vector(theta_hat0, k, "controller.theta_hat0", broadcast=False))
        estimate(self)

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"phi_hat[{p}]" for p in self.model.param_names) + tuple(f"theta_hat[{k}]" for k in self.estimated)

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        return np.concatenate([self.phi_hat0, self.theta_hat0])

    def phi_hat(self, x: Array) -> Array:
        return x[..., : self.model.p]

    def theta_hat(self, x: Array) -> Array:
        """θ̂_k, the estimated kinematic parameters (`unknown`), metres."""
        return x[..., self.model.p :]

    @property
    def theta(self) -> Array:
        """The arm's true kinematic parameters of `unknown` (for the monitors: the law's torque never reads them)."""
        names = self.arm.kinematic_names(self.tool)
        values = np.asarray(self.arm.kinematic_values(self.tool), dtype=float)
        return values[[names.index(k) for k in self.estimated]]

    @property
    def estimated(self) -> tuple[str, ...]:
        """The names of θ_k (`unknown`, every kinematic parameter by default)."""
        return tuple(self.unknown or ())

    def _parts(self, x: Array, q: Array, dq: Array, ref: Reference) -> dict[str, Array]:
        """Every signal of the law at (x, q, q̇) (class docstring)."""
        m = self.error_size
        basis = self.arm.kinematic_basis(q, dq, self.tool, self.unknown)
        theta = self.theta_hat(x)
        B, dB = basis.B[..., :m, :], basis.dB[..., :m, :]
        J_hat = B[..., 0, :, :] + (theta[..., :, None, None] * B[..., 1:, :, :]).sum(axis=-3)
        Yk = matvec(B[..., 1:, :, :], dq[..., None, :]).mT  # (..., m, k): column j = B_j q̇
        x_now, J, _ = self.kinematics(q, dq)
        dx = x_now - ref.q_des
        P = self.Kp + self.alpha * self.Kv
        dtheta = matvec(self.Gamma_k, matvec(Yk.mT, matvec(P, dx)))
        dJ_hat = dB[..., 0, :, :] + (theta[..., :, None, None] * dB[..., 1:, :, :]).sum(axis=-3) + (
            dtheta[..., :, None, None] * B[..., 1:, :, :]).sum(axis=-3)
        v = ref.dq_des - self.alpha * dx
        dv = ref.ddq_des - self.alpha * (matvec(J, dq) - ref.dq_des)
        dq_r, ddq_r = self.reference(q, dq, J_hat, dJ_hat, v, dv)
        return {"J_hat": J_hat, "dx": dx, "dxhat": matvec(J_hat, dq) - ref.dq_des, "dq_r": dq_r, "ddq_r": ddq_r,
                "s": dq - dq_r, "dtheta": dtheta}

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        return self._parts(x, q, dq, ref)["s"]

    def monitors(self, x: Array, q: Array) -> dict[str, Array]:
        """σ_min of the estimated Jacobian's truth (:meth:`Task.monitors`), θ̂_k and the truth it estimates at the logged
        states (metres; the figures and metrics.json)."""
        theta = self.theta_hat(x)
        return {**super().monitors(x, q), "theta_hat": theta, "theta_true": np.broadcast_to(self.theta, theta.shape)}

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        xp = array_namespace(x, q)
        f = self._parts(x, q, dq, ref)
        Yphi, Yts = self.model.regressor_products(q, dq, f["dq_r"], f["ddq_r"], self.phi_hat(x), f["s"])
        force = matvec(self.Kv, f["dxhat"]) + matvec(self.Kp, f["dx"])
        tau = Yphi - matvec(f["J_hat"].mT, force) - matvec(self.Ks, f["s"])
        return tau, xp.concatenate([-matvec(self.Gamma, Yts), f["dtheta"]], axis=-1)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        f = self._parts(x, q, dq, ref)
        s, dx = f["s"], f["dx"]
        phi_err, theta_err = phi - self.phi_hat(x), self.theta - self.theta_hat(x)
        P = self.Kp + self.alpha * self.Kv
        return 0.5 * ((s * matvec(self.model.mass_matrix(q, phi), s)).sum(axis=-1)
                      + (phi_err * matvec(inverse(self.Gamma), phi_err)).sum(axis=-1)
                      + (theta_err * matvec(inverse(self.Gamma_k), theta_err)).sum(axis=-1)
                      + (dx * matvec(P, dx)).sum(axis=-1))


@dataclass(frozen=True, eq=False)
class OperationalSpace(Task, FixedEstimate):
    """Khatib's operational-space control with a fixed model φ̂, the task-space laws' non-adaptive baseline (IEEE J.
    Robotics and Automation 3(1), 1987; docs/task-space.md):

    Λ_x = (J M̂⁻¹ Jᵀ)⁻¹,  J̄ = M̂⁻¹ Jᵀ Λ_x,  f = Λ_x (ẍ_d + K_v ẋ_e + K_p x_e − J̇ q̇) + J̄ᵀ (V̂_m q̇ + Ĝ)
    τ = Jᵀ f + (I − Jᵀ J̄ᵀ) M̂ (k_n (q_0 − q) − K_d q̇)

    With φ̂ = φ, ẍ = ẍ_d + K_v ẋ_e + K_p x_e exactly (x_e → 0 for any K_p, K_v ≻ 0). No state."""

    kind = "operational_space"
    nominal = True
    tuned = ("Kp", "Kv")
    lineup = (Contender("operational_space", "operational space, fixed φ̂", "Khatib 1987", "task-circle-2link",
                        {"kind": "operational_space", "Kp": 100.0, "Kv": 20.0}, rank=200),)

    model: RobotModel
    Kp: Any
    Kv: Any
    phi_hat0: Any = None
    Kd: Any = 0.0
    tool: Any = None
    damping: Any = 0.0
    posture: Any = None
    Kn: Any = 0.0

    def __post_init__(self) -> None:
        self.checks_task()
        m = self.error_size
        freeze(self, Kp=as_gain(self.Kp, m, "controller.Kp"), Kv=as_gain(self.Kv, m, "controller.Kv"),
               Kd=as_gain(self.Kd, self.model.n, "controller.Kd", semidefinite=True))
        estimate(self)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        xp = array_namespace(q, x)
        phi = self.phi_hat0
        pos, J, dJ = self.kinematics(q, dq)
        e, de = ref.q_des - pos, ref.dq_des - matvec(J, dq)
        M = self.model.mass_matrix(q, phi)
        Mi = inverse(M)
        Lx = inverse(_mm(_mm(J, Mi), J.mT) + self.damping**2 * xp.eye(J.shape[-2]))
        Jbar = _mm(_mm(Mi, J.mT), Lx)
        bias = matvec(self.model.coriolis_matrix(q, dq, phi), dq) + self.model.gravity(q, phi)
        accel = ref.ddq_des + matvec(self.Kv, de) + matvec(self.Kp, e) - matvec(dJ, dq)
        f = matvec(Lx, accel) + matvec(Jbar.mT, bias)
        posture = matvec(M, self.Kn * (self.posture - q) - matvec(self.Kd, dq))
        null = xp.eye(self.model.n) - _mm(J.mT, Jbar.mT)
        return matvec(J.mT, f) + matvec(null, posture), xp.zeros(x.shape)
