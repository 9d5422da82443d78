"""The true plant stepped by MuJoCo (`[plant] engine = "mujoco"`, extra `[mujoco]`): dynamics the project did not write.

The MuJoCo model is built from the description the controller uses:

- the book's arms through `mujoco.MjSpec`: point masses at the ends of massless links, the same lengths and gravity
  (two-link arm, Example 3.2.2), the polar arm's revolute and prismatic joints (Example 3.2.1), the one-link arm's
  inertia, viscous friction and spring. MuJoCo refuses a moving body without rotational inertia (mjMINVAL = 1e-15), so each
  point mass gets `POINT_INERTIA` about its centre; its cost is that much added to the diagonal of M
  (docs/realtime.md, "Cross-check");
- URDF arms from their URDF, read by MuJoCo's own parser (its kinematics, joint limits): locked joints made fixed and
  fused into their parent, visual meshes dropped (MuJoCo reads no COLLADA), collision meshes kept where MuJoCo can read
  them (STL, OBJ) for pictures only (no contacts). Each moving body's inertial is then set from the plant's φ (by
  default the URDF's own inertials, the same numbers);
- other kinematic trees (DH tables, planar chains) through `MjSpec` from the tree's joint placements and link frames,
  each link's inertial from φ (:func:`inertial`: MuJoCo takes only rigid bodies, A + B ≥ C).

MuJoCo's options are plant fields: `timestep` (s; default the simulation's plant step), `integrator` (MuJoCo's
"Euler", "RK4", "implicit", "implicitfast"; default "RK4", the project's own plant integrator, so that a difference
between the engines is the dynamics), per-joint `damping` (N·m·s/rad), `armature` (kg·m²) and `frictionloss` (N·m),
`joint_limits` (a URDF's), and `actuation`: torques through "motor" actuators (gear 1, unlimited) or written
into `qfrc_applied`. Where the truth model has the matching columns (rotor inertia Ia_i, viscous fv_i or b, Coulomb
fc_i) MuJoCo's option and φ's entry are one number: an option left out takes φ's value, and they may not differ.
A constant torque offset off_i (τ = … + off_i) is a bias force, −off_i added to `qfrc_applied` at every step; MuJoCo
has no smooth (tanh) Coulomb friction, so a truth with a nonzero fs_i is refused (`plant.phi`).

The plant is advanced by MuJoCo's own step (:meth:`MujocoPlant.advance`) at the control ticks of the sampled-data loop
(:mod:`robotadapt.sim.sampled`) with the torque held: a host-side engine, numpy backend only. Its `MjData` is a
workspace (state in, state out), like Pinocchio's `Data`: share a plant between processes, not threads.
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, ClassVar
from xml.etree import ElementTree

import numpy as np

from ..robots.base import RobotModel
from ..robots.kinematic_tree import KinematicTree
from ..robots.one_link import OneLinkArm
from ..robots.polar import PolarArm
from ..robots.two_link import TwoLinkArm
from ..validation import ConfigError, as_scalar, as_vector, check_switch
from .plant import Plant

Array = Any
INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")
ACTUATIONS = ("motor", "qfrc_applied")
OPTIONS = ("armature", "damping", "frictionloss")  # per-joint MuJoCo options that are also columns of a model
_COLUMN = {"Ia": "armature", "fv": "damping", "fc": "frictionloss"}  # φ's per-joint column prefix → option
POINT_INERTIA = 1e-12  # kg·m², the rotational inertia of a point mass in MuJoCo (docs/realtime.md: its cost)
MESH_FORMATS = (".stl", ".obj", ".msh")
INSTALL = "the MuJoCo plant needs the mujoco package: pip install 'robotadapt[mujoco]'"


def load_mujoco() -> Any:
    """The `mujoco` module, imported without an OpenGL backend: simulating draws nothing, and MuJoCo's import would
    otherwise load the one MUJOCO_GL names (PyOpenGL and libOSMesa for "osmesa"), failing on a machine without it.
    The renderer picks a backend when it is needed (:func:`robotadapt.report.video.gl_backend`), honouring a
    MUJOCO_GL the user set. A missing package is a ConfigError naming `plant.engine`."""
    first, user = "mujoco" not in sys.modules, os.environ.get("MUJOCO_GL")
    if first:
        os.environ["MUJOCO_GL"] = "disable"  # read once, by mujoco.rendering.classic.gl_context at import
    try:
        import mujoco
    except ImportError:
        raise ConfigError("plant.engine", INSTALL) from None
    finally:
        if first and user is not None:
            os.environ["MUJOCO_GL"] = user
        elif first:
            os.environ.pop("MUJOCO_GL", None)
    return mujoco


def option_columns(model: RobotModel) -> dict[str, np.ndarray]:
    """For each of `OPTIONS`, the index in φ of each joint's matching column (−1 where the model has none)."""
    out = {name: np.full(model.n, -1) for name in OPTIONS}
    for k, name in enumerate(model.param_names):
        match = re.fullmatch(r"(Ia|fv|fc)(\d+)", name)
        if match and int(match[2]) <= model.n:
            out[_COLUMN[match[1]]][int(match[2]) - 1] = k
        elif name == "b" and model.n == 1:  # the one-link arm's viscous friction
            out["damping"][0] = k
    return out


def with_options(model: RobotModel, phi: Array, options: dict[str, Any]) -> np.ndarray:
    """φ with the columns of the MuJoCo options given in `options` (armature, damping, frictionloss) set to them."""
    phi = np.array(phi, dtype=float)
    for name, index in option_columns(model).items():
        if options.get(name) is not None:
            value = as_vector(options[name], model.n, f"plant.{name}")
            phi[index[index >= 0]] = value[index >= 0]
    return phi


def inertial(phi_link: Array, frame: tuple[Array, Array] | None = None, root_axis: Array | None = None,
             link: int = 1) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(m, c, quaternion of the principal axes, principal moments λ) of one link's 10 standard parameters [m, m c,
    I about the link frame's origin (xx, xy, yy, xz, yz, zz)] in the body frame, where the link frame sits at
    `frame` = (R, p) (default: the body frame itself); I_c = I_o − m (|c|² 1 − c cᵀ) (parallel axes).

    MuJoCo wants a positive mass and principal moments with A + B ≥ C. A point mass's zero moments become
    `POINT_INERTIA`. A body turning about a fixed axis u (`root_axis`: its hinge hangs from the world) sees only
    uᵀ I_c u and m at c: where it fails, it gets the inertia (uᵀ I_c u) 1 and, massless, `POINT_INERTIA` kg at c, which
    its motion cannot tell apart (the PUMA 560's first link holds only its I_yy). Any other body that fails is a ConfigError
    naming `link` (the PUMA's published link 3 has A + B < C: no rigid body has that inertia)."""
    R0, p0 = (np.eye(3), np.zeros(3)) if frame is None else (np.asarray(frame[0]), np.asarray(frame[1]))
    m, h = float(phi_link[0]), np.asarray(phi_link[1:4], dtype=float)
    xx, xy, yy, xz, yz, zz = phi_link[4:10]
    c = h / m if m > 0 else np.zeros(3)
    I_c = R0 @ (np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) - m * (c @ c * np.eye(3) - np.outer(c, c))) @ R0.T
    lam, R = np.linalg.eigh(I_c)
    lam = np.where(np.abs(lam) <= 1e-14 * max(1.0, lam.max()), POINT_INERTIA, lam)
    if root_axis is not None and (m <= 0 or lam.min() <= 0 or lam[0] + lam[1] < lam[2]):
        u = np.asarray(root_axis, dtype=float)
        m, lam, R = m if m > 0 else POINT_INERTIA, np.full(3, max(u @ I_c @ u, POINT_INERTIA)), np.eye(3)
    if m <= 0 or lam.min() <= 0 or lam[0] + lam[1] < lam[2] * (1 - 1e-12):
        raise ConfigError("plant.phi", f"link {link}: MuJoCo needs a positive mass and principal moments with "
                          f"A + B ≥ C (a rigid body's); got m = {m:g}, moments {np.round(lam, 6).tolist()}: use "
                          "plant.engine = 'robotadapt'")
    quat = np.zeros(4)
    load_mujoco().mju_mat2Quat(quat, (R * np.sign(np.linalg.det(R))).reshape(-1))
    return m, p0 + R0 @ c, quat, lam


@dataclass(frozen=True, eq=False)
class MujocoPlant(Plant):
    """A :class:`~robotadapt.plant.plant.Plant` whose dynamics are MuJoCo's (module docstring): `model` and `phi` are
    the truth the MuJoCo model is built from (figures compare estimates with them), `urdf` the URDF file of a URDF arm
    (None: built by MjSpec) with `locked_joints` fixed, then MuJoCo's options. A torque limit and a sensor act
    at the ticks as for the project's own plant; elastic joints, motors and a payload attached during the run are not
    modelled here; a disturbance torque is held over each MuJoCo step (:meth:`advance`)."""

    stepped_on_host: ClassVar[bool] = True
    urdf: str | None = None
    locked_joints: tuple[str, ...] = ()
    timestep: float | None = None
    integrator: str = "RK4"
    actuation: str = "motor"
    damping: Any = None
    armature: Any = None
    frictionloss: Any = None
    joint_limits: bool = False
    _options: dict[str, np.ndarray] = field(init=False, repr=False, metadata={"internal": True})
    _offset: Any = field(init=False, repr=False, metadata={"internal": True})

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("elastic_joint", "motor"):
            if getattr(self, name) is not None:
                raise ConfigError(f"plant.{name}", "the MuJoCo plant does not model it: drop it, or use "
                                  "plant.engine = 'robotadapt'")
        if self.varies:
            raise ConfigError("plant.payload_time", "the MuJoCo plant holds one set of inertials: attach the payload "
                              "at t = 0, or use plant.engine = 'robotadapt'")
        if self.timestep is not None:
            object.__setattr__(self, "timestep", as_scalar(self.timestep, "plant.timestep", positive=True))
        for name, allowed in (("integrator", INTEGRATORS), ("actuation", ACTUATIONS)):
            if getattr(self, name) not in allowed:
                raise ConfigError(f"plant.{name}", f"expected one of {', '.join(allowed)} (MuJoCo's); got "
                                  f"{getattr(self, name)!r}")
        check_switch(self.joint_limits, "plant.joint_limits")
        if self.joint_limits and self.urdf is None:
            raise ConfigError("plant.joint_limits", "MuJoCo takes joint limits from a URDF; this arm has none: drop it")
        if not isinstance(self.model, TwoLinkArm | PolarArm | OneLinkArm | KinematicTree) and self.urdf is None:
            raise ConfigError("plant.engine", f"MuJoCo builds the book's arms, kinematic trees and URDF arms here, not a "
                              f"{type(self.model).__name__}: use plant.engine = 'robotadapt'")
        phi, options = self.phi_at(0.0), {}
        for name, index in option_columns(self.model).items():
            from_phi = np.where(index >= 0, phi[index], 0.0)
            value = from_phi if getattr(self, name) is None else as_vector(getattr(self, name), self.model.n,
                                                                           f"plant.{name}")
            if np.any(value < 0):
                raise ConfigError(f"plant.{name}", f"must be zero or positive, got {value.tolist()}")
            if not np.allclose(value[index >= 0], from_phi[index >= 0], rtol=1e-12, atol=0.0):
                raise ConfigError(f"plant.{name}", f"{value.tolist()} differs from plant.phi's matching entries "
                                  f"{from_phi[index >= 0].tolist()}: MuJoCo's option is the truth; drop one of them")
            options[name] = value
        object.__setattr__(self, "_options", options)
        object.__setattr__(self, "_offset", self._friction_terms(phi))
        self.engine  # noqa: B018 -- compile now: a model MuJoCo refuses is a scenario error, not a run's

    def _friction_terms(self, phi: np.ndarray) -> np.ndarray:
        """The truth's constant torque offsets off_i per joint (zero without the column); a ConfigError for a nonzero
        smooth Coulomb coefficient fs_i, which MuJoCo cannot represent."""
        offset, smooth = np.zeros(self.model.n), {}
        for k, name in enumerate(self.model.param_names):
            match = re.fullmatch(r"(off|fs)(\d+)", name)
            if match and 1 <= int(match[2]) <= self.model.n:
                if match[1] == "off":
                    offset[int(match[2]) - 1] = phi[k]
                elif phi[k] != 0.0:
                    smooth[name] = float(phi[k])
        if smooth:
            raise ConfigError("plant.phi", f"MuJoCo has no smooth (tanh) Coulomb friction, and the truth has "
                              f"{', '.join(f'{k} = {v:g}' for k, v in smooth.items())}: set them to 0 or use "
                              "plant.engine = 'robotadapt'")
        return offset

    # -- the MuJoCo model ---------------------------------------------------------------------------------------------

    @cached_property
    def engine(self) -> tuple[Any, Any, np.ndarray, np.ndarray]:
        """(MjModel, MjData, qpos addresses, dof addresses of the model's joints in its order)."""
        mj = load_mujoco()
        if self.urdf is not None:
            spec, names = self._urdf_spec(mj)
        elif isinstance(self.model, KinematicTree):
            spec, names = self._tree_spec(mj)
        else:
            spec, names = self._book_spec(mj)
        _stage(mj, spec, floor=not isinstance(self.model, TwoLinkArm | PolarArm | OneLinkArm))
        spec.option.timestep = self.timestep or 1e-3
        spec.option.integrator = getattr(mj.mjtIntegrator, f"mjINT_{self.integrator.upper()}")
        joints = {j.name: j for j in spec.joints}
        for i, name in enumerate(names):
            joint = joints[name]
            joint.armature, joint.frictionloss = float(self._options["armature"][i]), float(self._options["frictionloss"][i])
            joint.damping = _coefficient(joint.damping, self._options["damping"][i])
            joint.limited = mj.mjtLimited.mjLIMITED_TRUE if self.joint_limits else mj.mjtLimited.mjLIMITED_FALSE
            if self.actuation == "motor":
                spec.add_actuator(name=f"motor_{name}", target=name, trntype=mj.mjtTrn.mjTRN_JOINT)
        try:
            model = spec.compile()
        except ValueError as exc:
            where = "robot.path" if self.urdf is not None else "plant.phi"
            raise ConfigError(where, f"MuJoCo cannot compile the model: {str(exc).splitlines()[0]}") from None
        ids = [model.joint(name).id for name in names]
        data = mj.MjData(model)
        if self.urdf is not None:
            self._set_inertials(mj, model, data, [int(model.jnt_bodyid[j]) for j in ids])
        return model, data, model.jnt_qposadr[ids].copy(), model.jnt_dofadr[ids].copy()

    def _book_spec(self, mj: Any) -> tuple[Any, list[str]]:
        """The book's arm as an MjSpec: (spec, joint names in the model's order)."""
        spec, arm, phi = mj.MjSpec(), self.model, self.phi_at(0.0)
        hinge, slide = mj.mjtJoint.mjJNT_HINGE, mj.mjtJoint.mjJNT_SLIDE
        if isinstance(arm, TwoLinkArm):  # angles from the horizontal, gravity along −y, masses at the link ends
            gravity = [0.0, -arm.g, 0.0]
            links = [(hinge, [0.0, 0.0, 0.0], phi[0], [arm.l1, 0.0, 0.0]), (hinge, [arm.l1, 0.0, 0.0], phi[1],
                                                                             [arm.l2, 0.0, 0.0])]
        elif isinstance(arm, PolarArm):  # θ about z, then r along the rotated x axis carrying the mass
            gravity = [0.0, -arm.g, 0.0]
            links = [(hinge, [0.0, 0.0, 0.0], 0.0, [0.0, 0.0, 0.0]), (slide, [0.0, 0.0, 0.0], phi[0], [0.0, 0.0, 0.0])]
        else:  # one link: inertia m about its axis, no gravity
            gravity = [0.0, 0.0, 0.0]
            links = [(hinge, [0.0, 0.0, 0.0], phi[0], [0.0, 0.0, 0.0])]
        spec.option.gravity = gravity
        body, names = spec.worldbody, []
        for i, (kind, pos, mass, end) in enumerate(links):
            body = body.add_body(name=f"link{i + 1}", pos=pos)
            names.append(f"joint{i + 1}")
            axis = [1.0, 0.0, 0.0] if kind == slide else [0.0, 0.0, 1.0]
            joint = body.add_joint(name=names[-1], type=kind, axis=axis)
            if isinstance(arm, OneLinkArm) and arm.stiffness:  # the spring k q (φ's third entry): MuJoCo's stiffness
                joint.stiffness = _coefficient(joint.stiffness, phi[2])
            body.explicitinertial, body.mass, body.ipos = True, max(float(mass), POINT_INERTIA), end
            body.inertia = [float(mass)] * 3 if isinstance(arm, OneLinkArm) else [POINT_INERTIA] * 3
            if kind == hinge and any(end):
                body.add_geom(type=mj.mjtGeom.mjGEOM_CAPSULE, fromto=[0.0, 0.0, 0.0, *end], size=[0.04, 0.0, 0.0],
                              density=0.0, contype=0, conaffinity=0, rgba=[0.2, 0.4, 0.8, 1.0])
                body.add_geom(type=mj.mjtGeom.mjGEOM_SPHERE, pos=end, size=[0.08, 0.0, 0.0], density=0.0,
                              contype=0, conaffinity=0, rgba=[0.9, 0.4, 0.1, 1.0])
        if isinstance(arm, PolarArm):  # a rod along r and the mass at its end, for pictures
            body.add_geom(type=mj.mjtGeom.mjGEOM_CAPSULE, fromto=[-1.0, 0.0, 0.0, 0.0, 0.0, 0.0], size=[0.03, 0, 0],
                          density=0.0, contype=0, conaffinity=0, rgba=[0.2, 0.4, 0.8, 1.0])
            body.add_geom(type=mj.mjtGeom.mjGEOM_SPHERE, size=[0.08, 0.0, 0.0], density=0.0, contype=0,
                          conaffinity=0, rgba=[0.9, 0.4, 0.1, 1.0])
        return spec, names

    def _urdf_spec(self, mj: Any) -> tuple[Any, list[str]]:
        """The URDF arm as an MjSpec read by MuJoCo's parser: locked joints fixed, meshes MuJoCo cannot read dropped,
        the kept ones for pictures only; gravity the model's."""
        path = Path(str(self.urdf))
        root = ElementTree.parse(path).getroot()
        for joint in root.iter("joint"):
            if joint.get("name") in self.locked_joints:
                joint.set("type", "fixed")
        for link in root.iter("link"):
            for element in link.findall("visual"):
                link.remove(element)
            for element in link.findall("collision"):
                mesh = element.find("geometry/mesh")
                if mesh is not None:
                    resolved = _mesh_file(path, mesh.get("filename", ""))
                    if resolved is None:
                        link.remove(element)
                        continue
                    mesh.set("filename", str(resolved))
        ElementTree.SubElement(ElementTree.SubElement(root, "mujoco"), "compiler", fusestatic="true",
                               strippath="false", discardvisual="false")
        try:
            spec = mj.MjSpec.from_string(ElementTree.tostring(root, encoding="unicode"))
        except ValueError as exc:
            raise ConfigError("robot.path", f"MuJoCo cannot read {str(path)!r}: {str(exc).splitlines()[0]}") from None
        spec.option.gravity = [float(v) for v in self._gravity()]
        for geom in spec.geoms:
            geom.contype, geom.conaffinity, geom.rgba = 0, 0, [0.85, 0.85, 0.88, 1.0]
        names = list(getattr(self.model, "joint_names", ()))
        missing = [name for name in names if name not in {j.name for j in spec.joints}]
        if missing or len(names) != self.model.n:
            raise ConfigError("robot.path", f"MuJoCo's model of {path.name} lacks the joints {', '.join(missing)}")
        return spec, names

    def _gravity(self) -> np.ndarray:
        """The truth model's gravity vector (m/s², base axes)."""
        g = getattr(self.model, "g", None)
        if g is not None:
            return np.asarray(g, dtype=float)
        return np.asarray(self.model.pin_model.gravity.linear, dtype=float)  # type: ignore[attr-defined]

    def _set_inertials(self, mj: Any, model: Any, data: Any, bodies: list[int]) -> None:
        """Each moving body's mass, centre of mass and principal inertia from φ's 10 standard parameters (:func:`inertial`;
        the URDF's link frame is the body frame)."""
        phi = self.phi_at(0.0)
        for i, body in enumerate(bodies):
            joint = model.body_jntadr[body]
            root = model.body_parentid[body] == 0 and model.jnt_type[joint] == mj.mjtJoint.mjJNT_HINGE
            axis = model.jnt_axis[joint] if root else None
            mass, c, quat, lam = inertial(phi[10 * i : 10 * i + 10], root_axis=axis, link=i + 1)
            model.body_mass[body], model.body_ipos[body], model.body_iquat[body] = mass, c, quat
            model.body_inertia[body] = lam
        mj.mj_setConst(model, data)

    def _tree_spec(self, mj: Any) -> tuple[Any, list[str]]:
        """A kinematic tree (DH arms: the PUMA 560) as an MjSpec: body i's frame is joint i's frame, placed in its
        parent body by the parent's link frame L_parent and the joint placement P_i; the link frame L_i holds φ_i."""
        tree, phi, spec = self.model, self.phi_at(0.0), mj.MjSpec()
        spec.option.gravity = [float(v) for v in self._gravity()]
        names = [f"joint{i + 1}" for i in range(tree.n)]
        bodies: list[Any] = []
        for i, parent in enumerate(tree.parents):  # type: ignore[attr-defined]
            R, p = tree.rotation[i], tree.translation[i]  # type: ignore[attr-defined]
            if parent >= 0:
                LR, Lp = tree.link_rotation[parent], tree.link_translation[parent]  # type: ignore[attr-defined]
                R, p = LR @ R, LR @ p + Lp
            quat = np.zeros(4)
            mj.mju_mat2Quat(quat, np.ascontiguousarray(R).reshape(-1))
            body = (spec.worldbody if parent < 0 else bodies[parent]).add_body(name=f"link{i + 1}", pos=p, quat=quat)
            revolute = tree.joints[i] == "R"  # type: ignore[attr-defined]
            axis = tree.axis[i]  # type: ignore[attr-defined]
            body.add_joint(name=names[i], type=mj.mjtJoint.mjJNT_HINGE if revolute else mj.mjtJoint.mjJNT_SLIDE,
                           axis=axis)
            frame = (tree.link_rotation[i], tree.link_translation[i])  # type: ignore[attr-defined]
            mass, c, iquat, lam = inertial(phi[10 * i : 10 * i + 10], frame, axis if parent < 0 and revolute else None,
                                           i + 1)
            body.explicitinertial, body.mass, body.ipos, body.iquat, body.inertia = True, mass, c, iquat, lam
            if parent >= 0 and np.linalg.norm(p) > 1e-6:  # a rod from the parent's joint to this one, for pictures
                bodies[parent].add_geom(type=mj.mjtGeom.mjGEOM_CAPSULE, fromto=[0.0, 0.0, 0.0, *p], size=[0.04, 0, 0],
                                        density=0.0, contype=0, conaffinity=0, rgba=[0.85, 0.85, 0.88, 1.0])
            body.add_geom(type=mj.mjtGeom.mjGEOM_SPHERE, size=[0.06, 0.0, 0.0], density=0.0, contype=0, conaffinity=0,
                          rgba=[0.9, 0.4, 0.1, 1.0])
            bodies.append(body)
        return spec, names

    # -- stepping -----------------------------------------------------------------------------------------------------

    def qpos(self, q: Array) -> np.ndarray:
        """MuJoCo's qpos for the joint positions q (the model's order)."""
        model, _, qadr, _ = self.engine
        out = model.qpos0.copy()
        out[qadr] = q
        return out

    def advance(self, t: float, s: Array, u: Array, steps: int, dt: float, dynamics: Any = None) -> np.ndarray:
        """The state s = [q, q̇] at time t after `steps` MuJoCo steps of `dt` (s) with the torque u held (MuJoCo's
        dynamics, not `dynamics`); a disturbance T_d(t, q, q̇) is subtracted, evaluated at the start of each MuJoCo step
        and held over it, and the truth's torque offsets always."""
        mj = load_mujoco()
        model, data, qadr, vadr = self.engine
        n = self.model.n
        model.opt.timestep = dt
        data.qpos[qadr], data.qvel[vadr] = s[:n], s[n : 2 * n]
        motor = self.actuation == "motor"
        if motor:
            data.ctrl[:] = u
        applied = (0.0 if motor else u) - self._offset
        if self.disturbance is None:
            data.qfrc_applied[vadr] = applied
            mj.mj_step(model, data, nstep=steps)
        else:
            for i in range(steps):
                disturbance = self.disturbance(t + i * dt, data.qpos[qadr], data.qvel[vadr])
                data.qfrc_applied[vadr] = applied - disturbance
                mj.mj_step(model, data)
        return np.concatenate([data.qpos[qadr], data.qvel[vadr]])

    def acceleration(self, t: Array, q: Array, dq: Array, tau: Array) -> Array:
        """Refused: MuJoCo steps this plant (:meth:`advance`), one run at a time in the sampled-data loop; a path that
        integrates the plant's vector field itself (a batch, the compiled engine) would silently use the project's
        dynamics instead."""
        raise ConfigError("plant.engine", "a MuJoCo plant is stepped by MuJoCo, one run at a time: batches and "
                          "compiled runs integrate the project's dynamics (plant.engine = 'robotadapt')")

    def derivative(self, t: Array, s: Array, u: Array) -> Array:
        """Refused, as :meth:`acceleration`."""
        return self.acceleration(t, s, s, u)

    def describe(self) -> dict[str, Any]:
        """The project's plant's description and MuJoCo's: version, source, options."""
        options = {k: v.tolist() for k, v in self._options.items()}
        engine = {"engine": "mujoco", "version": load_mujoco().__version__, "source": self.urdf or "MjSpec",
                  "integrator": self.integrator, "actuation": self.actuation, "joint_limits": self.joint_limits,
                  **options}
        if np.any(self._offset != 0.0):
            engine["offset"] = self._offset.tolist()
        return {**super().describe(), "mujoco": engine}


def _coefficient(current: Any, value: float) -> Any:
    """A joint's damping or stiffness as its MuJoCo version holds it: a number, or (3.17) [linear, higher orders]."""
    return [float(value)] + [0.0] * (np.size(current) - 1) if np.ndim(current) else float(value)


def _stage(mj: Any, spec: Any, floor: bool) -> None:
    """What pictures need and the dynamics never see: a light sky, a brighter headlight and, under a 3-D arm, a
    checkered floor without contacts."""
    spec.add_texture(name="sky", type=mj.mjtTexture.mjTEXTURE_SKYBOX, builtin=mj.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[1.0, 1.0, 1.0], rgb2=[0.75, 0.8, 0.88], width=64, height=384)
    spec.visual.headlight.ambient, spec.visual.headlight.diffuse = [0.45] * 3, [0.6] * 3
    if floor:
        spec.add_texture(name="grid", type=mj.mjtTexture.mjTEXTURE_2D, builtin=mj.mjtBuiltin.mjBUILTIN_CHECKER,
                         rgb1=[1.0, 1.0, 1.0], rgb2=[0.88, 0.9, 0.93], width=64, height=64)
        material = spec.add_material(name="grid", texrepeat=[8.0, 8.0])
        material.textures[mj.mjtTextureRole.mjTEXROLE_RGB] = "grid"
        spec.worldbody.add_light(pos=[0.0, 0.0, 3.0], dir=[0.0, 0.0, -1.0], diffuse=[0.5] * 3)
        spec.worldbody.add_geom(type=mj.mjtGeom.mjGEOM_PLANE, size=[1.0, 1.0, 0.05], material="grid", contype=0,
                                conaffinity=0)


def _mesh_file(urdf: Path, filename: str) -> Path | None:
    """The file of a URDF mesh that MuJoCo can read (STL, OBJ), or None: `package://PKG/rest` is looked up in the
    folders named PKG above the URDF, a relative name next to it."""
    if Path(filename).suffix.lower() not in MESH_FORMATS:
        return None
    if filename.startswith("package://"):
        package, _, rest = filename.removeprefix("package://").partition("/")
        candidates = [parent / rest for parent in urdf.resolve().parents if parent.name == package]
    else:
        candidates = [urdf.parent / filename.removeprefix("file://")]
    return next((c for c in candidates if c.is_file()), None)
