"""Serial arms from Denavit–Hartenberg tables: M, Christoffel V_m, G, F and the mixed regressor derived with sympy.

    τ = M(q) q̈ + V_m(q, q̇) q̇ + G(q) + F(q̇)                              (6.2.1)
    Y(q, q̇, v, a) φ = M(q) a + V_m(q, q̇) v + G(q) + F(q̇)                 (docs/laws.md#model P3)

φ holds the standard inertial parameters, 10 per link ([m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]
with the inertia about the link-frame origin, link-frame axes: names "m1", "mx1", ..., "Izz1"), then optionally one
reflected rotor inertia per joint ("Ia1", ...: I_a q̈ on the joint, no gyroscopic coupling), one viscous ("fv1", ...:
f_v q̇), one Coulomb ("fc1", ...: f_c sgn q̇) and one smooth Coulomb coefficient ("fs1", ...: f_s tanh(q̇/v_s)), and a
constant torque offset ("off1", ...) (:class:`robotadapt.robots.dh.SerialChain`). The rigid-body part is derived and
compiled by
:mod:`robotadapt.robots.dh` (cached on disk, needs the `[symbolic]` extra on a cache miss only).

Models: :func:`from_dh_table` (any table, TOML-friendly), :func:`planar_arm` (an n-link planar family), :func:`puma560`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import InitVar, dataclass, field
from typing import Any

import numpy as np

from ..arrays import array_namespace
from ..pytree import derived
from ..validation import ConfigError, as_array, as_scalar, as_vector, check_names, check_spd, check_switch
from .base import Array, RobotModel
from .dh import EXTRAS, LINK_KEYS, SIGNED, SMOOTH_VELOCITY, Compiled, Geometry, SerialChain, compiled, joint_placements
from .hand import Hand, TaskKinematics
from .kinematic_tree import KinematicTree


@dataclass(frozen=True, eq=False)
class SymbolicArm(SerialChain, TaskKinematics, RobotModel):
    """A serial arm of revolute ('R') and prismatic ('P') joints given by its DH table and link inertias.

    Geometry (per joint, SI units): `a`, `alpha`, `d`, `theta` (for a revolute joint θ = q + theta, for a prismatic one
    d = q + d), `convention` "standard" (Rz(θ) Tz(d) Tx(a) Rx(α)) or "modified" (Craig: Rx(α) Tx(a) Rz(θ) Tz(d)),
    `g` the gravity vector (m/s², base frame). Inertia per link, in its DH frame: `mass` (kg), `com` (n, 3) centre of
    mass (m), `inertia` (n, 3, 3) about the centre of mass (kg m²). Optional per joint, each adding n columns to the
    regressor when given: `rotor_inertia` (kg m², reflected to the joint: J_m G²), `viscous` (N m s/rad), `coulomb`
    (N m), `smooth_coulomb` (N m, the coefficient of tanh(q̇/v_s), v_s = `smooth_coulomb_velocity` in rad/s), `offset`
    (N m, either sign). `q_limits` (n, 2), informative (trajectories should stay inside). `default_phi` is the vector
    these values give. The model is compiled at construction (from the disk cache when the geometry was derived
    before).
    """

    joints: str
    a: Any
    alpha: Any
    d: Any
    theta: Any
    mass: Any
    com: Any
    inertia: Any
    convention: str = "standard"
    g: Any = (0.0, 0.0, -9.81)
    rotor_inertia: Any = None
    viscous: Any = None
    coulomb: Any = None
    q_limits: Any = None
    smooth_coulomb: Any = None
    offset: Any = None
    smooth_coulomb_velocity: Any = SMOOTH_VELOCITY
    derive: InitVar[bool] = True  # False: the link data only, for the kinematic tree (no sympy, no generated code)
    _code: Compiled | None = field(init=False, repr=False, metadata={"internal": True})

    def __post_init__(self, derive: bool = True) -> None:
        if not isinstance(self.joints, str) or not self.joints or set(self.joints) - {"R", "P"}:
            raise ConfigError("robot.joints", f"expected a string of 'R' (revolute) and 'P' (prismatic), got "
                              f"{self.joints!r}")
        if self.convention not in ("standard", "modified"):
            raise ConfigError("robot.convention", f"expected 'standard' or 'modified', got {self.convention!r}")
        n = len(self.joints)
        set_ = object.__setattr__
        for name in ("a", "alpha", "d", "theta"):
            set_(self, name, as_vector(getattr(self, name), n, f"robot.{name}"))
        set_(self, "g", as_vector(self.g, 3, "robot.g", broadcast=False))
        set_(self, "mass", as_vector(self.mass, n, "robot.mass"))
        if np.any(self.mass < 0):
            raise ConfigError("robot.mass", f"masses must be zero or positive, got {self.mass}")
        set_(self, "com", _table(self.com, (n, 3), "robot.com"))
        inertia = _table(self.inertia, (n, 3, 3), "robot.inertia")
        for i in range(n):
            check_spd(inertia[i], f"robot.inertia[{i}]", semidefinite=True)
        set_(self, "inertia", inertia)
        self._check_extras()
        if self.q_limits is not None:
            limits = _table(self.q_limits, (n, 2), "robot.q_limits")
            if np.any(limits[:, 0] >= limits[:, 1]):
                raise ConfigError("robot.q_limits", "each row is [lower, upper] with lower < upper")
            set_(self, "q_limits", limits)
        set_(self, "_code", compiled(self.geometry) if derive else None)

    def __getstate__(self) -> dict[str, Any]:
        """Pickle (processes, Dask workers, deepcopy) without the compiled code, which is reloaded from the cache."""
        return {k: v for k, v in self.__dict__.items() if k != "_code"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        for key, value in state.items():
            object.__setattr__(self, key, value)
        object.__setattr__(self, "_code", compiled(self.geometry))

    # -- structure ----------------------------------------------------------------------------------------------------

    @property
    def geometry(self) -> Geometry:
        """What the symbolic derivation depends on (the inertial values do not enter it)."""
        a, alpha, d, theta, g = (tuple(float(x) for x in getattr(self, k)) for k in ("a", "alpha", "d", "theta", "g"))
        return Geometry(self.joints, a, alpha, d, theta, self.convention == "modified", (g[0], g[1], g[2]))

    @property
    def default_phi(self) -> Array:
        """The standard parameters of the given link data: m, m c, I_c + m(|c|² E − c cᵀ) per link, then the extras."""
        out = []
        for m, c, I_c in zip(self.mass, self.com, self.inertia, strict=True):
            I_o = I_c + m * (c @ c * np.eye(3) - np.outer(c, c))
            out += [m, *(m * c), I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]]
        return np.concatenate([np.array(out)] + [getattr(self, e) for e in self.extras])

    # -- evaluation of the generated functions --------------------------------------------------------------------

    def _eval(self, name: str, shape: tuple[int, ...], *args: Array) -> Array:
        """Call the generated function `name` and place its nonzero values into an array `(..., *shape)`."""
        code = self._code
        if code is None:
            raise ConfigError("robot.model", "this arm was built for the kinematic tree (derive=False): build it with "
                              "model = \"sympy\" to evaluate its generated code")
        pos, src, size = code.positions[name], code.sources[name], math.prod(shape)
        if all(type(x) is np.ndarray and x.ndim == 1 for x in args):  # one state: Python floats through `math`
            vals = code.scalar[name](*[x.tolist() for x in args])
            out = np.zeros(size)
            out[pos] = vals if src is None else np.array(vals)[src]
            return out.reshape(shape)
        xp = array_namespace(*args)
        batch = tuple(np.broadcast_shapes(*[x.shape[:-1] for x in args]))
        columns = [[x[..., i] for i in range(x.shape[-1])] for x in args]
        if xp is np:
            vals = code.vectorized[name](*columns)
            out = np.zeros(batch + (size,))
            if vals:
                stacked = np.stack([np.broadcast_to(v, batch) for v in vals], axis=-1)
                out[..., pos] = stacked if src is None else stacked[..., src]
            return out.reshape(batch + shape)
        vals = code.module.make(xp.cos, xp.sin)[name](*columns)  # any other namespace: stack, never assign
        full = [xp.zeros(batch, dtype=xp.float64)] * size
        for i, p_ in enumerate(pos.tolist()):
            value = vals[i if src is None else int(src[i])]
            full[p_] = xp.broadcast_to(xp.asarray(value, dtype=xp.float64), batch)
        return xp.reshape(xp.stack(full, axis=-1), batch + shape)

    def _inertial(self, phi: Array) -> Array:
        return phi[..., : 10 * self.n]

    def _columns(self, base: Array, diagonals: dict[str, Array]) -> Array:
        """The rigid-body columns followed by one diagonal block per extra group: diag(given vector), zero where a group
        plays no part."""
        xp = array_namespace(base)
        eye, zero = xp.eye(self.n), 0.0 * base[..., : self.n]
        blocks = []
        for e in self.extras:
            x = diagonals.get(e)
            blocks.append(zero if x is None else x[..., :, None] * eye + zero)
        return xp.concatenate([base] + blocks, axis=-1)

    # -- the model ------------------------------------------------------------------------------------------------------

    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        """Y(q, q̇, v, a), shape `(..., n, p)`: Y φ = M a + V_m(q, q̇) v + G + F(q̇) (P3)."""
        Y = self._eval("regressor", (self.n, 10 * self.n), q, dq, v, a)
        return Y if not self.extras else self._columns(Y, {"rotor_inertia": a, **self.friction_columns(dq)})

    def momentum_regressor(self, q: Array, dq: Array) -> Array:
        """Y_h(q, q̇) with Y_h φ = M(q) q̇ (6.6.3)."""
        Y = self._eval("momentum", (self.n, 10 * self.n), q, dq)
        return Y if not self.extras else self._columns(Y, {"rotor_inertia": dq})

    def remainder_regressor(self, q: Array, dq: Array) -> Array:
        """Y_g(q, q̇) with Y_g φ = −V_mᵀ q̇ + G + F (6.6.4), exact."""
        Y = self._eval("remainder", (self.n, 10 * self.n), q, dq)
        return Y if not self.extras else self._columns(Y, self.friction_columns(dq))

    def mass_matrix(self, q: Array, phi: Array) -> Array:
        M = self._eval("mass", (self.n, self.n), q, self._inertial(phi))
        if self.rotor_inertia is None:
            return M
        xp = array_namespace(q, phi)
        return M + self._extra(phi, "rotor_inertia")[..., :, None] * xp.eye(self.n)

    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        return self._eval("coriolis", (self.n, self.n), q, dq, self._inertial(phi))

    def gravity(self, q: Array, phi: Array) -> Array:
        return self._eval("gravity", (self.n,), q, self._inertial(phi))

    # -- task space: through the same arm as a kinematic tree ----------------------------------------------------------

    @derived
    def kinematic_tree(self) -> KinematicTree:
        """The same arm as a :class:`KinematicTree` (:meth:`KinematicTree.from_symbolic`), which gives the hand frame:
        built once on the host and carried as part of the arm's tree, so a compiled program takes it too."""
        return KinematicTree.from_symbolic(self)

    @property
    def task_axes(self) -> tuple[int, ...]:
        return self.kinematic_tree.task_axes

    def hand(self, q: Array, dq: Array, tool: Array | None = None) -> Hand:
        """The last DH frame, offset by `tool` in it (:meth:`KinematicTree.hand`)."""
        return self.kinematic_tree.hand(q, dq, tool)

    def kinematic_names(self, tool: Array | None = None) -> tuple[str, ...]:
        """:meth:`KinematicTree.kinematic_names` ("jointi.link.x" = a_i, "jointi.link.z" = d_i, standard DH)."""
        return self.kinematic_tree.kinematic_names(tool)

    def kinematic_values(self, tool: Array | None = None) -> Array:
        return self.kinematic_tree.kinematic_values(tool)

    def _kinematic_columns(self, q: Array, dq: Array, tool: Array | None) -> tuple[Hand, Array, Array, Array]:
        return self.kinematic_tree._kinematic_columns(q, dq, tool)

    # -- Pinocchio ----------------------------------------------------------------------------------------------------

    def pinocchio_model(self) -> Any:
        """The same arm as a `pinocchio.Model` (joints RZ/PZ placed per the DH table, each link's inertia in its DH
        frame, the same gravity; rotor inertia as `armature`; friction is not represented): for cross-checks and
        Pinocchio's algorithms. Needs the `[urdf]` extra."""
        import pinocchio as pin

        model = pin.Model()
        model.gravity = pin.Motion(np.concatenate([self.g, np.zeros(3)]))
        parent, previous_post = 0, np.eye(4)
        for i, ((pre, post), kind) in enumerate(zip(joint_placements(self.geometry), self.joints, strict=True)):
            X = previous_post @ pre
            joint = pin.JointModelRZ() if kind == "R" else pin.JointModelPZ()
            parent = model.addJoint(parent, joint, pin.SE3(X[:3, :3], X[:3, 3]), f"joint{i + 1}")
            body = pin.Inertia(float(self.mass[i]), self.com[i], self.inertia[i])
            model.appendBodyToJoint(parent, body, pin.SE3(post[:3, :3], post[:3, 3]))
            previous_post = post
        if self.rotor_inertia is not None:
            model.armature = self.rotor_inertia.copy()
        return model


def _table(value: Any, shape: tuple[int, ...], field_: str) -> Array:
    arr = as_array(value, field_)
    if arr.shape != shape:
        raise ConfigError(field_, f"expected shape {shape}, got {arr.shape}")
    return arr


# ---------------------------------------------------------------------------------------------------------------------
# Constructors (the scenario kinds "dh", "planar", "puma560")

_COLUMNS = ("joint", "a", "alpha", "d", "theta", "m", "com", "inertia")


def _inertia(value: Any, field_: str) -> Array:
    """3 principal moments (a diagonal tensor) or a 3×3 tensor."""
    arr = as_array(value, field_)
    if arr.shape == (3,):
        arr = np.diag(arr)
    if arr.shape != (3, 3):
        raise ConfigError(field_, f"expected 3 principal moments or a 3x3 tensor, got shape {arr.shape}")
    check_spd(arr, field_, semidefinite=True)
    return arr


def from_dh_table(links: Sequence[dict[str, Any]], convention: str = "standard", g: Any = (0.0, 0.0, -9.81),
                  smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> SymbolicArm:
    """An arm from a list of links (a TOML array of tables), one per joint, each with the keys

    `joint` ("R" or "P", default "R"), `a`, `alpha`, `d`, `theta` (DH numbers, default 0), `m` (kg), `com` (centre of
    mass in the link's DH frame, m, default 0), `inertia` (about the centre of mass, 3 principal moments or a 3×3 tensor,
    kg m², default 0), and optionally `rotor_inertia`, `viscous`, `coulomb`, `smooth_coulomb`, `offset` (a column group
    is added when any link gives its key; links that do not give it get 0; only an offset may be negative) and
    `q_limits` ([lower, upper], on every link or none). `smooth_coulomb_velocity` is v_s of tanh(q̇/v_s) (rad/s or m/s,
    one or one per joint).
    """
    if isinstance(links, dict) or not isinstance(links, Sequence) or isinstance(links, str) or not links:
        raise ConfigError("robot.links", "expected a list of link tables ([[robot.links]] in TOML), one per joint")
    columns: dict[str, list[Any]] = {k: [] for k in _COLUMNS}
    for i, link in enumerate(links):
        where = f"robot.links[{i}]"
        if not isinstance(link, dict):
            raise ConfigError(where, f"expected a table with keys {', '.join(LINK_KEYS)}, got {link!r}")
        check_names(list(link), LINK_KEYS, where)
        joint = link.get("joint", "R")
        if joint not in ("R", "P"):
            raise ConfigError(f"{where}.joint", f"expected 'R' (revolute) or 'P' (prismatic), got {joint!r}")
        columns["joint"].append(joint)
        for key in ("a", "alpha", "d", "theta", "m"):
            if key == "m" and key not in link:
                raise ConfigError(f"{where}.m", "missing: the link's mass in kg")
            columns[key].append(as_scalar(link.get(key, 0.0), f"{where}.{key}", nonnegative=key == "m"))
        columns["com"].append(as_vector(link.get("com", 0.0), 3, f"{where}.com"))
        columns["inertia"].append(_inertia(link.get("inertia", np.zeros(3)), f"{where}.inertia"))
    optional: dict[str, Any] = {}
    for key in EXTRAS:
        if any(key in link for link in links):
            optional[key] = [as_scalar(link.get(key, 0.0), f"robot.links[{i}].{key}", nonnegative=key not in SIGNED)
                             for i, link in enumerate(links)]
    given = sum("q_limits" in link for link in links)
    if given:
        if given != len(links):
            raise ConfigError("robot.links", "q_limits must be given on every link or on none")
        optional["q_limits"] = [as_vector(link["q_limits"], 2, f"robot.links[{i}].q_limits", broadcast=False)
                                for i, link in enumerate(links)]
    return SymbolicArm("".join(columns["joint"]), columns["a"], columns["alpha"], columns["d"], columns["theta"],
                       columns["m"], np.array(columns["com"]), np.array(columns["inertia"]), convention, g, **optional,
                       smooth_coulomb_velocity=smooth_coulomb_velocity)


def planar_arm(n_links: int, lengths: Any = 1.0, masses: Any = 1.0, rods: bool = False, g: float = 9.8,
               rotor_inertia: Any = None, viscous: Any = None, coulomb: Any = None, smooth_coulomb: Any = None,
               offset: Any = None, smooth_coulomb_velocity: Any = SMOOTH_VELOCITY, *,
               derive: bool = True) -> SymbolicArm:
    """An n-link planar arm of revolute joints about parallel vertical-plane axes, angles from the horizontal, gravity
    along −y (the book's two-link arm is `planar_arm(2)` with φ = [m1, 0, …, m2, 0, …]).

    `rods=False`: point masses at the distal link ends (massless links, as in the book's Example 3.2.2); `rods=True`:
    uniform slender rods (centre of mass at mid-length, I = m l²/12 about it). Standard DH: a_i = l_i, α = d = θ = 0, so
    only m, m c_x, m c_y and I_zz of each link enter the dynamics; the other regressor columns are zero. The optional
    groups (`rotor_inertia`, `viscous`, `coulomb`, `smooth_coulomb`, `offset`: one value or one per joint) add their
    columns when given, v_s = `smooth_coulomb_velocity`.
    """
    if isinstance(n_links, bool) or not isinstance(n_links, int | np.integer) or not 1 <= n_links <= 64:
        raise ConfigError("robot.n_links", f"expected a whole number of links from 1 to 64, got {n_links!r}")
    n = int(n_links)
    check_switch(rods, "robot.rods")
    length = as_vector(lengths, n, "robot.lengths", positive=True)
    mass = as_vector(masses, n, "robot.masses")
    if np.any(mass <= 0):
        raise ConfigError("robot.masses", f"every mass must be positive, got {mass}")
    g = as_scalar(g, "robot.g", nonnegative=True, maximum=1e3)
    com = np.zeros((n, 3))
    inertia = np.zeros((n, 3, 3))
    if rods:
        com[:, 0] = -length / 2  # the DH frame of link i sits at its distal end, x along the link
        inertia[:, 1, 1] = inertia[:, 2, 2] = mass * length**2 / 12
    zeros = np.zeros(n)
    return SymbolicArm("R" * n, length, zeros, zeros, zeros, mass, com, inertia, "standard", (0.0, -g, 0.0),
                       rotor_inertia, viscous, coulomb, smooth_coulomb=smooth_coulomb, offset=offset,
                       smooth_coulomb_velocity=smooth_coulomb_velocity, derive=derive)


# The PUMA 560 in standard DH, SI units, as in P. Corke's Robotics Toolbox (`Puma560`), whose values come from
#   B. Armstrong, O. Khatib, J. Burdick, "The explicit dynamic model and inertial parameters of the PUMA 560 arm",
#   Proc. IEEE ICRA 1986, pp. 510–518 (masses, centres of mass, inertias, rotor inertias, friction), and
#   P. Corke, B. Armstrong-Hélouvry, "A search for consensus among model parameters reported for the PUMA 560 robot",
#   Proc. IEEE ICRA 1994, pp. 1608–1613 (kinematics, d3 = 0.15005 m, the corrected centres of mass of links 2 and 3);
#   joint limits from Wang & Chen, IEEE Trans. Robotics and Automation 7(4), 1991.
# m1 is 0: Armstrong et al. give no mass for link 1, which only rotates about the vertical axis 1 (I_yy1 is about it).
# Per joint: a, alpha, d (m, rad), mass (kg), centre of mass (m), principal inertias about it (kg m²), motor inertia
# J_m (kg m²), gear ratio G, motor viscous friction B (N m s/rad) and Coulomb friction [T_c+, T_c−] (N m), limits (deg).
_PUMA = (
    (0.0, math.pi / 2, 0.672, 0.0, (0.0, 0.0, 0.0), (0.0, 0.35, 0.0), 200e-6, -62.6111, 1.48e-3, (0.395, -0.435),
     (-160, 160)),
    (0.4318, 0.0, 0.0, 17.4, (-0.3638, 0.006, 0.2275), (0.13, 0.524, 0.539), 200e-6, 107.815, 0.817e-3, (0.126, -0.071),
     (-45, 225)),
    (0.0203, -math.pi / 2, 0.15005, 4.8, (-0.0203, -0.0141, 0.070), (0.066, 0.086, 0.0125), 200e-6, -53.7063, 1.38e-3,
     (0.132, -0.105), (-225, 45)),
    (0.0, math.pi / 2, 0.4318, 0.82, (0.0, 0.019, 0.0), (1.8e-3, 1.3e-3, 1.8e-3), 33e-6, 76.0364, 71.2e-6,
     (11.2e-3, -16.9e-3), (-110, 170)),
    (0.0, -math.pi / 2, 0.0, 0.34, (0.0, 0.0, 0.0), (0.3e-3, 0.4e-3, 0.3e-3), 33e-6, 71.923, 82.6e-6, (9.26e-3, -14.5e-3),
     (-100, 100)),
    (0.0, 0.0, 0.0, 0.09, (0.0, 0.0, 0.032), (0.15e-3, 0.15e-3, 0.04e-3), 33e-6, 76.686, 36.7e-6, (3.96e-3, -10.5e-3),
     (-266, 266)),
)


def puma560(rotor_inertia: bool = False, viscous: bool = False, coulomb: bool = False, smooth_coulomb: bool = False,
            offset: bool = False, smooth_coulomb_velocity: Any = SMOOTH_VELOCITY, *, derive: bool = True) -> SymbolicArm:
    """The Unimation PUMA 560 (standard DH; sources in the comment above `_PUMA`), gravity 9.81 m/s² along −z.

    φ: the 60 standard parameters of the six links, then with `rotor_inertia` the reflected motor inertias J_m G²
    (which dominate the arm's inertia at joints 1–3), with `viscous` the link-side viscous friction B G², with `coulomb`
    the link-side Coulomb friction |G| (T_c+ − T_c−)/2 (the mean of the two directions), with `offset` the rest of the
    asymmetric Coulomb friction, |G| (T_c+ + T_c−)/2 (T_c± for q̇ ≷ 0, as f_c takes them: f_c sgn q̇ + τ_off is |G| T_c±
    at every nonzero speed, and τ_off also at rest), with `smooth_coulomb` zero columns (no published value; v_s =
    `smooth_coulomb_velocity`). `default_phi` holds the published values; `q_limits` the joint ranges.
    """
    for name, value in (("rotor_inertia", rotor_inertia), ("viscous", viscous), ("coulomb", coulomb),
                        ("smooth_coulomb", smooth_coulomb), ("offset", offset)):
        check_switch(value, f"robot.{name}")
    columns = [np.array(column, dtype=float) for column in zip(*_PUMA, strict=True)]
    a, alpha, d, m, com, moments, Jm, G, B, Tc, limits = columns
    return SymbolicArm("RRRRRR", a, alpha, d, np.zeros(6), m, com, np.array([np.diag(x) for x in moments]),
                       "standard", (0.0, 0.0, -9.81), Jm * G**2 if rotor_inertia else None,
                       B * G**2 if viscous else None, np.abs(G) * (Tc[:, 0] - Tc[:, 1]) / 2 if coulomb else None,
                       np.radians(limits), np.zeros(6) if smooth_coulomb else None,
                       np.abs(G) * (Tc[:, 0] + Tc[:, 1]) / 2 if offset else None, smooth_coulomb_velocity,
                       derive=derive)
