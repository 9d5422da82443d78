"""Rigid-body dynamics of a serial arm from its Denavit–Hartenberg table, derived with sympy and compiled to Python.

The derivation is the recursive Newton–Euler algorithm in link coordinates (Luh, Walker & Paul 1980), written for the
mixed ("two-slot") regressor of docs/laws.md#model P3:

    Y(q, q̇, v, a) φ = M(q) a + V_m(q, q̇) v + G(q)

Link i's body wrench (force, moment about its frame origin) is linear in its 10 standard parameters
φ_i = [m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz] (first moment and inertia about the link-frame origin,
in link-frame axes): f = m a + α × h + ω × (ω × h),  n = I α + ω × I ω + h × a, with h = m c. The joint torques are
τ = Σ_i J_iᵀ W_i (J_i the body Jacobian of frame i), so each link contributes the 10 columns J_iᵀ A_i.

Every velocity product in the recursion (ω × ż q̇_j, ω × (ω × p), ω × I ω, ...) is a quadratic form in q̇; it is replaced
by its polarisation ½[F(ω(q̇), ω(v)) + F(ω(v), ω(q̇))]. The symmetric bilinear form B(q̇, v) with B(q̇, q̇) = V_m q̇ is
unique and equals V_m(q, q̇) v with the Christoffel V_m (c_ijk is symmetric in i, j), so the result is exactly the
Christoffel form that property P2 (Ṁ − 2V_m skew) needs. M, V_m, G, Y_h and Y_g follow from Y by taking coefficients.

The expressions go through common-subexpression elimination (`sympy.cse`) and are printed as Python source: a function
`make(cos, sin)` returning closures over the elementary functions, so one compiled text serves Python floats (`math`,
the fast path for one state), numpy arrays and any array-API namespace. The source is cached on disk keyed by a hash of
the geometry (joint types, DH numbers, convention, gravity), in a folder named by a hash of this generator (folders of
older generators can be deleted); the inertial parameters are symbols, so one cache entry serves every set of masses and
inertias. Derivation time grows about as n³ (on this machine: PUMA 560 3 s, a spatial 7R chain 9 s, a 14-link planar
chain 19 s); a cached load takes 30–70 ms.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import tempfile
import types
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import array_namespace
from ..pytree import Module
from ..validation import ConfigError, as_vector

Array = Any
#: the order of a link's standard parameters (Pinocchio's `Inertia.toDynamicParameters` order)
LINK_PARAMS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
#: a chain's optional per-joint column groups, in this order after the 10n inertial ones, and their names' prefixes
EXTRAS = ("rotor_inertia", "viscous", "coulomb", "smooth_coulomb", "offset")
EXTRA_NAMES = {"rotor_inertia": "Ia", "viscous": "fv", "coulomb": "fc", "smooth_coulomb": "fs", "offset": "off"}
#: the groups of F(q̇), each a diagonal block of Y whose entries depend on q̇ alone (:meth:`SerialChain.friction`)
FRICTION = ("viscous", "coulomb", "smooth_coulomb", "offset")
#: the groups whose values may be negative (a constant torque offset); the others are ≥ 0
SIGNED = ("offset",)
#: v_s of the smooth Coulomb column tanh(q̇/v_s) unless a model says otherwise: rad/s (m/s on a prismatic joint)
SMOOTH_VELOCITY = 0.1
#: a link's keys in a DH table (`[[robot.links]]`)
LINK_KEYS = ("joint", "a", "alpha", "d", "theta", "m", "com", "inertia", *EXTRAS, "q_limits")


class SerialChain:
    """The joint count and parameter layout shared by the serial-chain models (the symbolic DH arm, the kinematic
    tree): 10 standard parameters per link (`LINK_PARAMS`), then n columns per optional group of `EXTRAS` the model
    has (a field of that name, None when absent). A mixin: the models are dataclasses with these fields.

    The friction groups (`FRICTION`) make F(q̇) = Σ_groups diag(column) φ_group, linear in φ, per joint i:

        viscous          fv_i q̇_i
        coulomb          fc_i sgn(q̇_i)
        smooth_coulomb   fs_i tanh(q̇_i / v_s,i)     v_s = `smooth_coulomb_velocity` (rad/s, m/s), a fixed setting
        offset           off_i                       a constant torque (force), either sign

    The smooth Coulomb term is Gaz et al.'s friction sigmoid (IEEE RA-L 4(4), 2019, the Panda's identified model
    φ₁/(1 + e^(−φ₂(q̇ + φ₃))) − φ₁/(1 + e^(−φ₂φ₃))) with the shift φ₃ = 0 and the slope φ₂ fixed: then it is
    φ₁ (σ(φ₂ q̇) − ½) = (φ₁/2) tanh(φ₂ q̇/2), i.e. fs = φ₁/2 and v_s = 2/φ₂, linear in its one coefficient. tanh rather
    than the uncentred sigmoid because tanh is odd: zero at rest, and no constant part, which would be collinear with
    the offset column; as v_s → 0 it tends to sgn, so fs is a Coulomb level in N·m. The shift φ₃ (not linear) makes
    the sigmoid's two levels unequal; away from zero speed that is fs tanh + off with off = −(φ₁/2) tanh(φ₂φ₃/2).
    The default v_s = `SMOOTH_VELOCITY` = 0.1 rad/s is below Gaz et al.'s Panda values 2/φ₂ = 0.12–0.39 rad/s; a
    much smaller v_s adds a slope fs/v_s at rest that makes the plant stiff for a fixed-step integrator."""

    joints: str  # one letter per joint, "R" or "P"
    rotor_inertia: Array | None  # the optional groups' values (`EXTRAS`), None when absent
    viscous: Array | None
    coulomb: Array | None
    smooth_coulomb: Array | None
    offset: Array | None
    smooth_coulomb_velocity: Array  # v_s per joint, > 0

    @property
    def n(self) -> int:
        return len(self.joints)

    @property
    def extras(self) -> tuple[str, ...]:
        """The optional column groups present, in order."""
        return tuple(name for name in EXTRAS if getattr(self, name) is not None)

    @property
    def param_names(self) -> tuple[str, ...]:
        names = [f"{p}{i + 1}" for i in range(self.n) for p in LINK_PARAMS]
        return tuple(names + [f"{EXTRA_NAMES[e]}{i + 1}" for e in self.extras for i in range(self.n)])

    def _extra(self, phi: Array, name: str) -> Array:
        """φ's entries of the optional group `name`, `(..., n)`."""
        k = 10 * self.n + self.n * self.extras.index(name)
        return phi[..., k : k + self.n]

    def friction_columns(self, dq: Array) -> dict[str, Array]:
        """The diagonal of each friction group's block of Y at q̇ `(..., n)`, for the groups present: q̇ (viscous),
        sgn q̇ (Coulomb), tanh(q̇/v_s) (smooth Coulomb), 1 (offset)."""
        xp = array_namespace(dq)
        out: dict[str, Array] = {}
        if self.viscous is not None:
            out["viscous"] = dq
        if self.coulomb is not None:
            out["coulomb"] = xp.sign(dq)
        if self.smooth_coulomb is not None:
            out["smooth_coulomb"] = xp.tanh(dq / self.smooth_coulomb_velocity)
        if self.offset is not None:
            out["offset"] = 1.0 + 0.0 * dq
        return out

    def friction(self, dq: Array, phi: Array) -> Array:
        """F(q̇) = f_v ∘ q̇ + f_c ∘ sgn(q̇) + f_s ∘ tanh(q̇/v_s) + τ_off (the groups present), shape `(..., n)`."""
        dq, phi = (x if hasattr(x, "shape") else np.asarray(x, dtype=float) for x in (dq, phi))
        out = 0.0 * dq + 0.0 * phi[..., :1]
        for name, column in self.friction_columns(dq).items():
            out = out + self._extra(phi, name) * column
        return out

    def _check_extras(self) -> None:
        """Validate the optional groups given (n values each, none negative but the offset's) and v_s (> 0), and store
        them as arrays."""
        for name in EXTRAS:
            if getattr(self, name) is not None:
                values = as_vector(getattr(self, name), self.n, f"robot.{name}")
                if name not in SIGNED and np.any(values < 0):
                    raise ConfigError(f"robot.{name}", f"must be zero or positive, got {values}")
                object.__setattr__(self, name, values)
        object.__setattr__(self, "smooth_coulomb_velocity", as_vector(
            self.smooth_coulomb_velocity, self.n, "robot.smooth_coulomb_velocity", positive=True))


#: the generated functions: name → (argument names, whether the last argument is φ)
FUNCTIONS = {"regressor": ("q", "dq", "v", "a"), "momentum": ("q", "dq"), "remainder": ("q", "dq"),
             "mass": ("q", "phi"), "coriolis": ("q", "dq", "phi"), "gravity": ("q", "phi")}


@dataclass(frozen=True)
class Geometry(Module):
    """What the symbolic derivation depends on (hashable): joint types ('R'/'P'), DH numbers, convention, gravity.

    Standard DH: link frame i = frame i−1 · Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i); modified (Craig): frame i−1 · Rx(α_i)
    Tx(a_i) Rz(θ_i) Tz(d_i), with row i holding a_{i−1}, α_{i−1}. The joint variable adds to θ (revolute) or d
    (prismatic); `theta` and `d` hold the constant parts. Lengths in m, angles in rad, gravity in m/s² (base frame).
    """

    joints: str
    a: tuple[float, ...]
    alpha: tuple[float, ...]
    d: tuple[float, ...]
    theta: tuple[float, ...]
    modified: bool
    gravity: tuple[float, float, float]

    @property
    def n(self) -> int:
        return len(self.joints)

    def key(self) -> str:
        """Hash of the geometry, exact float bits."""
        data = [self.joints, self.modified] + [[float(x).hex() for x in v]
                                               for v in (self.a, self.alpha, self.d, self.theta, self.gravity)]
        return hashlib.sha256(json.dumps(data).encode()).hexdigest()[:32]


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _transform(*parts: tuple[str, float]) -> np.ndarray:
    """Product of elementary homogeneous transforms ('Rx'|'Rz'|'Tx'|'Tz', value), 4×4."""
    out = np.eye(4)
    for kind, value in parts:
        step = np.eye(4)
        if kind[0] == "R":
            step[:3, :3] = _rot(kind[1], value)
        else:
            step["xyz".index(kind[1]), 3] = value
        out = out @ step
    return out


def joint_placements(geo: Geometry) -> list[tuple[np.ndarray, np.ndarray]]:
    """(pre_i, post_i) per joint, 4×4: link frame i = frame i−1 · pre_i · joint_i(q_i) · post_i, where joint_i is Rz(q_i)
    (revolute) or Tz(q_i) (prismatic) about the z axis of the frame it starts from."""
    out = []
    for j, kind in enumerate(geo.joints):
        a, al, d, th = geo.a[j], geo.alpha[j], geo.d[j], geo.theta[j]
        fixed_z = [("Rz", th)] if kind == "R" else [("Rz", th), ("Tz", d)]
        rest = [("Tz", d)] if kind == "R" else []
        if geo.modified:
            out.append((_transform(("Rx", al), ("Tx", a), *fixed_z), _transform(*rest)))
        else:
            out.append((_transform(*fixed_z), _transform(*rest, ("Tx", a), ("Rx", al))))
    return out


# ---------------------------------------------------------------------------------------------------------------------
# The symbolic Newton–Euler recursion


def _exact(sp: Any, T: np.ndarray) -> tuple[list[list[Any]], list[Any]]:
    """A numeric transform as sympy numbers, rotation entries within 1e-14 of 0 or ±1 made exact (so cos(π/2) is 0)."""
    def number(x: float, snap: bool) -> Any:
        for exact in (0.0, 1.0, -1.0):
            if (snap and abs(x - exact) < 1e-14) or x == exact:
                return sp.Integer(int(exact))
        return sp.Float(x, 17)

    return ([[number(T[i, k], True) for k in range(3)] for i in range(3)], [number(T[i, 3], False) for i in range(3)])


def _cross(u: list[Any], w: list[Any]) -> list[Any]:
    return [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]


def _add(*vs: list[Any]) -> list[Any]:
    return [sum(c[1:], c[0]) for c in zip(*vs, strict=True)]


def _scale(s: Any, u: list[Any]) -> list[Any]:
    return [s * c for c in u]


def _rot_t(R: list[list[Any]], u: list[Any]) -> list[Any]:
    """Rᵀ u: a vector of the parent frame in the child's coordinates."""
    return [R[0][i] * u[0] + R[1][i] * u[1] + R[2][i] * u[2] for i in range(3)]


def _sym(f: Any, w: list[Any], wv: list[Any], *args: Any) -> list[Any]:
    """Polarisation ½[f(ω(q̇), ω(v), …) + f(ω(v), ω(q̇), …)] of a velocity product."""
    return _scale(0.5, _add(f(w, wv, *args), f(wv, w, *args)))


def _double_cross(w1: list[Any], w2: list[Any], p: list[Any]) -> list[Any]:
    return _cross(w1, _cross(w2, p))


@dataclass
class _Frame:
    """Body quantities of the current frame, in its coordinates: ω(q̇), ω(v), origin velocity (for the Jacobian), the
    polarised angular and linear accelerations (gravity enters as the base acceleration −g)."""

    w: list[Any]
    wv: list[Any]
    lin: list[Any]
    alpha: list[Any]
    acc: list[Any]

    def fixed(self, R: list[list[Any]], p: list[Any]) -> _Frame:
        acc = _add(self.acc, _cross(self.alpha, p), _sym(_double_cross, self.w, self.wv, p))
        return _Frame(_rot_t(R, self.w), _rot_t(R, self.wv), _rot_t(R, _add(self.lin, _cross(self.w, p))),
                      _rot_t(R, self.alpha), _rot_t(R, acc))

    def revolute(self, sp: Any, q: Any, dq: Any, v: Any, a: Any) -> _Frame:
        z = [0, 0, 1]
        c, s = sp.cos(q), sp.sin(q)
        R = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
        coupling = _scale(0.5, _add(_cross(self.w, _scale(v, z)), _cross(self.wv, _scale(dq, z))))
        return _Frame(_rot_t(R, _add(self.w, _scale(dq, z))), _rot_t(R, _add(self.wv, _scale(v, z))),
                      _rot_t(R, self.lin), _rot_t(R, _add(self.alpha, _scale(a, z), coupling)), _rot_t(R, self.acc))

    def prismatic(self, q: Any, dq: Any, v: Any, a: Any) -> _Frame:
        zq = [0, 0, q]
        coriolis = _add(_cross(self.w, [0, 0, v]), _cross(self.wv, [0, 0, dq]))  # polarised 2 ω × ż q̇
        acc = _add(self.acc, _cross(self.alpha, zq), _sym(_double_cross, self.w, self.wv, zq), coriolis, [0, 0, a])
        return _Frame(self.w, self.wv, _add(self.lin, _cross(self.w, zq), [0, 0, dq]), self.alpha, acc)


def _coefficient(e: Any, var: Any, group: list[Any]) -> Any:
    """∂e/∂var for `e` linear and homogeneous in the symbols `group`: substitute var = 1, the others 0 (much cheaper
    than `diff` on nested expressions)."""
    from sympy import S

    return S(e).xreplace({s: S.One if s is var else S.Zero for s in group})


_UNIT = ((1, 0, 0), (0, 1, 0), (0, 0, 1))
_INERTIA_PAIRS = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))  # I_xx, I_xy, I_yy, I_xz, I_yz, I_zz


def _link_wrench(f: _Frame) -> list[list[Any]]:
    """A (6×10): the body wrench [force; moment about the origin] = A φ_i, column by column:
    m → [a; 0],  h_k → [α × e_k + ω × (ω × e_k); e_k × a],  I_jk → [0; E_jk α + ω × E_jk ω] (polarised products)."""
    zero = [0, 0, 0]
    columns = [f.acc + zero]
    for e in _UNIT:
        force = _add(_cross(f.alpha, list(e)), _sym(_double_cross, f.w, f.wv, list(e)))
        columns.append(force + _cross(list(e), f.acc))
    for j, k in _INERTIA_PAIRS:
        def times(u: list[Any], j: int = j, k: int = k) -> list[Any]:  # E_jk u, E_jk the symmetric unit tensor
            out: list[Any] = [0, 0, 0]
            out[j] += u[k]
            if j != k:
                out[k] += u[j]
            return out

        moment = _add(times(f.alpha), _sym(lambda w1, w2, t=times: _cross(w1, t(w2)), f.w, f.wv))
        columns.append(zero + moment)
    return [[columns[c][r] for c in range(10)] for r in range(6)]


def _run(sp: Any, geo: Geometry, q: list[Any], dq: list[Any], v: list[Any], a: list[Any], g: Sequence[Any],
         jacobians: list[list[list[Any]]]) -> list[list[Any]]:
    """The regressor Y (n × 10n) of one Newton–Euler pass with the given inputs (symbols or numbers; zeros prune)."""
    n = geo.n
    zero = [sp.S.Zero] * 3
    frame = _Frame(zero, zero, zero, zero, [-sp.S(x) for x in g])
    Y = [[sp.S.Zero] * (10 * n) for _ in range(n)]
    for i, ((pre, post), kind) in enumerate(zip(joint_placements(geo), geo.joints, strict=True)):
        frame = frame.fixed(*_exact(sp, pre))
        frame = frame.revolute(sp, q[i], dq[i], v[i], a[i]) if kind == "R" else frame.prismatic(q[i], dq[i], v[i], a[i])
        frame = frame.fixed(*_exact(sp, post))
        if len(jacobians) <= i:  # body Jacobian of link i, 6 × (i+1), from the first pass (q̇ symbolic)
            jacobians.append([[_coefficient(e, dq[k], dq) for k in range(i + 1)] for e in frame.lin + frame.w])
        J, A = jacobians[i], _link_wrench(frame)
        for k in range(i + 1):
            for c in range(10):
                Y[k][10 * i + c] = sp.Add(*[J[r][k] * A[r][c] for r in range(6) if J[r][k] != 0 and A[r][c] != 0])
    return Y


def derive(geo: Geometry) -> dict[str, Any]:
    """The sympy expressions of every generated function, as flat lists in row-major order, with their symbols.

    One Newton–Euler pass per part, with zeros and unit vectors instead of symbols where a part needs coefficients:
    Y(q, q̇, v, a); the columns M e_l (a = e_l) and V_m e_l (v = e_l); G (gravity only)."""
    import sympy as sp

    n, p = geo.n, 10 * geo.n
    q, dq, v, a = (list(sp.symbols(f"{name}0:{n}")) for name in ("q", "dq", "v", "a"))
    phi = list(sp.symbols(f"phi0:{p}"))
    g = [sp.Float(x, 17) for x in geo.gravity]
    nil, none = [sp.S.Zero] * n, [sp.S.Zero] * 3
    unit = [[sp.S.One if k == l_ else sp.S.Zero for k in range(n)] for l_ in range(n)]
    jac: list[list[list[Any]]] = []
    Y = _run(sp, geo, q, dq, v, a, g, jac)
    m_col = [_run(sp, geo, q, nil, nil, unit[l_], none, jac) for l_ in range(n)]  # m_col[l][j][k] = ∂M_jl/∂φ_k
    v_col = [_run(sp, geo, q, dq, unit[l_], nil, none, jac) for l_ in range(n)]  # v_col[l][j][k] = ∂V_m,jl/∂φ_k
    grv = _run(sp, geo, q, nil, nil, nil, g, jac)

    def dot(weights: list[Any], column: list[Any]) -> Any:
        return sp.Add(*[w * c for w, c in zip(weights, column, strict=True) if c != 0])

    mass = {(j, l_): dot(phi, m_col[l_][j]) for j in range(n) for l_ in range(j, n)}
    return {
        "symbols": {"q": q, "dq": dq, "v": v, "a": a, "phi": phi},
        "regressor": [e for row in Y for e in row],
        "momentum": [e for row in _run(sp, geo, q, nil, nil, dq, none, jac) for e in row],  # M q̇: a = q̇
        "remainder": [grv[l_][k] - dot(dq, [v_col[l_][j][k] for j in range(n)]) for l_ in range(n) for k in range(p)],
        "mass": [mass[min(j, l_), max(j, l_)] for j in range(n) for l_ in range(n)],  # symmetric by construction
        "coriolis": [dot(phi, v_col[l_][j]) for j in range(n) for l_ in range(n)],
        "gravity": [dot(phi, grv[j]) for j in range(n)],
    }


# ---------------------------------------------------------------------------------------------------------------------
# Code generation and the disk cache


def generate(geo: Geometry) -> str:
    """Python source of a module with `make(cos, sin) -> {name: function}` and, per function, the flat positions of its
    nonzero outputs (`POSITIONS[name]`) and which returned value fills each (`SOURCES[name]`)."""
    import sympy as sp
    from sympy.printing.pycode import PythonCodePrinter

    exprs = derive(geo)
    syms = exprs.pop("symbols")
    printer = PythonCodePrinter({"fully_qualified_modules": False, "standard": "python3"})
    lines = [f'"""Generated by robotadapt.robots.dh for {geo!r}. Do not edit."""', "", "", "def make(cos, sin):"]
    positions, sources = {}, {}
    for name, args in FUNCTIONS.items():
        flat = exprs[name]
        unique: dict[Any, int] = {}
        pos, src = [], []
        for i, e in enumerate(flat):
            if e != 0:
                pos.append(i)
                src.append(unique.setdefault(e, len(unique)))
        positions[name], sources[name] = pos, src
        replacements, reduced = sp.cse(list(unique), symbols=sp.numbered_symbols("x"), order="none")
        lines.append(f"    def {name}({', '.join(args)}):")
        for arg in args:
            names = [str(s) for s in syms[arg]]
            lines.append(f"        {', '.join(names)}{',' if len(names) == 1 else ''} = {arg}")
        lines += [f"        {s} = {printer.doprint(e)}" for s, e in replacements]
        lines.append("        return [" + ", ".join(printer.doprint(e) for e in reduced) + "]")
        lines.append("")
    lines.append("    return {" + ", ".join(f"{name!r}: {name}" for name in FUNCTIONS) + "}")
    lines += ["", "", f"POSITIONS = {positions!r}", f"SOURCES = {sources!r}", ""]
    return "\n".join(lines)


def cache_dir() -> Path:
    """$ROBOTADAPT_CACHE, else the user cache directory (platformdirs if installed, else ~/.cache/robotadapt)."""
    env = os.environ.get("ROBOTADAPT_CACHE")
    if env:
        return Path(env)
    try:
        import platformdirs
    except ImportError:
        return Path.home() / ".cache" / "robotadapt"
    return Path(platformdirs.user_cache_dir("robotadapt"))


@dataclass(frozen=True, eq=False)
class Compiled(Module):
    """The generated functions for Python floats (`math`) and numpy, and where their values go: the flat output
    positions of each function's nonzero values, and for each position the index of its value (None: in order)."""

    module: Any
    scalar: dict[str, Any]
    vectorized: dict[str, Any]
    positions: dict[str, np.ndarray]
    sources: dict[str, np.ndarray | None]
    path: Path


def _import(path: Path) -> Any:
    spec = importlib.util.spec_from_file_location(f"robotadapt_dh_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]  # also writes the bytecode cache next to it
    return module


def _write(path: Path, source: str) -> bool:
    """Write `source` atomically (parallel first loads each write a whole file); False if the cache is not writable."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, suffix=".tmp", delete=False, encoding="utf-8") as tmp:
            tmp.write(source)
        os.replace(tmp.name, path)
    except OSError:
        return False
    return True


@lru_cache(maxsize=64)
def compiled(geo: Geometry) -> Compiled:
    """Load the generated module for `geo` from the disk cache, deriving and writing it first on a miss (a cache that
    cannot be written costs a derivation per process, nothing else)."""
    import math

    generator = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]  # a new generator: a new folder
    path = cache_dir() / "dh" / generator / f"arm_{geo.key()}.py"
    if path.exists():
        module = _import(path)
    else:
        if importlib.util.find_spec("sympy") is None:
            raise ConfigError("robot.kind", "deriving an arm from its DH table needs sympy (this table is not in the "
                              "disk cache yet): pip install 'robotadapt[symbolic]'")
        source = generate(geo)
        if _write(path, source):
            module = _import(path)
        else:
            module = types.ModuleType(f"robotadapt_dh_{path.stem}")
            exec(compile(source, str(path), "exec"), module.__dict__)
    sources = {name: None if src == list(range(len(src))) else np.array(src, dtype=np.intp)
               for name, src in module.SOURCES.items()}
    positions = {name: np.array(pos, dtype=np.intp) for name, pos in module.POSITIONS.items()}
    return Compiled(module, module.make(math.cos, math.sin), module.make(np.cos, np.sin), positions, sources, path)
