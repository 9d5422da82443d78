"""Any URDF arm through Pinocchio (extra `[urdf]`; DESIGN "n-DOF robots through Pinocchio").

φ holds 10 standard parameters per link, Pinocchio's order [m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]
(c the centre of mass and I the inertia about the joint frame's origin, both in that frame; links after a locked joint
are merged into their parent), then optional friction per joint: F(q̇) = f_v ∘ q̇ (`viscous`) + f_c ∘ sgn(q̇) (`coulomb`)
+ f_s ∘ tanh(q̇/v_s) (`smooth_coulomb`, v_s = `smooth_coulomb_velocity`) + τ_off (`offset`), in this order, named
fv, fc, fs, off (:class:`robotadapt.robots.dh.SerialChain` has the same groups). Pinocchio's algorithms hold the
rigid-body part only; the friction columns are added here.

Every term is computed from the kinematics and φ, never from the inertias stored in the URDF, so each is exactly linear
in φ for any φ, including the zero or non-physical estimates a controller holds (Pinocchio's own `Inertia` cannot hold a
zero mass):

    Y(q, q̇, v, a) = ⁴⁄₃ Y_p(q, ½q̇ + ⅜v, ¾a) − ⅓ Y_p(q, q̇ − ¾v, 0)    the mixed regressor (P3), two calls
    M(q) = Σ_k J_kᵀ I_k(φ_k) J_k                                        J_k the link's Jacobian in its own frame
    V_m(q, q̇) e_j = ¼ [Y_p(q, q̇ + e_j, 0) − Y_p(q, q̇ − e_j, 0)] φ       Christoffel form, column by column
    G(q) = Y_p(q, 0, 0) φ

where Y_p(q, w, a) φ = M a + B(w, w) + G is Pinocchio's `computeJointTorqueRegressor` and B(x, y) = V_m(q, x) y is
symmetric in x, y. The two-call form follows from ⁴⁄₃ B(½q̇ + ⅜v) − ⅓ B(q̇ − ¾v) = B(q̇, v), ⁴⁄₃ · ¾ = 1 and
⁴⁄₃ − ⅓ = 1 (G once); the polarization form of DESIGN takes three calls. M = Σ J_kᵀ I_k J_k is what `crba` evaluates
recursively (Featherstone, *Rigid Body Dynamics Algorithms*, 2008, ch. 6).

Pinocchio takes one state at a time: leading batch axes are looped over, and outputs keep the batch contract. An
instance holds Pinocchio workspaces (`Data`, and for :meth:`PinocchioArm.forward_dynamics` a model copy per φ): share it
between processes, not between threads.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from os import PathLike
from pathlib import Path
from typing import Any, ClassVar
from xml.etree import ElementTree

import numpy as np

from ..validation import ConfigError, as_vector, check_switch
from .base import Array, RobotModel
from .dh import SMOOTH_VELOCITY
from .hand import Hand

_INERTIAL = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")

# name → (URDF under example-robot-data's robots/ folder, joints locked: grippers)
EXAMPLES: dict[str, tuple[str, tuple[str, ...]]] = {
    "panda": ("panda_description/urdf/panda.urdf", ("panda_finger_joint1", "panda_finger_joint2")),
    "ur3": ("ur_description/urdf/ur3_robot.urdf", ()),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", ()),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", ()),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", ()),
    "z1": ("z1_description/urdf/z1.urdf", ("jointGripper",)),
    "kinova": ("kinova_description/robots/kinova.urdf", ()),
    "so101": ("so_arm_description/urdf/so101.urdf", ("gripper",)),
    "talos_left_arm": ("talos_data/robots/talos_left_arm.urdf", ("gripper_left_joint",)),
    "double_pendulum": ("double_pendulum_description/urdf/double_pendulum.urdf", ()),
}


def _pin() -> Any:
    try:
        import pinocchio
    except ImportError:
        raise ConfigError("robot.kind", "URDF robots need Pinocchio: pip install 'robotadapt[urdf]'") from None
    return pinocchio


def example_urdf(name: Any) -> tuple[Path, tuple[str, ...]]:
    """The URDF file of the example-robot-data arm `name` (`EXAMPLES`, installed offline) and its gripper joints."""
    if not isinstance(name, str) or name not in EXAMPLES:
        raise ConfigError("robot.name", f"unknown example robot {name!r}; known: {', '.join(EXAMPLES)}")
    import importlib.metadata  # here: 20 ms of every start otherwise

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise ConfigError("robot.kind", "example robots need example-robot-data: pip install 'robotadapt[urdf]'"
                          ) from None
    relative, gripper = EXAMPLES[name]
    return Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))) / relative, tuple(gripper)


def urdf_model(path: Any, locked: Any, gravity: Any, path_field: str, locked_field: str) -> Any:
    """Pinocchio's model of the URDF file `path`, the joints named in `locked` fixed at their neutral position, and
    `gravity` (3 numbers, base axes; None: Pinocchio's (0, 0, −9.81)); bad input is a ConfigError naming `path_field`
    or `locked_field` (the scenario keys of the model that reads it)."""
    pin = _pin()
    if not isinstance(path, str | PathLike):
        raise ConfigError(path_field, f"expected the path of a URDF file, got {path!r}")
    path = Path(path)
    if not path.is_file():
        raise ConfigError(path_field, f"no file at {str(path)!r}: give the path of an existing .urdf file")
    try:  # checked first: urdfdom writes its own parse errors straight to stderr
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError as exc:
        raise ConfigError(path_field, f"{str(path)!r} is not an XML file ({exc}): give a URDF file") from None
    if root.tag != "robot":
        raise ConfigError(path_field, f"{str(path)!r} is not a URDF (root <{root.tag}>, not <robot>)")
    try:
        model = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(path_field, f"Pinocchio cannot read {str(path)!r}: {exc}") from None
    if isinstance(locked, str) or not isinstance(locked, list | tuple) or not all(isinstance(j, str) for j in locked):
        raise ConfigError(locked_field, f"expected a list of joint names, got {locked!r}")
    if locked:
        names = list(model.names)
        missing = [j for j in locked if j not in names[1:]]
        if missing:
            raise ConfigError(locked_field, f"no joint named {', '.join(map(repr, missing))} in {path.name}; its "
                              f"joints: {', '.join(names[1:])}")
        model = pin.buildReducedModel(model, [names.index(j) for j in locked], pin.neutral(model))
    if gravity is not None:
        model.gravity = pin.Motion(as_vector(gravity, 3, "robot.gravity", broadcast=False), np.zeros(3))
    return model


def _unit_inertias() -> Array:
    """T of shape (10, 6, 6) with I_k = Σ_p φ_k,p T_p the spatial inertia [[m 1, −[h]×], [[h]×, I]] (h = m c) in
    Pinocchio's [linear; angular] order."""
    T = np.zeros((10, 6, 6))
    T[0, :3, :3] = np.eye(3)
    for p, h in enumerate(np.eye(3)):
        cross = np.cross(np.eye(3), h)  # [h]×, the matrix of x ↦ h × x
        T[1 + p, 3:, :3], T[1 + p, :3, 3:] = cross, -cross
    for p, (i, j) in enumerate([(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)]):
        T[4 + p, 3 + i, 3 + j] = T[4 + p, 3 + j, 3 + i] = 1.0
    return T


_T = _unit_inertias().reshape(10, 36)
_FRICTION = {"viscous": "fv", "coulomb": "fc", "smooth_coulomb": "fs", "offset": "off"}  # group → name prefix, in order


@dataclass(frozen=True, eq=False)
class PinocchioArm(RobotModel):
    """An arm from a `pinocchio.Model` of revolute, continuous and prismatic joints (lock any others, e.g. fingers).

    Build one with :meth:`from_urdf` or :meth:`example`. The model is never modified; a `pinocchio.Data` workspace is
    created once per instance. Joint angles of continuous joints are plain angles here (Pinocchio's (cos, sin) inside).
    """

    traceable: ClassVar[bool] = False  # Pinocchio's C++ takes concrete arrays: the numpy engine only
    pin_model: Any
    viscous: bool = False
    coulomb: bool = False
    name: str = "urdf"
    smooth_coulomb: bool = False
    offset: bool = False
    smooth_coulomb_velocity: Any = SMOOTH_VELOCITY

    def __post_init__(self) -> None:
        for key in _FRICTION:
            check_switch(getattr(self, key), f"robot.{key}")
        model = self.pin_model
        if model.nv == 0:
            raise ConfigError("robot.path", "the model has no moving joint")
        bad = [f"{model.names[j]} ({model.joints[j].shortname()})" for j in range(1, model.njoints)
               if model.joints[j].nv != 1]
        if bad:
            raise ConfigError("robot.locked_joints", f"only 1-DOF joints are supported; lock {', '.join(bad)}")
        object.__setattr__(self, "smooth_coulomb_velocity", as_vector(
            self.smooth_coulomb_velocity, model.nv, "robot.smooth_coulomb_velocity", positive=True))

    # construction ----------------------------------------------------------------------------------------------------
    @classmethod
    def from_urdf(cls, path: str | Path, locked_joints: Any = (), viscous: bool = False, coulomb: bool = False,
                  gravity: Any = None, smooth_coulomb: bool = False, offset: bool = False,
                  smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> PinocchioArm:
        """The arm of the URDF file `path`, with `locked_joints` (names) fixed at their neutral position, optional
        friction columns, and `gravity` (m/s², 3 numbers in the base frame; default Pinocchio's (0, 0, −9.81))."""
        model = urdf_model(path, locked_joints, gravity, "robot.path", "robot.locked_joints")
        return cls(model, viscous, coulomb, Path(path).stem, smooth_coulomb, offset, smooth_coulomb_velocity)

    @classmethod
    def example(cls, name: str, locked_joints: Any = (), viscous: bool = False, coulomb: bool = False,
                gravity: Any = None, smooth_coulomb: bool = False, offset: bool = False,
                smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> PinocchioArm:
        """An arm shipped by `example-robot-data` (offline), see `EXAMPLES`; its gripper joints are locked, and
        `locked_joints` lists further joints to lock."""
        path, gripper = example_urdf(name)
        if not isinstance(locked_joints, list | tuple):
            raise ConfigError("robot.locked_joints", f"expected a list of joint names, got {locked_joints!r}")
        arm = cls.from_urdf(path, gripper + tuple(locked_joints), viscous, coulomb, gravity, smooth_coulomb, offset,
                            smooth_coulomb_velocity)
        return replace(arm, name=name)

    # the RobotModel contract -----------------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return int(self.pin_model.nv)

    @cached_property
    def param_names(self) -> tuple[str, ...]:
        n = range(1, self.n + 1)
        names = [f"{s}{i}" for i in n for s in _INERTIAL]
        return tuple(names + [f"{prefix}{i}" for key, prefix in _FRICTION.items() if getattr(self, key) for i in n])

    @property
    def default_phi(self) -> Array:
        """The URDF's own parameters: its inertias, then its `<dynamics damping friction>` values when enabled (zero
        smooth Coulomb and offset: a URDF has no such numbers)."""
        model = self.pin_model
        parts = [model.inertias[j].toDynamicParameters() for j in range(1, model.njoints)]
        values = {"viscous": model.damping, "coulomb": model.friction, "smooth_coulomb": np.zeros(self.n),
                  "offset": np.zeros(self.n)}
        parts += [np.asarray(values[key], dtype=float) for key in _FRICTION if getattr(self, key)]
        return np.concatenate(parts)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.pin_model.names[1:])

    @property
    def position_limits(self) -> tuple[Array, Array]:
        """(lower, upper) joint limits from the URDF (rad or m), continuous joints ±inf."""
        model, lower, upper = self.pin_model, np.full(self.n, -np.inf), np.full(self.n, np.inf)
        for j in range(1, model.njoints):
            if model.joints[j].nq == 1:
                lower[model.idx_vs[j]] = model.lowerPositionLimit[model.idx_qs[j]]
                upper[model.idx_vs[j]] = model.upperPositionLimit[model.idx_qs[j]]
        return lower, upper

    def mass_matrix(self, q: Array, phi: Array) -> Array:
        """M(q) = Σ_k J_kᵀ I_k(φ_k) J_k, symmetrised (P1)."""
        J = self._each(self._jacobians, (self.n, 6, self.n), q)
        IJ = self._spatial_inertias(phi) @ J
        M = np.einsum("...kai,...kaj->...ij", J, IJ)
        return 0.5 * (M + np.swapaxes(M, -1, -2))

    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        """V_m(q, q̇), Christoffel form (P2): column j = ¼ [Y_p(q, q̇ + e_j, 0) − Y_p(q, q̇ − e_j, 0)] φ."""
        C = self._each(self._coriolis_columns, (self.n, self.n, 10 * self.n), q, dq)
        return np.einsum("...ijp,...p->...ij", C, self._rigid(phi))

    def gravity(self, q: Array, phi: Array) -> Array:
        """G(q) = Y_p(q, 0, 0) φ."""
        Y = self._each(lambda q1: self._torque_regressor(q1, self._zero, self._zero), (self.n, 10 * self.n), q)
        return (Y @ self._rigid(phi)[..., None])[..., 0]

    def friction(self, dq: Array, phi: Array) -> Array:
        """F(q̇) = f_v ∘ q̇ + f_c ∘ sgn(q̇) + f_s ∘ tanh(q̇/v_s) + τ_off (whichever columns the model has)."""
        Yf = self._friction_columns(np.asarray(dq, dtype=float))
        return (Yf @ np.asarray(phi, dtype=float)[..., 10 * self.n :, None])[..., 0]

    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        """Y(q, q̇, v, a), `Y φ = M a + V_m(q, q̇) v + G + F(q̇)` (P3), from two calls of Pinocchio's regressor."""
        Y = self._each(self._mixed, (self.n, 10 * self.n), q, dq, v, a)
        return self._with_friction(Y, dq)

    def forward_dynamics(self, q: Array, dq: Array, tau: Array, phi: Array) -> Array:
        """q̈ = M⁻¹ (τ − V_m q̇ − G − F) by Pinocchio's ABA on a copy of the model holding φ's inertias (built once per
        φ), when φ is one vector with a positive mass on every link (a plant's); else the generic solve."""
        phi = np.asarray(phi, dtype=float)
        if phi.ndim != 1 or not np.all(phi[: 10 * self.n : 10] > 0):
            return super().forward_dynamics(q, dq, tau, phi)
        pin, (model, data) = _pin(), self._holding(phi)

        def aba(q1: Array, dq1: Array, tau1: Array) -> Array:
            return pin.aba(model, data, self._configuration(q1), dq1, tau1).copy()

        return self._each(aba, (self.n,), q, dq, np.asarray(tau, dtype=float) - self.friction(dq, phi))

    def momentum_regressor(self, q: Array, dq: Array) -> Array:
        """Y_h(q, q̇), `Y_h φ = M q̇` (6.6.3): Y_p(q, 0, q̇) − Y_p(q, 0, 0), two calls; zero friction columns."""
        Y = self._each(self._momentum, (self.n, 10 * self.n), q, dq)
        return np.concatenate([Y, np.zeros(Y.shape[:-1] + (self.p - 10 * self.n,))], axis=-1)

    # task space: the hand alone (the kinematic basis is KinematicTree.from_pinocchio(arm.pin_model)'s) ------------------
    @property
    def task_axes(self) -> tuple[int, ...]:
        """(0, 1, 2): the hand's position in space."""
        return (0, 1, 2)

    def hand(self, q: Array, dq: Array, tool: Array | None = None) -> Hand:
        """The last joint's frame offset by `tool` (:meth:`TaskKinematics.hand`), by Pinocchio's frame algorithms
        (`computeJointJacobiansTimeVariation`, `updateFramePlacements`, `getFrameJacobian` and
        `getFrameJacobianTimeVariation`, LOCAL_WORLD_ALIGNED) on a copy of the model holding that frame."""
        pin, n = _pin(), self.n
        model, data, frame = self._tool_frame(np.zeros(3) if tool is None else np.asarray(tool, dtype=float))

        def one(q1: Array, dq1: Array) -> Array:
            config = self._configuration(q1)
            pin.computeJointJacobiansTimeVariation(model, data, config, dq1)
            pin.updateFramePlacements(model, data)
            X = data.oMf[frame]
            return np.concatenate([X.translation, X.rotation.ravel(),
                                   pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED).ravel(),
                                   pin.getFrameJacobianTimeVariation(model, data, frame, pin.LOCAL_WORLD_ALIGNED).ravel()])

        flat = self._each(one, (12 + 12 * n,), q, dq)
        lead = flat.shape[:-1]
        return Hand(flat[..., :3], flat[..., 3:12].reshape(lead + (3, 3)),
                    flat[..., 12 : 12 + 6 * n].reshape(lead + (6, n)), flat[..., 12 + 6 * n :].reshape(lead + (6, n)))


    def _tool_frame(self, tool: Array) -> tuple[Any, Any, int]:
        """(model, data, frame id) of a copy of the model with a frame at `tool` in the last joint's frame, cached per
        offset (a few: a law uses one)."""
        key = tool.tobytes()
        if key not in self._frames:
            pin, model = _pin(), self.pin_model.copy()
            placement = pin.SE3(np.eye(3), tool)
            frame = model.addFrame(pin.Frame("hand", model.njoints - 1, placement, pin.FrameType.OP_FRAME))
            if len(self._frames) >= 8:
                self._frames.clear()
            self._frames[key] = (model, model.createData(), frame)
        return self._frames[key]

    @cached_property
    def _frames(self) -> dict[bytes, tuple[Any, Any, int]]:
        return {}

    # per-state Pinocchio calls -----------------------------------------------------------------------------------------
    @cached_property
    def _data(self) -> Any:
        return self.pin_model.createData()

    @cached_property
    def _models(self) -> dict[bytes, tuple[Any, Any]]:
        return {}

    def _holding(self, phi: Array) -> tuple[Any, Any]:
        """(model, data) with the link inertias of φ, cached per φ (a few: a plant uses one)."""
        key = phi.tobytes()
        if key not in self._models:
            pin, model = _pin(), self.pin_model.copy()
            for j in range(1, model.njoints):
                model.inertias[j] = pin.Inertia.FromDynamicParameters(phi[10 * (j - 1) : 10 * j])
            if len(self._models) >= 8:
                self._models.clear()
            self._models[key] = (model, model.createData())
        return self._models[key]

    @cached_property
    def _zero(self) -> Array:
        return np.zeros(self.n)

    @cached_property
    def _unbounded(self) -> tuple[Array, Array, Array, Array] | None:
        """Index maps angle → configuration when continuous joints make nq > nv: (q plain, v plain, q of cos, v)."""
        model = self.pin_model
        if model.nq == model.nv:
            return None
        joints = range(1, model.njoints)
        plain = [j for j in joints if model.joints[j].nq == 1]
        wrapped = [j for j in joints if model.joints[j].nq == 2]
        return (np.array([model.idx_qs[j] for j in plain], dtype=int), np.array([model.idx_vs[j] for j in plain], dtype=int),
                np.array([model.idx_qs[j] for j in wrapped], dtype=int),
                np.array([model.idx_vs[j] for j in wrapped], dtype=int))

    def _configuration(self, q: Array) -> Array:
        maps = self._unbounded
        if maps is None:
            return q
        q_plain, v_plain, q_cos, v_wrapped = maps
        config = np.empty(self.pin_model.nq)
        config[q_plain] = q[v_plain]
        config[q_cos], config[q_cos + 1] = np.cos(q[v_wrapped]), np.sin(q[v_wrapped])
        return config

    def _torque_regressor(self, q: Array, w: Array, a: Array) -> Array:
        """Pinocchio's Y_p(q, w, a), a fresh array."""
        return _pin().computeJointTorqueRegressor(self.pin_model, self._data, self._configuration(q), w, a).copy()

    def _mixed(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        Y = (4.0 / 3.0) * self._torque_regressor(q, 0.5 * dq + 0.375 * v, 0.75 * a)
        Y -= (1.0 / 3.0) * self._torque_regressor(q, dq - 0.75 * v, self._zero)
        return Y

    def _momentum(self, q: Array, dq: Array) -> Array:
        return self._torque_regressor(q, self._zero, dq) - self._torque_regressor(q, self._zero, self._zero)

    def _coriolis_columns(self, q: Array, dq: Array) -> Array:
        columns = [self._torque_regressor(q, dq + e, self._zero) - self._torque_regressor(q, dq - e, self._zero)
                   for e in np.eye(self.n)]
        return 0.25 * np.stack(columns, axis=1)

    def _jacobians(self, q: Array) -> Array:
        pin, model, data = _pin(), self.pin_model, self._data
        pin.computeJointJacobians(model, data, self._configuration(q))
        return np.array([pin.getJointJacobian(model, data, j, pin.LOCAL) for j in range(1, model.njoints)])

    def _each(self, fn: Any, shape: tuple[int, ...], *arrays: Array) -> Array:
        """out[i] = fn(*(x[i] for x in arrays)) over the broadcast leading axes of the `(..., n)` inputs."""
        arrays = tuple(np.asarray(x, dtype=float) for x in arrays)
        if all(x.ndim == 1 for x in arrays):  # one state: the simulator's hot path
            return fn(*arrays)
        lead = np.broadcast_shapes(*(x.shape[:-1] for x in arrays))
        arrays = tuple(np.ascontiguousarray(np.broadcast_to(x, lead + x.shape[-1:])) for x in arrays)
        out = np.empty(lead + shape)
        for i in np.ndindex(lead):
            out[i] = fn(*(x[i] for x in arrays))
        return out

    # φ-dependent parts, vectorized ---------------------------------------------------------------------------------------
    def _rigid(self, phi: Array) -> Array:
        return np.asarray(phi, dtype=float)[..., : 10 * self.n]

    def _spatial_inertias(self, phi: Array) -> Array:
        """I_k(φ_k), shape `(..., n, 6, 6)`."""
        rigid = self._rigid(phi)
        return (rigid.reshape(rigid.shape[:-1] + (self.n, 10)) @ _T).reshape(rigid.shape[:-1] + (self.n, 6, 6))

    def _friction_columns(self, dq: Array) -> Array:
        """The friction block of Y, shape `(..., n, n·groups)`: diag(q̇), diag(sgn q̇), diag(tanh(q̇/v_s)), 𝟙 for the
        groups present."""
        eye = np.eye(self.n)
        columns = {"viscous": dq, "coulomb": np.sign(dq), "smooth_coulomb": np.tanh(dq / self.smooth_coulomb_velocity),
                   "offset": np.ones_like(dq)}
        blocks = [columns[key][..., None] * eye for key in _FRICTION if getattr(self, key)]
        return np.concatenate(blocks, axis=-1) if blocks else np.zeros(dq.shape + (0,))

    def _with_friction(self, Y: Array, dq: Array) -> Array:
        if self.p == 10 * self.n:
            return Y
        Yf = self._friction_columns(np.asarray(dq, dtype=float))
        return np.concatenate([Y, np.broadcast_to(Yf, Y.shape[:-1] + Yf.shape[-1:])], axis=-1)
