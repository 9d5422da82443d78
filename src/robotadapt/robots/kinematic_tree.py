"""Any serial arm (or tree) from a URDF or a DH table, by recursive Newton–Euler, traceable by JAX.

    τ = M(q) q̈ + V_m(q, q̇) q̇ + G(q) + F(q̇)                              (6.2.1)
    Y(q, q̇, v, a) φ = M(q) a + V_m(q, q̇) v + G(q) + F(q̇)                 (P3)

The chain holds constants only. Link i's frame is its parent's frame times P_i J_i(q_i) L_i: P_i the joint's fixed
placement (`rotation`, `translation`), J_i a rotation about (or a translation along) the unit `axis` u_i, and L_i the
placement of the link frame in the joint frame (`link_rotation`, `link_translation`): the identity for a URDF
(Pinocchio's joint frame), Tz(d) Tx(a) Rx(α) for a standard DH row (:func:`robotadapt.robots.dh.joint_placements`).
φ holds 10 standard parameters per link, [m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz] about the link
frame's origin in its axes (Pinocchio's order, as :mod:`.pinocchio` and :mod:`.symbolic`), then optional columns per
joint: rotor inertia I_a q̈ ("Ia1", …), viscous f_v q̇ ("fv1", …), Coulomb f_c sgn q̇ ("fc1", …), smooth Coulomb
f_s tanh(q̇/v_s) ("fs1", …) and a constant offset τ_off ("off1", …) (:class:`robotadapt.robots.dh.SerialChain`).

Route: the recursive Newton–Euler algorithm (Luh, Walker & Paul 1980; Featherstone, *Rigid Body Dynamics Algorithms*,
2008, ch. 5), bilinear in two velocities. Every velocity product of the standard pass (V ×ₘ S q̇, ω × (ω × h), ω × I ω)
is replaced by its polarisation ½[F(q̇, v) + F(v, q̇)] (Niemeyer & Slotine 1991); the symmetric form B(q̇, v) with
B(q̇, q̇) = V_m q̇ is unique and equals the Christoffel V_m(q, q̇) v (P2), so ONE pass gives the mixed regressor, and with
v = q̇ it is the standard pass (checked against Pinocchio's `computeJointTorqueRegressor`, `crba`,
`computeCoriolisMatrix`, `computeGeneralizedGravity`, `rnea` in tests/test_kinematic_tree.py). Per pass:

    world poses of the links (a loop over the links: the only sequential part),
    V_i = Σ_j S̃_j q̇_j,  A_i = −g + Σ_j [S̃_j a_j + ½(V_j(q̇) ×ₘ S̃_j v_j + V_j(v) ×ₘ S̃_j q̇_j)]   over the joints j
        that move link i (a cumulative sum along a chain), S̃_j joint j's motion in world axes,
    A_i φ_i, link i's wrench (6 × 10, in its own axes, where φ_i is linear), and
    Y[j, 10 i + c] = S̃_jᵀ (X_i* A_i)[:, c] over the joints j that move link i.

An adaptive law needs Y only through Y φ̂ and Yᵀ r (Table 6.3.1): `regressor_products` gives both from the same pass
without the projections — the pass contracted with φ̂ as τ is, and link i's block A_iᵀ W_i with W_i the velocity the
joint rates r give link i — two thirds of the arithmetic through Y on the Panda (tests/test_kinematic_tree.py checks it
against Y). M is the composite-rigid-body algorithm (Featherstone 2008, §6.2) on φ in world axes, V_m column by column
(the pass with v = e_k, all k at once on an extra axis), G from the subtrees' mass and first moment, τ and the bias
from the pass contracted with φ. The arrays are laid out per link (`(..., n, 3)`), not per scalar. Measured on the
Panda, the same algorithm unrolled into scalar code (one array per component, zeros of the geometry dropped, like
generated code) gave an XLA program with 26,000 multiplies for Y alone (fusion copies the kinematics into each of Y's
490 outputs), and a Slotine–Li RK4 step that compiled in 51 s and ran in 825 µs; this layout: 8 s and 100 µs, on the
same loaded machine (benchmarks/bench_kinematic_tree.py). M by composite rigid bodies measured 2–3 times faster than
from the regressor's acceleration slot (n passes with a = e_k).

The hand frame (task space, :mod:`robotadapt.robots.hand`) comes from the same world poses and joint motions S̃_j:
:meth:`KinematicTree.hand` (p, R, the geometric Jacobian and its rate) and the kinematic basis, one column per nonzero
component of a placement translation (a vector fixed in a link, so ∂/∂q_l is u_l × ·).

Every method takes leading batch axes and is written with the namespace of its inputs (no writes, no branching on
values; small products switch between multiply-and-sum and matmul on the static batch size), so the same code runs in
numpy and under `jax.jit`, `vmap` and `lax.scan` (float64 needs `jax_enable_x64`). The model's constants are numpy
arrays in `_const`, a dict, which the model's pytree structure keeps as constants (robotadapt.pytree).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import array_namespace
from ..validation import ConfigError, as_array, as_scalar, as_vector, check_names, check_spd, check_switch
from .base import Array, RobotModel
from .dh import EXTRAS, LINK_KEYS, SIGNED, SMOOTH_VELOCITY, Geometry, SerialChain, joint_placements
from .hand import Hand, TaskKinematics, hand_on, tool_names, tool_values
from .hand import cross as _cross

_MATMUL_ABOVE = 64  # leading size (states × links) above which small products use matmul (see `_many`)
_PAIRS = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))  # I_xx, I_xy, I_yy, I_xz, I_yz, I_zz
# Pinocchio joints this model takes: short name → (kind, axis or None: the joint's own `axis`)
_PIN_JOINTS: dict[str, tuple[str, tuple[float, ...] | None]] = {f"JointModel{p}{x}": (k, tuple(float(c == x) for c in "XYZ"))
               for p, k in (("R", "R"), ("RUB", "R"), ("P", "P")) for x in "XYZ"}
_PIN_JOINTS |= {"JointModelRevoluteUnaligned": ("R", None), "JointModelRevoluteUnboundedUnaligned": ("R", None),
                "JointModelPrismaticUnaligned": ("P", None)}


def _concat(xp: Any, arrays: list[Array]) -> Array:
    """Concatenate along the last axis, broadcasting the others."""
    lead = tuple(np.broadcast_shapes(*(a.shape[:-1] for a in arrays)))
    return xp.concat([xp.broadcast_to(a, lead + a.shape[-1:]) for a in arrays], axis=-1)


def _skew(xp: Any, a: Array) -> Array:
    """[a]×, shape `(..., 3, 3)`: [a]× b = a × b."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    z = 0.0 * a0
    return xp.stack([xp.stack([z, -a2, a1], axis=-1), xp.stack([a2, z, -a0], axis=-1),
                     xp.stack([-a1, a0, z], axis=-1)], axis=-2)


def _many(A: Array) -> bool:
    """Whether products over the leading axes of A go to matmul: measured faster under XLA for many states (batches),
    slower for one (where multiply-and-sum fuses with its neighbours). Shapes are static: a trace-time choice."""
    return math.prod(A.shape[:-2]) > _MATMUL_ABOVE


def _mm(A: Array, B: Array) -> Array:
    """A B over leading axes (small matrices)."""
    return A @ B if _many(A) else (A[..., :, :, None] * B[..., None, :, :]).sum(axis=-2)


def _mv(R: Array, x: Array) -> Array:
    """R x over leading axes."""
    return (R @ x[..., None])[..., 0] if _many(R) else (R * x[..., None, :]).sum(axis=-1)


def _mtv(R: Array, x: Array) -> Array:
    """Rᵀ x over leading axes: a world vector in link axes."""
    return (x[..., None, :] @ R)[..., 0, :] if _many(R) else (R * x[..., :, None]).sum(axis=-2)


def _sym(xp: Any, six: Array) -> Array:
    """The symmetric 3×3 of the entries [xx, xy, yy, xz, yz, zz] on the last axis."""
    xx, xy, yy, xz, yz, zz = (six[..., k] for k in range(6))
    return xp.stack([xp.stack([xx, xy, xz], axis=-1), xp.stack([xy, yy, yz], axis=-1),
                     xp.stack([xz, yz, zz], axis=-1)], axis=-2)


def _pair_columns(xp: Any, x: Array) -> Array:
    """E_c x for the six inertia entries c (E_c the symmetric unit tensor), shape `(..., 6, 3)`."""
    x0, x1, x2 = x[..., 0], x[..., 1], x[..., 2]
    z = 0.0 * x0
    return xp.stack([xp.stack(c, axis=-1) for c in ((x0, z, z), (x1, x0, z), (z, x1, z), (x2, z, x0), (z, x2, x1),
                                                    (z, z, x2))], axis=-2)


def _ldl_solve(xp: Any, M: Array, b: Array) -> Array:
    """x with M x = b over leading axes, M symmetric, by M = L D Lᵀ unrolled over the entries (no pivoting)."""
    n = M.shape[-1]
    L: list[list[Any]] = [[None] * n for _ in range(n)]
    D: list[Any] = []
    for j in range(n):
        D.append(M[..., j, j] - sum((L[j][k] * L[j][k] * D[k] for k in range(j)), 0.0))
        for i in range(j + 1, n):
            L[i][j] = (M[..., i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)), 0.0)) / D[j]
    y: list[Any] = []
    for i in range(n):
        y.append(b[..., i] - sum((L[i][k] * y[k] for k in range(i)), 0.0))
    x: list[Any] = [None] * n
    for i in reversed(range(n)):
        x[i] = y[i] / D[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), 0.0)
    return xp.stack(xp.broadcast_arrays(*x), axis=-1)


def _link(kind: str, PR: Array, Pp: Array, u: Array, LR: Array, Lp: Array) -> tuple[Array, ...]:
    """(C_c, C_s, C_1, p_c, p_s, p_1, p_q, σ, s): the link frame in its parent's is R = C_c cos q + C_s sin q + C_1,
    p = p_c cos q + p_s sin q + p_1 + p_q q; S = [σ; s] the joint's motion in link axes at the link origin."""
    zero3, zero33 = np.zeros(3), np.zeros((3, 3))
    if kind == "R":  # Rot(u, q) = cos q (1 − u uᵀ) + sin q [u]× + u uᵀ
        uu, K = np.outer(u, u), np.cross(np.eye(3), u)  # K = [u]×: row i is e_i × u = −u × e_i
        sigma = LR.T @ u
        return (PR @ (np.eye(3) - uu) @ LR, PR @ K @ LR, PR @ uu @ LR, PR @ (np.eye(3) - uu) @ Lp, PR @ K @ Lp,
                Pp + PR @ uu @ Lp, zero3, sigma, np.cross(-LR.T @ Lp, sigma))  # s = r × σ, r the joint origin
    return zero33, zero33, PR @ LR, zero3, zero3, Pp + PR @ Lp, PR @ u, zero3, LR.T @ u


@dataclass(frozen=True, eq=False)
class _Kin:
    """World poses of the links (R0 `(..., n, 3, 3)`, p0 `(..., n, 3)`) and the joints' motion S̃_j = [u_j; x_j] in world
    axes at the world origin."""

    R0: Array
    p0: Array
    u: Array
    x: Array

    def expand(self) -> _Kin:
        """An axis before the links' (for passes over unit vectors e_k)."""
        return _Kin(self.R0[..., None, :, :, :], self.p0[..., None, :, :], self.u[..., None, :, :], self.x[..., None, :, :])


@dataclass(frozen=True, eq=False)
class _Motion:
    """One Newton–Euler pass in link axes, bilinear in two velocities (slot 1 q̇, slot 2 v; `same` when v = q̇): angular
    and linear (origin) velocities per slot (None: zero), angular acceleration (None: zero) and the classical
    acceleration of the origin (gravity as −g at the base), each `(..., n, 3)`."""

    w: Array  # each of w, wv, lin, alpha may be None (zero)
    wv: Array
    lin: Array
    alpha: Array
    acc: Array
    same: bool


@dataclass(frozen=True, eq=False)
class KinematicTree(SerialChain, TaskKinematics, RobotModel):
    """A chain (or tree) of revolute ('R') and prismatic ('P') joints: constants only, every method traceable.

    Per joint: `parents` (index of the parent joint, −1 for the base; parents come first), `rotation` (n, 3, 3) and
    `translation` (n, 3) the joint frame in the parent link's frame at q = 0, `axis` (n, 3) unit, in the joint frame,
    `link_rotation`, `link_translation` the link frame in the joint frame; `g` the gravity vector (m/s², base axes);
    `link_params` (n, 10) the standard parameters `default_phi` starts with; `rotor_inertia`, `viscous`, `coulomb`,
    `smooth_coulomb`, `offset` (n,) or None: the column groups present and their default values, and
    `smooth_coulomb_velocity` v_s (rad/s or m/s; one, or one per joint) of the smooth Coulomb column; `joint_names`,
    `q_limits` (n, 2), `dq_limits` and `tau_limits` (n,) (a URDF's `<limit velocity effort>`), `name` informative
    (exciting trajectories respect them).
    Build one with :meth:`from_urdf`, :meth:`example`, :meth:`from_pinocchio`, :meth:`from_dh` or :meth:`from_symbolic`;
    `dataclasses.replace` makes variants.
    """

    joints: str
    parents: tuple[int, ...]
    rotation: Any
    translation: Any
    axis: Any
    link_rotation: Any
    link_translation: Any
    g: Any
    link_params: Any
    rotor_inertia: Any = None
    viscous: Any = None
    coulomb: Any = None
    joint_names: tuple[str, ...] = ()
    q_limits: Any = None
    dq_limits: Any = None
    tau_limits: Any = None
    name: str = "chain"
    smooth_coulomb: Any = None
    offset: Any = None
    smooth_coulomb_velocity: Any = SMOOTH_VELOCITY
    _const: dict[str, Array] = field(init=False, repr=False)
    _chain: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.joints, str) or not self.joints or set(self.joints) - {"R", "P"}:
            raise ConfigError("robot.joints", f"expected a string of 'R' (revolute) and 'P' (prismatic), got "
                              f"{self.joints!r}")
        n, set_ = len(self.joints), object.__setattr__
        try:
            parents = tuple(int(j) for j in self.parents)
        except (TypeError, ValueError):
            parents = ()
        if len(parents) != n or any(not -1 <= j < i for i, j in enumerate(parents)):
            raise ConfigError("robot.parents", f"expected {n} parent indices, each −1 (the base) or an earlier joint, "
                              f"got {self.parents!r}")
        set_(self, "parents", parents)
        for name, shape in (("rotation", (n, 3, 3)), ("translation", (n, 3)), ("axis", (n, 3)),
                            ("link_rotation", (n, 3, 3)), ("link_translation", (n, 3)), ("link_params", (n, 10))):
            arr = as_array(getattr(self, name), f"robot.{name}")
            if arr.shape != shape:
                raise ConfigError(f"robot.{name}", f"expected shape {shape}, got {arr.shape}")
            set_(self, name, arr)
        for name in ("rotation", "link_rotation"):
            R = getattr(self, name)
            if np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max() > 1e-9 or np.any(np.linalg.det(R) < 0):
                raise ConfigError(f"robot.{name}", "every entry must be a rotation matrix (orthonormal, det +1)")
        if np.abs(np.linalg.norm(self.axis, axis=-1) - 1.0).max() > 1e-9:
            raise ConfigError("robot.axis", f"every joint axis must be a unit vector, got {self.axis.tolist()}")
        set_(self, "g", as_vector(self.g, 3, "robot.g", broadcast=False))
        self._check_extras()
        if self.q_limits is not None:
            limits = np.asarray(self.q_limits, dtype=float)
            if limits.shape != (n, 2) or np.any(np.isnan(limits)) or np.any(limits[:, 0] >= limits[:, 1]):
                raise ConfigError("robot.q_limits", f"expected {n} rows [lower, upper] with lower < upper")
            set_(self, "q_limits", limits)
        for name in ("dq_limits", "tau_limits"):
            if getattr(self, name) is not None:
                set_(self, name, as_vector(getattr(self, name), n, f"robot.{name}", positive=True, broadcast=False))
        names = tuple(str(x) for x in self.joint_names) or tuple(f"joint{i + 1}" for i in range(n))
        if len(names) != n:
            raise ConfigError("robot.joint_names", f"expected {n} names, got {len(names)}")
        set_(self, "joint_names", names)
        per_link = zip(*(_link(self.joints[i], self.rotation[i], self.translation[i], self.axis[i], self.link_rotation[i],
                               self.link_translation[i]) for i in range(n)), strict=True)
        const = dict(zip(("Cc", "Cs", "C1", "pc", "ps", "p1", "pq", "sigma", "s"), map(np.array, per_link), strict=True))
        down = np.eye(n)  # down[j, i] = 1 when joint j moves link i (j is i or an ancestor)
        for i, k in enumerate(parents):
            if k >= 0:
                down[:, i] += down[:, k]
        const |= {"down": down, "up": down.T.copy(), "minus_g": -self.g, "eye": np.eye(n)}
        set_(self, "_const", const | self._hand_constants(down))
        set_(self, "_chain", parents == tuple(range(-1, n - 1)))

    # -- construction -------------------------------------------------------------------------------------------------

    @classmethod
    def from_pinocchio(cls, model: Any, rotor_inertia: bool = False, viscous: bool = False, coulomb: bool = False,
                       name: str = "pinocchio", smooth_coulomb: bool = False, offset: bool = False,
                       smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> KinematicTree:
        """The chain (or tree) of a `pinocchio.Model` of revolute, continuous and prismatic joints (any axis); φ about
        each joint frame (Pinocchio's); `default_phi` from its inertias, then `armature`, `damping`, `friction`, and
        zero for the smooth Coulomb and offset groups (a URDF has no such numbers)."""
        return cls._from_model(model, {"rotor_inertia": rotor_inertia, "viscous": viscous, "coulomb": coulomb,
                                       "smooth_coulomb": smooth_coulomb, "offset": offset}, smooth_coulomb_velocity,
                               name, "robot.model")

    @classmethod
    def _from_model(cls, model: Any, flags: dict[str, Any], smooth_coulomb_velocity: Any, name: str,
                    field_: str) -> KinematicTree:
        for key, flag in flags.items():
            check_switch(flag, f"robot.{key}")
        kinds, axes, bad = [], [], []
        for j in range(1, model.njoints):
            short = model.joints[j].shortname()
            if short not in _PIN_JOINTS:
                bad.append(f"{model.names[j]!r} ({short.removeprefix('JointModel')})")
                continue
            kind, axis = _PIN_JOINTS[short]
            kinds.append(kind)
            axes.append(axis if axis is not None else np.asarray(model.joints[j].extract().axis, dtype=float))
        if bad:
            raise ConfigError(field_, f"joint {', '.join(bad)} is not revolute, continuous or prismatic: make it fixed, "
                              "or lock it (robot.locked)")
        if not kinds:
            raise ConfigError(field_, "the model has no moving joint")
        joints = range(1, model.njoints)
        limits = np.array([[model.lowerPositionLimit[model.idx_qs[j]], model.upperPositionLimit[model.idx_qs[j]]]
                           if model.joints[j].nq == 1 else [-np.inf, np.inf] for j in joints])
        q_limits = limits if np.all(limits[:, 0] < limits[:, 1]) else None
        rates = {name: values if np.all(np.isfinite(values) & (values > 0)) else None for name, values in
                 (("dq_limits", np.array([model.velocityLimit[model.idx_vs[j]] for j in joints])),
                  ("tau_limits", np.array([model.effortLimit[model.idx_vs[j]] for j in joints])))}
        placements = [model.jointPlacements[j] for j in joints]
        n = len(kinds)
        extras = {"rotor_inertia": model.armature, "viscous": model.damping, "coulomb": model.friction,
                  "smooth_coulomb": np.zeros(n), "offset": np.zeros(n)}
        return cls("".join(kinds), tuple(int(model.parents[j]) - 1 for j in joints),
                   np.array([X.rotation for X in placements]), np.array([X.translation for X in placements]),
                   np.array(axes), np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), np.array(model.gravity.linear),
                   np.array([model.inertias[j].toDynamicParameters() for j in joints]),
                   **{k: np.array(v, dtype=float) if flags[k] else None for k, v in extras.items()},
                   joint_names=tuple(model.names[1:]), q_limits=q_limits, name=name,
                   smooth_coulomb_velocity=smooth_coulomb_velocity, **rates)

    @classmethod
    def from_urdf(cls, path: str | PathLike[str], locked: Sequence[str] = (), rotor_inertia: bool = False,
                  viscous: bool = False, coulomb: bool = False, gravity: Any = None, smooth_coulomb: bool = False,
                  offset: bool = False, smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> KinematicTree:
        """The arm of the URDF file `path` read by Pinocchio, with the joints named in `locked` fixed at their neutral
        position (grippers), optional column groups (defaults from the URDF's `<dynamics damping friction>`, zero for
        the smooth Coulomb and offset groups), and `gravity` (m/s², base axes; default (0, 0, −9.81))."""
        from .pinocchio import urdf_model

        model = urdf_model(path, locked, gravity, "robot.urdf", "robot.locked")
        flags = {"rotor_inertia": rotor_inertia, "viscous": viscous, "coulomb": coulomb,
                 "smooth_coulomb": smooth_coulomb, "offset": offset}
        return cls._from_model(model, flags, smooth_coulomb_velocity, Path(path).stem, "robot.urdf")

    @classmethod
    def example(cls, name: str, locked: Sequence[str] = (), rotor_inertia: bool = False, viscous: bool = False,
                coulomb: bool = False, smooth_coulomb: bool = False, offset: bool = False,
                smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> KinematicTree:
        """An arm of `example-robot-data` (offline, `robotadapt.robots.pinocchio.EXAMPLES`), grippers locked."""
        from .pinocchio import example_urdf

        path, gripper = example_urdf(name)
        arm = cls.from_urdf(path, gripper + tuple(locked), rotor_inertia, viscous, coulomb, None, smooth_coulomb,
                            offset, smooth_coulomb_velocity)
        return replace(arm, name=name)

    @classmethod
    def from_dh(cls, links: Sequence[dict[str, Any]], convention: str = "standard", g: Any = (0.0, 0.0, -9.81),
                smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> KinematicTree:
        """An arm from DH rows, the link tables of :func:`robotadapt.robots.symbolic.from_dh_table` (`joint`, `a`,
        `alpha`, `d`, `theta`, `m`, `com`, `inertia` about the centre of mass, optional `rotor_inertia`, `viscous`,
        `coulomb`, `smooth_coulomb`, `offset`, `q_limits`), v_s of the smooth Coulomb columns; φ in each link's DH
        frame, as :class:`robotadapt.robots.symbolic.SymbolicArm`.
        Standard: frame i = frame i−1 · Rz(θ) Tz(d) Tx(a) Rx(α); modified (Craig): Rx(α) Tx(a) Rz(θ) Tz(d)."""
        if isinstance(links, dict | str) or not isinstance(links, Sequence) or not links:
            raise ConfigError("robot.links", "expected a list of link tables ([[robot.links]] in TOML), one per joint")
        if convention not in ("standard", "modified"):
            raise ConfigError("robot.convention", f"expected 'standard' or 'modified', got {convention!r}")
        rows: dict[str, list[Any]] = {k: [] for k in ("joint", "a", "alpha", "d", "theta", "params")}
        for i, link in enumerate(links):
            where = f"robot.links[{i}]"
            if not isinstance(link, dict):
                raise ConfigError(where, f"expected a table with keys {', '.join(LINK_KEYS)}, got {link!r}")
            check_names(list(link), LINK_KEYS, where)
            if link.get("joint", "R") not in ("R", "P"):
                raise ConfigError(f"{where}.joint", f"expected 'R' (revolute) or 'P' (prismatic), got {link['joint']!r}")
            if "m" not in link:
                raise ConfigError(f"{where}.m", "missing: the link's mass in kg")
            rows["joint"].append(link.get("joint", "R"))
            for key in ("a", "alpha", "d", "theta"):
                rows[key].append(as_scalar(link.get(key, 0.0), f"{where}.{key}"))
            m = as_scalar(link["m"], f"{where}.m", nonnegative=True)
            c = as_vector(link.get("com", 0.0), 3, f"{where}.com")
            inertia = as_array(link.get("inertia", np.zeros(3)), f"{where}.inertia")
            inertia = np.diag(inertia) if inertia.shape == (3,) else inertia
            if inertia.shape != (3, 3):
                raise ConfigError(f"{where}.inertia", f"expected 3 principal moments or a 3x3 tensor, got {inertia.shape}")
            check_spd(inertia, f"{where}.inertia", semidefinite=True)
            I_o = inertia + m * (c @ c * np.eye(3) - np.outer(c, c))  # about the frame origin (parallel axes)
            rows["params"].append([m, *(m * c), *(I_o[j, k] for j, k in _PAIRS)])
        extras = {key: [as_scalar(link.get(key, 0.0), f"robot.links[{i}].{key}", nonnegative=key not in SIGNED)
                        for i, link in enumerate(links)] for key in EXTRAS if any(key in link for link in links)}
        limits = [link.get("q_limits") for link in links]
        if any(x is not None for x in limits) and not all(x is not None for x in limits):
            raise ConfigError("robot.links", "q_limits must be given on every link or on none")
        gravity = as_vector(g, 3, "robot.g", broadcast=False)
        geo = Geometry("".join(rows["joint"]), tuple(rows["a"]), tuple(rows["alpha"]), tuple(rows["d"]),
                       tuple(rows["theta"]), convention == "modified", (gravity[0], gravity[1], gravity[2]))
        pre, post = zip(*joint_placements(geo), strict=True)
        n = geo.n
        return cls(geo.joints, tuple(range(-1, n - 1)), np.array([T[:3, :3] for T in pre]),
                   np.array([T[:3, 3] for T in pre]), np.tile([0.0, 0.0, 1.0], (n, 1)), np.array([T[:3, :3] for T in post]),
                   np.array([T[:3, 3] for T in post]), gravity, np.array(rows["params"]),
                   extras.get("rotor_inertia"), extras.get("viscous"), extras.get("coulomb"),
                   q_limits=None if limits[0] is None else as_array(limits, "robot.q_limits"), name="dh",
                   smooth_coulomb=extras.get("smooth_coulomb"), offset=extras.get("offset"),
                   smooth_coulomb_velocity=smooth_coulomb_velocity)

    @classmethod
    def from_symbolic(cls, arm: Any) -> KinematicTree:
        """The same arm as a :class:`robotadapt.robots.symbolic.SymbolicArm` (same φ, same columns), without sympy."""
        links = []
        for i, kind in enumerate(arm.joints):
            link = {"joint": kind, "a": arm.a[i], "alpha": arm.alpha[i], "d": arm.d[i], "theta": arm.theta[i],
                    "m": arm.mass[i], "com": arm.com[i], "inertia": arm.inertia[i]}
            link |= {key: getattr(arm, key)[i] for key in EXTRAS if getattr(arm, key) is not None}
            if arm.q_limits is not None:
                link["q_limits"] = arm.q_limits[i]
            links.append(link)
        return cls.from_dh(links, arm.convention, arm.g, arm.smooth_coulomb_velocity)

    # -- structure ----------------------------------------------------------------------------------------------------

    @property
    def default_phi(self) -> Array:
        """The chain's own parameters: `link_params` (URDF inertials or DH link data), then the extras' values."""
        xp = array_namespace(self.link_params)  # numpy; traced arrays when the compiled engine swaps the fields
        return xp.concat([xp.reshape(self.link_params, (-1,))] + [getattr(self, e) for e in self.extras])

    # -- task space (robotadapt.robots.hand) ------------------------------------------------------------------------

    def _hand_constants(self, down: Array) -> dict[str, Any]:
        """What the hand needs, from the geometry: the joints that move the last link (the hand's path), the kinematic
        parameters (a link index, n for the base; a unit vector in that link's axes; the joints that turn that link;
        name and value), the tool's three rows last, and the task axes."""
        n, last = self.n, self.n - 1
        path = down[:, last]
        rows: list[tuple[int, Array, str, float]] = []  # (link, vector in its axes, name, value)
        for k in np.flatnonzero(path):
            parent = self.parents[k] if self.parents[k] >= 0 else n
            for c, axis in enumerate("xyz"):
                if abs(self.translation[k, c]) > 1e-12:
                    rows.append((parent, np.eye(3)[c], f"{self.joint_names[k]}.{axis}", self.translation[k, c]))
                if abs(self.link_translation[k, c]) > 1e-12:
                    rows.append((int(k), self.link_rotation[k, c], f"{self.joint_names[k]}.link.{axis}",
                                 self.link_translation[k, c]))  # row c of L_R: Lᵣᵀ e_c
        links = [r[0] for r in rows] + [last] * 3
        moved = np.concatenate([down, np.zeros((n, 1))], axis=1)[:, links].T  # joint l moves the vector's link
        planes = [a for a in (2, 1, 0) if self._moves_across(a, path)]
        return {"hand_path": path, "kin_link": np.array(links, dtype=int),
                "kin_vector": np.array([r[1] for r in rows] + list(np.eye(3))).reshape(-1, 3), "kin_moved": moved,
                "kin_names": tuple(r[2] for r in rows), "kin_value": np.array([r[3] for r in rows], dtype=float),
                "task_axes": np.array([a for a in range(3) if a != planes[0]] if planes else [0, 1, 2], dtype=int)}

    def _moves_across(self, a: int, path: Array) -> bool:
        """Whether the hand stays in a plane normal to the base axis e_a: every fixed rotation keeps e_a (up to sign),
        every revolute joint on the path turns about ±e_a and every prismatic one slides across it."""
        on = path > 0
        keeps = (np.abs(np.abs(self.rotation[on][:, a, a]) - 1) < 1e-12).all() and \
            (np.abs(np.abs(self.link_rotation[on][:, a, a]) - 1) < 1e-12).all()
        kinds = np.array(list(self.joints))[on]
        return bool(keeps and (np.abs(np.abs(self.axis[on][kinds == "R", a]) - 1) < 1e-12).all()
                    and (np.abs(self.axis[on][kinds == "P", a]) < 1e-12).all())

    @property
    def task_axes(self) -> tuple[int, ...]:
        """(0, 1, 2), or the two base axes of the plane the hand moves in when every fixed rotation on its path keeps
        the third axis e_a, every revolute joint turns about ±e_a and every prismatic one slides across it (a planar
        arm: (0, 1) for joints about z)."""
        return tuple(int(a) for a in self._const["task_axes"])

    def kinematic_names(self, tool: Array | None = None) -> tuple[str, ...]:
        """The kinematic parameters of the hand position: for each joint on the hand's path, "<joint>.x|y|z" the nonzero
        components (|·| > 1e-12 m) of its placement `translation` (the joint frame's origin in the parent link's axes:
        a URDF joint's <origin xyz>), then "<joint>.link.x|y|z" those of `link_translation` (the link frame's origin in
        the joint frame after the joint's motion), then "tool.x|y|z" when a tool is given. DH arms (:meth:`from_dh`),
        standard convention: revolute joint i "jointi.link.x" = a_i, "jointi.link.z" = d_i; prismatic "jointi.z" = d_i
        (the constant part), "jointi.link.x" = a_i. Modified (Craig): "jointi.x" = a_{i−1}; revolute "jointi.link.z" =
        d_i; prismatic "jointi.y" = −d_i sin α_{i−1}, "jointi.z" = d_i cos α_{i−1}. A prismatic joint's travel q·axis
        is no parameter (index 0 of the basis)."""
        names: tuple[str, ...] = self._const["kin_names"]
        return names + tool_names(tool)

    def kinematic_values(self, tool: Array | None = None) -> Array:
        """The values of `kinematic_names(tool)` (m): the chain's own, then the tool's."""
        return tool_values(self._const["kin_value"], tool)

    def hand(self, q: Array, dq: Array, tool: Array | None = None) -> Hand:
        """The last link's frame offset by `tool` (:meth:`TaskKinematics.hand`): with S̃_j = [u_j; x_j] joint j's motion
        in world axes at the world origin and V_j = [ω_j; v_j] = Σ S̃_l q̇_l over the joints that move link j,
        J_j = [x_j + u_j × p; u_j] and, as Ṡ_j = V_j ×ₘ S̃_j = [ω_j × u_j; ω_j × x_j + v_j × u_j] (Featherstone 2008,
        §2.9) and ṗ = v_n + ω_n × p, J̇_j = [ẋ_j + u̇_j × p + u_j × ṗ; u̇_j], for the joints that move the last link."""
        xp, _, (q, dq) = self._inputs(q, dq)
        return self._hand(xp, q, dq, tool)[0]

    def _hand(self, xp: Any, q: Array, dq: Array, tool: Array | None) -> tuple[Hand, _Kin, Array, Array]:
        """(the hand, the link poses, each link's angular velocity ω_j and the rate u̇_j of each joint axis)."""
        kin = self._kinematics(xp, q)
        u, x = kin.u, kin.x
        V = self._ancestors(xp, dq[..., None] * xp.concat([u, x], axis=-1))
        w, lin = V[..., 0:3], V[..., 3:6]
        R = kin.R0[..., -1, :, :]
        p = kin.p0[..., -1, :] if tool is None else kin.p0[..., -1, :] + _mv(R, xp.asarray(tool))
        p_dot = lin[..., -1, :] + _cross(xp, w[..., -1, :], p)
        du = _cross(xp, w, u)
        dx = _cross(xp, w, x) + _cross(xp, lin, u)
        path = self._const["hand_path"][:, None]
        J = xp.concat([x + _cross(xp, u, p[..., None, :]), u], axis=-1) * path  # (..., n, 6): columns
        dJ = xp.concat([dx + _cross(xp, du, p[..., None, :]) + _cross(xp, u, p_dot[..., None, :]), du], axis=-1) * path
        return hand_on(xp, q, dq, p, R, xp.swapaxes(J, -1, -2), xp.swapaxes(dJ, -1, -2)), kin, w, du

    def _kinematic_columns(self, q: Array, dq: Array, tool: Array | None) -> tuple[Hand, Array, Array, Array]:
        """Each parameter multiplies a unit vector w_j = R_ℓ e_j fixed in a link ℓ (or the base):
        ∂w_j/∂q_l = u_l × w_j for each revolute joint l that moves ℓ (u_l = 0 for a prismatic one), and
        d/dt (u_l × w_j) = u̇_l × w_j + u_l × (ω_ℓ × w_j)."""
        xp, _, (q, dq) = self._inputs(q, dq)
        hand, kin, w, du = self._hand(xp, q, dq, tool)
        k = len(self.kinematic_names(tool))
        const = self._const
        links = const["kin_link"][:k]
        base = xp.broadcast_to(xp.eye(3), kin.R0.shape[:-3] + (1, 3, 3))  # the base's axes: index n
        R_of = xp.take(xp.concat([kin.R0, base], axis=-3), links, axis=-3)
        W = _mv(R_of, const["kin_vector"][:k])  # (..., k, 3)
        omega = xp.take(xp.concat([w, xp.zeros(w.shape[:-2] + (1, 3))], axis=-2), links, axis=-2)
        moved = const["kin_moved"][:k, :, None]  # (k, n, 1)
        u = kin.u[..., None, :, :]
        B = moved * _cross(xp, u, W[..., :, None, :])  # (..., k, n, 3)
        dB = moved * (_cross(xp, du[..., None, :, :], W[..., :, None, :])
                      + _cross(xp, u, _cross(xp, omega, W)[..., :, None, :]))
        return hand, W, xp.swapaxes(B, -1, -2), xp.swapaxes(dB, -1, -2)

    # -- the recursion --------------------------------------------------------------------------------------------------

    def _kinematics(self, xp: Any, q: Array) -> _Kin:
        """World poses by the chain of link transforms (a loop over the links) and the joints' world motion S̃_j."""
        k = self._const
        c, s = xp.cos(q)[..., None], xp.sin(q)[..., None]
        R = c[..., None] * k["Cc"] + s[..., None] * k["Cs"] + k["C1"]
        p = c * k["pc"] + s * k["ps"] + k["p1"] + q[..., None] * k["pq"]
        R0: list[Array] = []
        p0: list[Array] = []
        for i, parent in enumerate(self.parents):
            Ri, pi = R[..., i, :, :], p[..., i, :]
            if parent < 0:
                R0.append(Ri)
                p0.append(pi)
            else:
                R0.append(_mm(R0[parent], Ri))
                p0.append(p0[parent] + _mv(R0[parent], pi))
        R0s, p0s = xp.stack(R0, axis=-3), xp.stack(p0, axis=-2)
        u = _mv(R0s, k["sigma"])
        return _Kin(R0s, p0s, u, _mv(R0s, k["s"]) + _cross(xp, p0s, u))

    def _pass(self, xp: Any, kin: _Kin, dq: Array, v: Array, a: Array, gravity: bool) -> _Motion:
        """The Newton–Euler forward pass in world axes, bilinear in (q̇, v) (v None: v = q̇; None elsewhere: zero):
        V_i = Σ_j S̃_j q̇_j,  A_i = −g + Σ_j [S̃_j a_j + ½(V_j(q̇) ×ₘ S̃_j v_j + V_j(v) ×ₘ S̃_j q̇_j)] over the joints j
        that move link i, then in link i's axes. Quantities go through the sums and rotations stacked (fewer kernels)."""
        same, u, x, p0 = v is None, kin.u, kin.x, kin.p0
        S = xp.concat([u, x], axis=-1)
        w = wv = lin = linv = accel = None
        if dq is not None:
            V = self._ancestors(xp, dq[..., None] * S if same else _concat(xp, [dq[..., None] * S, v[..., None] * S]))
            w, lin = V[..., 0:3], V[..., 3:6]
            wv, linv, vs = (w, lin, dq) if same else (V[..., 6:9], V[..., 9:12], v)
            accel = vs[..., None] * _concat(xp, [_cross(xp, w, u), _cross(xp, w, x) + _cross(xp, lin, u)])
            if not same:  # (V_j ×ₘ S̃_j) v_j polarised
                accel = 0.5 * (accel + dq[..., None] * _concat(xp, [_cross(xp, wv, u), _cross(xp, wv, x)
                                                                    + _cross(xp, linv, u)]))
        if a is not None:
            accel = a[..., None] * S if accel is None else accel + a[..., None] * S
        vectors = []  # world vectors to express in link axes (velocities at the link origin: v + ω × p)
        if w is not None:
            vectors += [w, lin + _cross(xp, w, p0)] + ([] if same else [wv, linv + _cross(xp, wv, p0)])
        if accel is not None:
            accel = self._ancestors(xp, accel)
            alpha, acc = accel[..., 0:3], accel[..., 3:6] + _cross(xp, accel[..., 0:3], p0)
            vectors += [alpha, acc + self._const["minus_g"] if gravity else acc]
        elif gravity:
            vectors.append(0.0 * p0 + self._const["minus_g"])
        if not vectors:
            return _Motion(None, None, None, None, 0.0 * p0, True)
        local = _mtv(kin.R0[..., None, :, :], xp.stack(vectors, axis=-2))  # Rᵀ y, (..., n, k, 3)
        alpha = local[..., -2, :] if accel is not None else None
        acc = local[..., -1, :]
        if w is None:
            return _Motion(None, None, None, alpha, acc, True)
        w_l, lin_l = local[..., 0, :], local[..., 1, :]
        if same:
            return _Motion(w_l, w_l, lin_l, alpha, acc + _cross(xp, w_l, lin_l), True)
        wv_l, linv_l = local[..., 2, :], local[..., 3, :]
        return _Motion(w_l, wv_l, lin_l, alpha, acc + 0.5 * (_cross(xp, w_l, linv_l) + _cross(xp, wv_l, lin_l)), False)

    def _ancestors(self, xp: Any, y: Array) -> Array:
        """Σ_j y_j over the joints j that move link i (j = i or an ancestor), along axis −2: a cumulative sum for a
        chain (measured faster under XLA than the product with the 0/1 matrix a tree needs)."""
        return xp.cumsum(y, axis=-2) if self._chain else xp.matmul(self._const["up"], y)

    def _subtree(self, xp: Any, y: Array) -> Array:
        """Σ_i y_i over the links i that joint j moves (its subtree), along axis −2."""
        if self._chain:
            return xp.flip(xp.cumsum(xp.flip(y, axis=-2), axis=-2), axis=-2)
        return xp.matmul(self._const["down"], y)

    @staticmethod
    def _link_regressor(xp: Any, m: _Motion) -> Array:
        """A_i, link i's wrench [moment about its origin; force] = A_i φ_i, shape `(..., n, 6, 10)`, columns
        m → [0; ā],  h_k → [e_k × ā; α × e_k + ω × (ω × e_k)],  I_c → [E_c α + ω × E_c ω; 0]  (ω-products polarised)."""
        acc = m.acc
        moment_h, force_h = -_skew(xp, acc), 0.0 * acc[..., None] + 0.0 * acc[..., None, :]
        moment_i = 0.0 * acc[..., None, :] + xp.zeros((6, 3))
        if m.alpha is not None:
            force_h = force_h + _skew(xp, m.alpha)
            moment_i = moment_i + _pair_columns(xp, m.alpha)
        if m.w is not None:  # ½[ω × (ωv × e) + ωv × (ω × e)] = ½(ωv ωᵀ + ω ωvᵀ)e − (ω·ωv) e
            w, wv = m.w, m.wv
            dot = (w * wv).sum(axis=-1)[..., None, None]
            force_h = force_h + 0.5 * (wv[..., :, None] * w[..., None, :] + w[..., :, None] * wv[..., None, :]) \
                - dot * xp.eye(3)
            moment_i = moment_i + (_cross(xp, w[..., None, :], _pair_columns(xp, wv)) if m.same else
                                   0.5 * (_cross(xp, w[..., None, :], _pair_columns(xp, wv))
                                          + _cross(xp, wv[..., None, :], _pair_columns(xp, w))))
        zero = 0.0 * acc[..., None]
        moment = xp.concat([zero, moment_h, xp.swapaxes(moment_i, -1, -2)], axis=-1)
        force = xp.concat([acc[..., None], force_h, zero + xp.zeros(6)], axis=-1)
        return xp.concat([moment, force], axis=-2)

    def _project(self, xp: Any, kin: _Kin, A: Array) -> Array:
        """Y[j, 10 i + c] = S̃_jᵀ (X_i* A_i)[:, c] for the joints j that move link i: link wrenches to world axes
        (f̃ = R0 f, ñ = R0 n + p0 × f̃), then dotted with the joints' world motion; shape `(..., n, 10n)`."""
        R0 = kin.R0
        force = _mm(R0, A[..., 3:, :])
        moment = _mm(R0, A[..., :3, :]) + _mm(_skew(xp, kin.p0), force)
        S = xp.concat([kin.u, kin.x], axis=-1)
        Y = xp.einsum("...jd,...idc->...jic", S, xp.concat([moment, force], axis=-2)) * self._const["down"][:, :, None]
        return xp.reshape(Y, Y.shape[:-2] + (10 * self.n,))

    def _wrench_torques(self, xp: Any, kin: _Kin, m: _Motion, phi: Array) -> Array:
        """τ_j = S̃_jᵀ Σ_i X_i* (A_i φ_i) over the links j moves, with n = I α + ω × I ω + h × ā and
        f = m ā + α × h + ω × (ω × h) (ω-products polarised)."""
        links = xp.reshape(phi[..., : 10 * self.n], phi.shape[:-1] + (self.n, 10))
        mass, h, inertia = links[..., 0:1], links[..., 1:4], _sym(xp, links[..., 4:10])
        moment, force = _cross(xp, h, m.acc), mass * m.acc
        if m.alpha is not None:
            moment, force = moment + _mv(inertia, m.alpha), force + _cross(xp, m.alpha, h)
        if m.w is not None:
            pairs = [(m.w, m.wv)] if m.same else [(m.w, m.wv), (m.wv, m.w)]
            scale = 1.0 / len(pairs)
            for a, b in pairs:
                moment = moment + scale * _cross(xp, a, _mv(inertia, b))
                force = force + scale * _cross(xp, a, _cross(xp, b, h))
        world = _mv(kin.R0[..., None, :, :], xp.stack([moment, force], axis=-2))
        force = world[..., 1, :]
        total = self._subtree(xp, _concat(xp, [world[..., 0, :] + _cross(xp, kin.p0, force), force]))
        return (xp.concat([kin.u, kin.x], axis=-1) * total).sum(axis=-1)

    def _world_inertias(self, xp: Any, kin: _Kin, phi: Array) -> tuple[Array, Array, Array]:
        """Composite (subtree) mass `(..., n, 1)`, first moment `(..., n, 3)` and inertia `(..., n, 3, 3)` about the world
        origin in world axes: h̃ = R h + m p, Ĩ = R I Rᵀ − p h̃ᵀ − h̃ pᵀ + 2(h̃·p) 1 − m(p pᵀ − |p|² 1) with h̃ = R h."""
        links = xp.reshape(phi[..., : 10 * self.n], phi.shape[:-1] + (self.n, 10))
        mass, h = links[..., 0], links[..., 1:4]
        R0, p0 = kin.R0, kin.p0
        Rh = _mv(R0, h)
        RIRt = _mm(_mm(R0, _sym(xp, links[..., 4:10])), xp.swapaxes(R0, -1, -2))
        pp, ph = (p0 * p0).sum(axis=-1), (p0 * Rh).sum(axis=-1)
        outer = p0[..., :, None] * Rh[..., None, :]
        inertia = RIRt - outer - xp.swapaxes(outer, -1, -2) - mass[..., None, None] * p0[..., :, None] * p0[..., None, :] \
            + (2.0 * ph + mass * pp)[..., None, None] * xp.eye(3)
        flat = xp.reshape(inertia, inertia.shape[:-2] + (9,))
        composite = xp.reshape(self._subtree(xp, flat), flat.shape[:-2] + (self.n, 3, 3))
        return self._subtree(xp, mass[..., None]), self._subtree(xp, Rh + mass[..., None] * p0), composite

    def _with_extras(self, xp: Any, Y: Array, batch: tuple[int, ...], values: dict[str, Array]) -> Array:
        """Y with the extra column groups: diag(values[group]), zero for a group not in `values`."""
        Y = xp.broadcast_to(Y, batch + (self.n, 10 * self.n))
        if not self.extras:
            return Y
        eye = self._const["eye"]
        blocks = [Y]
        for e in self.extras:
            x = values.get(e)
            block = 0.0 * eye if x is None else x[..., :, None] * eye
            blocks.append(xp.broadcast_to(block, batch + (self.n, self.n)))
        return xp.concat(blocks, axis=-1)

    # -- the model ------------------------------------------------------------------------------------------------------

    def _inputs(self, *arrays: Array) -> tuple[Any, tuple[int, ...], list[Array]]:
        xp = array_namespace(*arrays)
        arrays = tuple(np.asarray(x, dtype=float) if xp is np else xp.asarray(x) for x in arrays)
        return xp, tuple(np.broadcast_shapes(*(x.shape[:-1] for x in arrays))), list(arrays)

    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        """Y(q, q̇, v, a), shape `(..., n, p)`: Y φ = M a + V_m(q, q̇) v + G + F(q̇) (P3), one bilinear pass."""
        xp, batch, (q, dq, v, a) = self._inputs(q, dq, v, a)
        kin = self._kinematics(xp, q)
        Y = self._project(xp, kin, self._link_regressor(xp, self._pass(xp, kin, dq, v, a, True)))
        return self._with_extras(xp, Y, batch, {"rotor_inertia": a, **self.friction_columns(dq)})

    def regressor_products(self, q: Array, dq: Array, v: Array, a: Array, phi: Array, r: Array) -> tuple[Array, Array]:
        """(Y φ, Yᵀ r) for Y = Y(q, q̇, v, a) without forming Y, from one bilinear pass: Y φ = Σ S̃_jᵀ X_i* (A_i φ_i) is
        the pass contracted with φ (as τ is), and link i's block of Yᵀ r is A_iᵀ W_i, W_i = [ω; v_o] the velocity
        of link i (in its axes, at its origin) that the joint rates r give, since Σ_j r_j S̃_jᵀ X_i* w = W_iᵀ w over
        the joints j that move link i. On the Panda, translated to C: 4 200 operations against 6 100 for Y φ and Yᵀ r
        through Y."""
        xp, batch, (q, dq, v, a, phi, r) = self._inputs(q, dq, v, a, phi, r)
        kin = self._kinematics(xp, q)
        m = self._pass(xp, kin, dq, v, a, True)
        Yphi = self._wrench_torques(xp, kin, m, phi) + self.friction(dq, phi)
        if self.rotor_inertia is not None:
            Yphi = Yphi + self._extra(phi, "rotor_inertia") * a
        W = self._ancestors(xp, r[..., None] * xp.concat([kin.u, kin.x], axis=-1))  # Σ r_j S̃_j, world, at the origin
        w, lin = W[..., 0:3], W[..., 3:6]
        local = _mtv(kin.R0[..., None, :, :], xp.stack([w, lin + _cross(xp, w, kin.p0)], axis=-2))  # (..., n, 2, 3)
        Ytr = (self._link_regressor(xp, m) * xp.reshape(local, local.shape[:-2] + (6, 1))).sum(axis=-2)  # (..., n, 10)
        Ytr = xp.reshape(Ytr, Ytr.shape[:-2] + (10 * self.n,))
        extras = {"rotor_inertia": a, **self.friction_columns(dq)}
        Ytr = xp.concat([xp.broadcast_to(Ytr, batch + Ytr.shape[-1:])]
                        + [xp.broadcast_to(extras[e] * r, batch + (self.n,)) for e in self.extras], axis=-1)
        return xp.broadcast_to(Yphi, batch + (self.n,)), Ytr

    def momentum_regressor(self, q: Array, dq: Array) -> Array:
        """Y_h(q, q̇) with Y_h φ = M(q) q̇ (6.6.3): the pass with zero velocity, acceleration q̇ and no gravity."""
        xp, batch, (q, dq) = self._inputs(q, dq)
        kin = self._kinematics(xp, q)
        Y = self._project(xp, kin, self._link_regressor(xp, self._pass(xp, kin, None, None, dq, False)))
        return self._with_extras(xp, Y, batch, {"rotor_inertia": dq})

    def remainder_regressor(self, q: Array, dq: Array) -> Array:
        """Y_g(q, q̇) with Y_g φ = −V_mᵀ q̇ + G + F (6.6.4), exact: row k of −V_mᵀ q̇ is −Σ_i V_iᵀ A_i(q̇, e_k), V_i link
        i's velocity and A_i(q̇, e_k) its wrench regressor in the pass with v = e_k (no gravity)."""
        xp, batch, (q, dq) = self._inputs(q, dq)
        kin = self._kinematics(xp, q)
        Y = self._project(xp, kin, self._link_regressor(xp, self._pass(xp, kin, None, None, None, True)))
        m = self._pass(xp, kin.expand(), dq[..., None, :], self._const["eye"], None, False)  # axis -3: k
        velocity = xp.concat([m.w, m.lin], axis=-1)[..., :1, :, :]  # slot 1 does not depend on k
        coriolis = (velocity[..., None] * self._link_regressor(xp, m)).sum(axis=-2)  # (..., k, i, 10)
        Y = Y - xp.reshape(coriolis, coriolis.shape[:-2] + (10 * self.n,))
        return self._with_extras(xp, Y, batch, self.friction_columns(dq))

    def mass_matrix(self, q: Array, phi: Array) -> Array:
        """M(q) (P1), shape `(..., n, n)`, by composite rigid bodies on φ: M_jk = S̃_jᵀ Ĩᶜ_k S̃_k for j moving k."""
        xp, batch, (q, phi) = self._inputs(q, phi)
        return xp.broadcast_to(self._mass(xp, self._kinematics(xp, q), phi), batch + (self.n, self.n))

    def _mass(self, xp: Any, kin: _Kin, phi: Array) -> Array:
        mass, h, inertia = self._world_inertias(xp, kin, phi)
        u, x = kin.u, kin.x
        ang = _mv(inertia, u) + _cross(xp, h, x)  # Ĩᶜ_k S̃_k = [I u + h × x; m x + u × h]
        lin = mass * x + _cross(xp, u, h)
        U = xp.einsum("...jd,...kd->...jk", u, ang) + xp.einsum("...jd,...kd->...jk", x, lin)
        down = self._const["down"]
        M = U * down + xp.swapaxes(U * down, -1, -2) - U * self._const["eye"]
        if self.rotor_inertia is not None:
            M = M + self._extra(phi, "rotor_inertia")[..., :, None] * self._const["eye"]
        return M

    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        """V_m(q, q̇) (P2, Christoffel form), column k = B(q̇, e_k): the bilinear pass with v = e_k, no gravity."""
        xp, batch, (q, dq, phi) = self._inputs(q, dq, phi)
        kin = self._kinematics(xp, q).expand()
        m = self._pass(xp, kin, dq[..., None, :], self._const["eye"], None, False)
        return xp.broadcast_to(xp.swapaxes(self._wrench_torques(xp, kin, m, phi[..., None, :]), -1, -2),
                               batch + (self.n, self.n))

    def gravity(self, q: Array, phi: Array) -> Array:
        """G(q), shape `(..., n)`: τ_j = S̃_jᵀ [h̃ᶜ_j × (−g); −mᶜ_j g] from the subtrees' mass and first moment."""
        xp, batch, (q, phi) = self._inputs(q, phi)
        kin = self._kinematics(xp, q)
        mass, h, _ = self._world_inertias(xp, kin, phi)
        minus_g = self._const["minus_g"]
        G = (kin.u * _cross(xp, h, minus_g + 0.0 * h)).sum(axis=-1) + (kin.x * minus_g).sum(axis=-1) * mass[..., 0]
        return xp.broadcast_to(G, batch + (self.n,))

    def inverse_dynamics(self, q: Array, dq: Array, ddq: Array, phi: Array) -> Array:
        """τ = M q̈ + V_m q̇ + G + F (6.2.1): the standard pass on φ, O(n²) with the subtree sums."""
        xp, batch, (q, dq, ddq, phi) = self._inputs(q, dq, ddq, phi)
        kin = self._kinematics(xp, q)
        tau = self._wrench_torques(xp, kin, self._pass(xp, kin, dq, None, ddq, True), phi) + self.friction(dq, phi)
        if self.rotor_inertia is not None:
            tau = tau + self._extra(phi, "rotor_inertia") * ddq
        return xp.broadcast_to(tau, batch + (self.n,))

    def forward_dynamics(self, q: Array, dq: Array, tau: Array, phi: Array) -> Array:
        """q̈ = M⁻¹ (τ − V_m q̇ − G − F): M by composite rigid bodies, the bias by one pass, an unrolled LDLᵀ solve
        (no pivoting: M symmetric with nonzero leading minors, as a plant's M is; elementwise, so it fuses under XLA
        and vectorises over batches, measured 5–10 % faster per closed-loop step than `linalg.solve`)."""
        xp, batch, (q, dq, tau, phi) = self._inputs(q, dq, tau, phi)
        kin = self._kinematics(xp, q)
        bias = self._wrench_torques(xp, kin, self._pass(xp, kin, dq, None, None, True), phi) + self.friction(dq, phi)
        return _ldl_solve(xp, self._mass(xp, kin, phi), tau - bias)
