"""Task-space kinematics of an arm's hand frame (DESIGN "Task space"): pose, geometric Jacobian and its rate, the
position's basis linear in kinematic parameters (Cheah, Liu & Slotine, "Adaptive Jacobian tracking control of robots
with uncertainties in kinematic, dynamic and actuator models", IEEE TAC 51(6), 2006; IJRR 25(3), 2006), and the
orientation error a Cartesian law feeds back.

    ẋ = J_v(q) q̇,   ẍ = J_v q̈ + J̇_v q̇                       (J̇ the time derivative at (q, q̇))
    p(q, θ_k) = h_0(q) + Σ_j θ_k,j h_j(q),   J_v(q, θ_k) = B_0(q) + Σ_j θ_k,j B_j(q)
    ẋ = Y_k(q, q̇) θ_k + B_0(q) q̇,   Y_k[:, j] = B_j(q) q̇      (the kinematic regressor)

A model with a hand frame is a :class:`TaskKinematics` (KinematicTree, SymbolicArm, the book's arms): `hand`,
`kinematic_basis`, `kinematic_regressor`; this module holds them, their value types and the pieces the book's planar
arms share. (PinocchioArm gives `hand` alone, through Pinocchio's frame functions.) Every function takes leading batch
axes and is written with the namespace of its inputs (numpy or `jax.numpy`), without writes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from ..arrays import array_namespace
from ..validation import ConfigError

Array = Any
#: the names of a tool offset's components, in the last link's axes
TOOL_NAMES = ("tool.x", "tool.y", "tool.z")


class Hand(NamedTuple):
    """The hand frame at (q, q̇), world axes throughout."""

    p: Array  #: (..., 3) position of the frame's origin (m)
    R: Array  #: (..., 3, 3) orientation: columns are the frame's axes
    J: Array  #: (..., 6, n) geometric Jacobian [linear velocity of the origin; angular velocity] (Pinocchio's
    #: LOCAL_WORLD_ALIGNED frame Jacobian)
    dJ: Array  #: (..., 6, n) its time derivative at (q, q̇) (Pinocchio's getFrameJacobianTimeVariation, LOCAL_WORLD_ALIGNED)


class KinematicBasis(NamedTuple):
    """The hand position linear in kinematic parameters θ_k (Cheah, Liu & Slotine 2006): index 0 is the known part."""

    h: Array  #: (..., k+1, 3): p = h[0] + Σ_j θ_k[j] h[j+1]
    B: Array  #: (..., k+1, 3, n): J_v = B[0] + Σ_j θ_k[j] B[j+1]
    dB: Array  #: (..., k+1, 3, n): the time derivative of each B at (q, q̇)


def hand_on(xp: Any, q: Array, dq: Array, p: Array, R: Array, J: Array, dJ: Array) -> Hand:
    """The hand with every part on the broadcast leading axes of q and q̇ (the batch contract)."""
    lead = tuple(np.broadcast_shapes(q.shape[:-1], dq.shape[:-1]))
    return Hand(*(xp.broadcast_to(x, lead + x.shape[x.ndim - k :]) for x, k in ((p, 1), (R, 2), (J, 2), (dJ, 2))))


def tool_names(tool: Array | None) -> tuple[str, ...]:
    """The names of the tool's parameters: none without a tool."""
    return () if tool is None else TOOL_NAMES


def tool_values(values: Any, tool: Array | None) -> Array:
    """A model's kinematic parameter values, then the tool's (in the tool's namespace: it may be traced)."""
    values = np.array(values, dtype=float)  # a copy
    if tool is None:
        return values
    tool = tool if hasattr(tool, "shape") else np.asarray(tool, dtype=float)  # a list, or an array of any namespace
    xp = array_namespace(tool)
    return xp.concat([xp.asarray(values), xp.asarray(tool, dtype=xp.float64)])


def cross(xp: Any, a: Array, b: Array) -> Array:
    """a × b along the last axis, broadcasting."""
    a0, a1, a2, b0, b1, b2 = a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2]
    return xp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def orientation_error(R_d: Array, R: Array) -> Array:
    """e = log(R_d Rᵀ)^∨, shape `(..., 3)`: the rotation vector (unit axis × angle θ ∈ [0, π], world axes) of the
    rotation that takes the frame R to R_d, R_d = exp([e]×) R; zero at R = R_d, the small rotation δ for
    R_d = exp([δ]×) R, odd (e(R, R_d) = −e(R_d, R) for θ < π). Below θ = π/2 it is θ/sin θ times the axial vector
    v = ½ (E − Eᵀ)^∨ = sin θ · axis of E = R_d Rᵀ (series near 0); above, the axis is the column of the symmetric
    part ½(E + Eᵀ) − cos θ 1 = (1 − cos θ) a aᵀ with the largest diagonal, its sign that of v, so it holds up to π
    (where the sign is either)."""
    xp = array_namespace(R_d, R)
    E = R_d @ xp.swapaxes(R, -1, -2)
    v = 0.5 * xp.stack([E[..., 2, 1] - E[..., 1, 2], E[..., 0, 2] - E[..., 2, 0], E[..., 1, 0] - E[..., 0, 1]], axis=-1)
    c = 0.5 * (E[..., 0, 0] + E[..., 1, 1] + E[..., 2, 2] - 1.0)
    s = xp.sqrt((v * v).sum(axis=-1))
    angle = xp.atan2(s, c)
    small = s > 1e-4
    ratio = xp.where(small, angle / xp.where(small, s, 1.0), 1.0 + s * s / 6.0)  # θ / sin θ
    S = 0.5 * (E + xp.swapaxes(E, -1, -2)) - c[..., None, None] * xp.eye(3)
    d = xp.stack([S[..., 0, 0], S[..., 1, 1], S[..., 2, 2]], axis=-1)  # (1 − cos θ) a_i²
    first = (d[..., 0] >= d[..., 1]) & (d[..., 0] >= d[..., 2])
    second = ~first & (d[..., 1] >= d[..., 2])
    pick = xp.stack([first, second, ~first & ~second], axis=-1)
    column = (S * xp.astype(pick, S.dtype)[..., None, :]).sum(axis=-1)  # (1 − cos θ) a a_i, i the largest
    scale = xp.sqrt(xp.maximum(((1.0 - c)[..., None] * d * xp.astype(pick, d.dtype)).sum(axis=-1), 1e-300))
    axis = column / scale[..., None]  # ± a
    axis = xp.where(((axis * v).sum(axis=-1) < 0.0)[..., None], -axis, axis)
    return xp.where((c > 0.0)[..., None], ratio[..., None] * v, angle[..., None] * axis)


def planar_axes(xp: Any, angle: Array, rate: Array, turned: Sequence[float]) -> tuple[Array, Array, Array]:
    """The axes of a frame Rz(angle) fixed in a link of a planar arm whose joints turn about z, turning at `rate`:
    (W `(..., 3, 3)`, row i axis i; B `(..., 3, 3, n)` with B[i][:, l] = ∂w_i/∂q_l = e_z × w_i for the joints l
    that turn the link (`turned[l]` = 1) and 0 for the others; dB its time derivative e_z × (rate e_z × w_i))."""
    c, s = xp.cos(angle), xp.sin(angle)
    zero = 0.0 * c
    W = xp.stack([xp.stack(row, axis=-1) for row in ((c, s, zero), (-s, c, zero), (zero, zero, 1.0 + zero))], axis=-2)
    cols = np.asarray(turned, dtype=float)
    about_z = xp.stack([-W[..., 1], W[..., 0], 0.0 * W[..., 2]], axis=-1)  # e_z × w
    inward = -rate[..., None, None] * xp.stack([W[..., 0], W[..., 1], 0.0 * W[..., 2]], axis=-1)  # e_z × (ω × w)
    return W, about_z[..., None] * cols, inward[..., None] * cols


def planar_chain(q: Array, dq: Array, lengths: Sequence[float], tool: Array | None) -> tuple[Hand, Array, Array, Array]:
    """The hand of a planar chain of revolute joints about z (angles summed from the x axis), link i of length l_i
    along the x axis of its frame Rz(q_1 + … + q_i), the hand frame the last link's, offset by `tool` in it; and the
    columns (h, B, dB) of the parameters (l_1, …, l_n, then tool.x, tool.y, tool.z when a tool is given):
    p = Σ_i l_i x_i + R tool, J_v = Σ θ_j ∂w_j/∂q, J_ω = [e_z … e_z], J̇_ω = 0."""
    xp = array_namespace(q, dq)
    n = len(lengths)
    angles, rates = xp.cumsum(q, axis=-1), xp.cumsum(dq, axis=-1)
    parts = [planar_axes(xp, angles[..., i], rates[..., i], [float(l_ <= i) for l_ in range(n)]) for i in range(n)]
    h = [W[..., 0:1, :] for W, _, _ in parts]  # each link's x axis
    B = [b[..., 0:1, :, :] for _, b, _ in parts]
    dB = [d[..., 0:1, :, :] for _, _, d in parts]
    theta = [xp.asarray(np.asarray(lengths, dtype=float))]
    if tool is not None:
        W, b, d = parts[-1]
        h, B, dB, theta = h + [W], B + [b], dB + [d], theta + [tool]
    h, B, dB = xp.concat(h, axis=-2), xp.concat(B, axis=-3), xp.concat(dB, axis=-3)
    theta_ = xp.concat([xp.asarray(t, dtype=h.dtype) for t in theta], axis=-1)
    p = (theta_[..., :, None] * h).sum(axis=-2)
    Jv = (theta_[..., :, None, None] * B).sum(axis=-3)
    dJv = (theta_[..., :, None, None] * dB).sum(axis=-3)
    W_last = parts[-1][0]
    Jw = xp.asarray(np.array([[0.0] * n, [0.0] * n, [1.0] * n])) + 0.0 * Jv
    hand = hand_on(xp, q, dq, p, xp.swapaxes(W_last, -1, -2), xp.concat([Jv, Jw], axis=-2),
                   xp.concat([dJv, 0.0 * dJv], axis=-2))
    return hand, h, B, dB


class TaskKinematics(ABC):
    """The task-space kinematics of an arm with a hand frame (a mixin before
    :class:`robotadapt.robots.base.RobotModel`): the model gives `hand`, its kinematic parameters' names and values and
    their columns (`_kinematic_columns`); the basis and the regressor follow here."""

    @property
    def task_axes(self) -> tuple[int, ...]:
        """The position rows a task uses: (0, 1, 2); (0, 1) for an arm whose hand moves in the x–y plane."""
        return (0, 1, 2)

    @abstractmethod
    def hand(self, q: Array, dq: Array, tool: Array | None = None) -> Hand:
        """The hand frame at (q, q̇): the last link's frame offset by `tool` (3,) in its axes (m; None: zero):
        position, orientation, geometric Jacobian J (rows: linear velocity of the origin, angular velocity; world axes)
        and J̇ at (q, q̇), so that the hand's classical acceleration is J q̈ + J̇ q̇ (:class:`Hand`)."""

    @abstractmethod
    def kinematic_names(self, tool: Array | None = None) -> tuple[str, ...]:
        """Every candidate kinematic parameter of the hand position, in order ("tool.x", "tool.y", "tool.z" last when
        a tool is given)."""

    @abstractmethod
    def kinematic_values(self, tool: Array | None = None) -> Array:
        """The true values (m) of `kinematic_names(tool)`, in order."""

    @abstractmethod
    def _kinematic_columns(self, q: Array, dq: Array, tool: Array | None) -> tuple[Hand, Array, Array, Array]:
        """(the hand, and for every kinematic parameter j its columns h_j `(..., k, 3)`, B_j `(..., k, 3, n)`, Ḃ_j):
        the parts of p, J_v and J̇_v that θ_k,j multiplies; the rest (prismatic travel) is what they leave."""

    def kinematic_basis(self, q: Array, dq: Array, tool: Array | None = None,
                        unknown: tuple[str, ...] | None = None) -> KinematicBasis:
        """The hand position linear in the parameters named in `unknown` (default: every `kinematic_names(tool)`), in
        that order: p = h[0] + Σ_j θ_k[j] h[j+1], J_v = B[0] + Σ_j θ_k[j] B[j+1], dB its rate (Cheah, Liu & Slotine
        2006). Index 0 is the rest at the model's values: the known parameters folded in, and what no parameter
        multiplies (prismatic travel)."""
        names = self.kinematic_names(tool)
        wanted = names if unknown is None else tuple(unknown)
        missing = [name for name in wanted if name not in names]
        if missing or len(set(wanted)) != len(wanted):
            raise ConfigError("unknown", f"expected distinct names among {', '.join(names) or '(none)'}; got "
                              f"{', '.join(map(repr, wanted))}")
        hand, h, B, dB = self._kinematic_columns(q, dq, tool)
        xp = array_namespace(h, B, dB)
        pick = np.array([names.index(name) for name in wanted], dtype=int)
        theta = xp.take(xp.asarray(self.kinematic_values(tool)), pick, axis=-1)
        h, B, dB = xp.take(h, pick, axis=-2), xp.take(B, pick, axis=-3), xp.take(dB, pick, axis=-3)
        h0 = hand.p - (theta[:, None] * h).sum(axis=-2)
        B0 = hand.J[..., :3, :] - (theta[:, None, None] * B).sum(axis=-3)
        dB0 = hand.dJ[..., :3, :] - (theta[:, None, None] * dB).sum(axis=-3)
        lead = hand.J.shape[:-2]  # the broadcast leading axes of q and q̇

        def on(x: Array, k: int) -> Array:
            return xp.broadcast_to(x, lead + x.shape[x.ndim - k :])

        return KinematicBasis(xp.concat([on(h0[..., None, :], 2), on(h, 2)], axis=-2),
                              xp.concat([on(B0[..., None, :, :], 3), on(B, 3)], axis=-3),
                              xp.concat([on(dB0[..., None, :, :], 3), on(dB, 3)], axis=-3))

    def kinematic_regressor(self, q: Array, dq: Array, tool: Array | None = None,
                            unknown: tuple[str, ...] | None = None) -> tuple[Array, Array]:
        """(Y_k `(..., 3, k)`, known `(..., 3)`) with ẋ = J_v q̇ = Y_k θ_k + known: Y_k[:, j] = B[j+1] q̇ and
        known = B[0] q̇ of :meth:`kinematic_basis` (Cheah, Liu & Slotine 2006)."""
        B = self.kinematic_basis(q, dq, tool, unknown).B
        Bq = (B * dq[..., None, None, :]).sum(axis=-1)  # (..., k+1, 3)
        xp = array_namespace(Bq)
        return xp.swapaxes(Bq[..., 1:, :], -1, -2), Bq[..., 0, :]


class PlanarChain(TaskKinematics):
    """The task-space methods of a book's planar arm of revolute joints about z (:func:`planar_chain`), a mixin before
    :class:`robotadapt.robots.base.RobotModel`: the model gives `_hand_links`, (name, length in m) per link."""

    @property
    @abstractmethod
    def _hand_links(self) -> tuple[tuple[str, float], ...]:
        """(name, length in m) of each link, base first."""

    @property
    def task_axes(self) -> tuple[int, ...]:
        """(0, 1): the hand moves in the x–y plane."""
        return (0, 1)

    def kinematic_names(self, tool: Array | None = None) -> tuple[str, ...]:
        """The link lengths' names, then the tool's."""
        return tuple(name for name, _ in self._hand_links) + tool_names(tool)

    def kinematic_values(self, tool: Array | None = None) -> Array:
        """The link lengths (m), then the tool's offset."""
        return tool_values([length for _, length in self._hand_links], tool)

    def hand(self, q: Array, dq: Array, tool: Array | None = None) -> Hand:
        """The last link's frame Rz(q_1 + … + q_n), offset by `tool` in it (:func:`planar_chain`)."""
        return planar_chain(q, dq, [length for _, length in self._hand_links], tool)[0]

    def _kinematic_columns(self, q: Array, dq: Array, tool: Array | None) -> tuple[Hand, Array, Array, Array]:
        return planar_chain(q, dq, [length for _, length in self._hand_links], tool)
