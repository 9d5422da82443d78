"""Task-space references for laws that drive the hand (end effector) position: `traj(t) -> Reference(x_d, ẋ_d, ẍ_d)`.

The fields of the :class:`~robotadapt.trajectories.Reference` hold the hand's desired position, velocity and
acceleration, each of shape `t.shape + (m,)` (m = `traj.n`, the task dimension: 2 for a planar arm's x–y, 3 in space),
with every derivative in closed form and written in the array API of `t` (numpy and `jax.numpy` alike, traced by
`jax.jit`). A sum of sines per axis is :func:`robotadapt.trajectories.sum_of_sines` with n = m (the scenario kind
`sum_of_sines`).

Planes (:class:`Circle`, :class:`FigureEight`) are spanned by an orthonormal pair (u, v), the path's first and second
in-plane axes, with normal u × v: for m = 2 the x–y plane (u = e_x, v = e_y); for m = 3 "xy" (e_x, e_y), "yz" (e_y,
e_z), "xz" (e_x, e_z; normal −e_y), or a normal vector ν: u is the coordinate axis least aligned with ν (the first of
equals) projected onto the plane and normalised, v = ν̂ × u (so ν = e_z, e_x, −e_y give "xy", "yz", "xz").
Angles in rad, angular speeds in rad/s, lengths in m.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from .arrays import array_namespace
from .pytree import Module
from .trajectories import Quintic, Reference, Trajectory
from .validation import ConfigError, as_array, as_scalar, as_vector, scalar_gain

Array = Any

#: the kinds a task scenario names: kind → ("module:attribute" under robotadapt, what the constructor takes first), the
PLANES = {"xy": (0, 1), "yz": (1, 2), "xz": (0, 2)}


def _time(t: Array) -> tuple[Any, Array]:
    """The namespace of `t` and `t` as float64 of shape `t.shape + (1,)` (as the joint-space trajectories)."""
    xp = array_namespace(t) if hasattr(t, "shape") else np
    return xp, xp.asarray(t, dtype=xp.float64)[..., None]


def _point(value: Any, field: str) -> Array:
    """A task-space point: 2 numbers (x, y) or 3 (x, y, z)."""
    arr = as_array(value, field)
    if arr.shape not in ((2,), (3,)):
        raise ConfigError(field, f"expected 2 numbers (x, y: a planar arm) or 3 (x, y, z), got shape {arr.shape}")
    return arr


def _basis(plane: Any, m: int) -> tuple[Any, Array, Array]:
    """(the plane as kept: its name or unit normal, u, v), module docstring."""
    eye = np.eye(m)
    if isinstance(plane, str) and plane in PLANES and (m == 3 or plane == "xy"):
        i, j = PLANES[plane]
        return plane, eye[i], eye[j]
    if m == 2:
        raise ConfigError("trajectory.plane", f"a planar task (a centre of 2 numbers) moves in the x-y plane: leave "
                                              f"plane out or set \"xy\", got {plane!r}")
    if isinstance(plane, str):
        raise ConfigError("trajectory.plane", f"expected \"xy\", \"yz\", \"xz\" or a normal vector of 3 numbers, "
                                              f"got {plane!r}")
    normal = as_vector(plane, 3, "trajectory.plane", broadcast=False)
    size = float(np.linalg.norm(normal))
    if not size > 0:
        raise ConfigError("trajectory.plane", "a normal vector must not be zero")
    nu = normal / size
    k = int(np.argmin(np.abs(nu)))
    u = eye[k] - nu[k] * nu
    u = u / np.linalg.norm(u)
    return nu, u, np.cross(nu, u)


def _omega(value: Any) -> Array:
    w = scalar_gain(value, "trajectory.omega", positive=False)
    if w == 0:
        raise ConfigError("trajectory.omega", "must not be zero (a negative omega turns the other way)")
    return w


def _angle(xp: Any, tt: Array, omega: Array, phase: Array, ramp: float) -> tuple[Array, Array, Array]:
    """(θ, θ̇, θ̈) at `tt` (`(..., 1)`): θ = φ + ω t without a ramp; with a ramp T > 0 the angular speed rises from 0 to ω
    along the quintic θ̇ = ω S(s), S(s) = 10s³ − 15s⁴ + 6s⁵, s = clip(t/T, 0, 1), so (integrated)

    θ = φ + ω T (5s⁴/2 − 3s⁵ + s⁶) + ω max(t − T, 0),   θ̈ = 30 ω s²(1 − s)² / T:

    at rest at θ = φ for t ≤ 0 (θ̇ = θ̈ = θ⃛ = 0 at t = 0), then θ = φ + ω(t − T/2) after T."""
    w, ph = omega[..., None], phase[..., None]
    if ramp == 0.0:
        return w * tt + ph, w + 0.0 * tt, 0.0 * tt
    s = xp.clip(tt / ramp, 0.0, 1.0)
    theta = ph + w * (ramp * s**4 * (2.5 - 3.0 * s + s**2) + xp.maximum(tt - ramp, 0.0))
    return theta, w * s**3 * (10.0 - 15.0 * s + 6.0 * s**2), 30.0 * w * s**2 * (1.0 - s) ** 2 / ramp


def _period(omega: Array, ramp: float) -> float | None:
    """2π/|ω| for a path that is periodic from t = 0 (no ramp), else None."""
    return float(2 * np.pi / abs(float(omega))) if ramp == 0.0 and np.ndim(omega) == 0 else None


class InPlane:
    """What a path traced in a plane by an angle θ(t) holds and does (:class:`Circle`, :class:`FigureEight`): its
    `centre`, `omega`, `plane`, `phase`, `ramp` validated with its own sizes, the plane's (u, v), the task dimension,
    the period and θ, θ̇, θ̈ at t (:func:`_angle`)."""

    centre: Array
    omega: Array
    plane: Any
    phase: Array
    ramp: float

    def settle(self, **sizes: Array) -> None:
        """Validate the fields (sizes: the path's own, already checked) and set the plane's basis (u, v)."""
        centre = _point(self.centre, "trajectory.centre")
        plane, u, v = _basis(self.plane, centre.shape[0])
        values = {"centre": centre, **sizes, "omega": _omega(self.omega), "plane": plane,
                  "phase": scalar_gain(self.phase, "trajectory.phase", positive=False),
                  "ramp": as_scalar(self.ramp, "trajectory.ramp", nonnegative=True), "u": u, "v": v}
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        return int(self.centre.shape[-1])

    @property
    def period(self) -> float | None:
        return _period(self.omega, self.ramp)

    def angle(self, t: Array) -> tuple[Any, Array, Array, Array]:
        """(the namespace of t, θ, θ̇, θ̈) at t."""
        xp, tt = _time(t)
        return (xp, *_angle(xp, tt, self.omega, self.phase, self.ramp))


@dataclass(frozen=True, eq=False)
class Circle(InPlane, Module):
    """x_d = c + r (cos θ u + sin θ v) in the plane (u, v), θ(t) = ωt + phase, or with a ramp T > 0

    θ = phase + ωT (5s⁴/2 − 3s⁵ + s⁶) + ω max(t − T, 0),   s = clip(t/T, 0, 1)   (θ̇ = ω (10s³ − 15s⁴ + 6s⁵)),
    ẋ_d = r θ̇ (−sin θ u + cos θ v),   ẍ_d = r θ̈ (−sin θ u + cos θ v) − r θ̇² (cos θ u + sin θ v).

    `centre` (m,), `radius` > 0, `omega` ≠ 0 (counter-clockwise about u × v when positive), `plane` (module
    docstring), `phase` the angle at t = 0 (θ = 0 on c + r u), `ramp` ≥ 0 s: the hand starts at rest (θ̇ = θ̈ = 0 at
    t = 0) and turns at ω from `ramp` on (a quintic in the angular speed); 0 = at ω from the start.
    """

    array_api: ClassVar[bool] = True  # its own code is array API: a compiled loop evaluates it

    per_run: ClassVar[tuple[str, ...]] = ("centre", "radius", "omega", "phase")  # varies per run in one vectorized batch

    centre: Array
    radius: Array
    omega: Array
    plane: Any = "xy"
    phase: Array = 0.0
    ramp: float = 0.0
    u: Array = field(init=False)
    v: Array = field(init=False)

    def __post_init__(self) -> None:
        self.settle(radius=scalar_gain(self.radius, "trajectory.radius"))

    def __call__(self, t: Array) -> Reference:
        xp, theta, dtheta, ddtheta = self.angle(t)
        c, s = xp.cos(theta), xp.sin(theta)
        radial, tangent = c * self.u + s * self.v, -s * self.u + c * self.v
        r = self.radius[..., None]
        return Reference(self.centre + r * radial, r * dtheta * tangent, r * (ddtheta * tangent - dtheta**2 * radial))


@dataclass(frozen=True, eq=False)
class FigureEight(InPlane, Module):
    """The lemniscate of Gerono, (x/a)⁴ = (x/a)² − (y/b)² in plane coordinates (x, y) along (u, v), traced as

    x_d = c + a sin θ u + (b/2) sin 2θ v,   a = width/2, b = height (the full extents),
    ẋ_d = a θ̇ cos θ u + b θ̇ cos 2θ v,   ẍ_d = a (θ̈ cos θ − θ̇² sin θ) u + b (θ̈ cos 2θ − 2θ̇² sin 2θ) v,

    θ as for :class:`Circle` (ωt + phase, optionally ramped from rest). It crosses the centre at θ = 0 and π (along
    a u ± b v) and reaches the ends c ± a u at θ = ±π/2; one loop per 2π/|ω|.
    """

    array_api: ClassVar[bool] = True  # its own code is array API: a compiled loop evaluates it

    per_run: ClassVar[tuple[str, ...]] = ("centre", "width", "height", "omega", "phase")  # varies per run in one batch

    centre: Array
    width: Array
    height: Array
    omega: Array
    plane: Any = "xy"
    phase: Array = 0.0
    ramp: float = 0.0
    u: Array = field(init=False)
    v: Array = field(init=False)

    def __post_init__(self) -> None:
        self.settle(width=scalar_gain(self.width, "trajectory.width"),
                    height=scalar_gain(self.height, "trajectory.height"))

    def __call__(self, t: Array) -> Reference:
        xp, theta, dtheta, ddtheta = self.angle(t)
        s1, c1, s2, c2 = xp.sin(theta), xp.cos(theta), xp.sin(2 * theta), xp.cos(2 * theta)
        a, b = self.width[..., None] / 2, self.height[..., None]
        return Reference(self.centre + a * s1 * self.u + b / 2 * s2 * self.v,
                         a * dtheta * c1 * self.u + b * dtheta * c2 * self.v,
                         a * (ddtheta * c1 - dtheta**2 * s1) * self.u
                         + b * (ddtheta * c2 - 2 * dtheta**2 * s2) * self.v)


@dataclass(frozen=True, eq=False)
class Line(Module):
    """The segment from `x0` to `x1` with the quintic time law of :class:`~robotadapt.trajectories.Quintic`:

    x_d = x0 + (x1 − x0) (10s³ − 15s⁴ + 6s⁵),   s = clip((t − t0)/(t1 − t0), 0, 1),

    at rest (zero velocity and acceleration) at both ends, held at x0 before t0 and at x1 after t1.
    """

    array_api: ClassVar[bool] = True  # its own code is array API: a compiled loop evaluates it

    per_run: ClassVar[tuple[str, ...]] = ("x0", "x1")  # varies per run in one vectorized batch

    x0: Array
    x1: Array
    t0: float = 0.0
    t1: float = 1.0

    def __post_init__(self) -> None:
        x0 = _point(self.x0, "trajectory.x0")
        t0, t1 = as_scalar(self.t0, "trajectory.t0"), as_scalar(self.t1, "trajectory.t1")
        if not t1 > t0:
            raise ConfigError("trajectory.t1", f"must be later than t0 = {t0:g}, got {t1:g}")
        values = {"x0": x0, "x1": as_vector(self.x1, x0.shape[0], "trajectory.x1", broadcast=False), "t0": t0, "t1": t1}
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        return int(self.x0.shape[-1])

    period = None

    def __call__(self, t: Array) -> Reference:
        return Quintic(self.x0, self.x1, self.t0, self.t1)(t)


def reach_check(trajectory: Trajectory, origin: Any, inner: float, outer: float, t_final: float,
                samples: int = 2000) -> None:
    """Raise a :class:`~robotadapt.validation.ConfigError` ("trajectory", one line) when the path leaves the shell
    inner ≤ |x_d(t) − origin| ≤ outer for some t in [0, t_final]; it names the first such point, its time, its distance
    and the fix. `origin` (m,) is the base (the first joint); for the book's two-link arm inner = |l1 − l2|, outer =
    l1 + l2.

    The path is sampled at `samples` instants evenly spread over [0, t_final] and at every extremum of the distance
    between two samples: the zeros of (x_d − origin)·ẋ_d (half the distance² rate) where it changes sign, found by
    bisection (every extremum of a circle, whose distance has one maximum and one minimum per turn).
    """
    o = as_vector(origin, trajectory.n, "origin", broadcast=False)
    lo, hi = as_scalar(inner, "inner", nonnegative=True), as_scalar(outer, "outer", positive=True)
    if not hi > lo:
        raise ConfigError("outer", f"must exceed inner = {lo:g}, got {hi:g}")
    T = as_scalar(t_final, "t_final", positive=True)
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 2:
        raise ConfigError("samples", f"expected a whole number of at least 2, got {samples!r}")
    t = np.linspace(0.0, T, int(samples))
    t = np.sort(np.concatenate([t, _extrema(trajectory, o, t)]))
    x = trajectory(t).q_des
    distance = np.linalg.norm(x - o, axis=-1)
    out = np.flatnonzero((distance > hi) | (distance < lo))
    if out.size == 0:
        return
    i = out[0]
    fix = ("shrink the path (a smaller radius, width, height or amplitude) or move its centre closer to the base"
           if distance[i] > hi else "move the path away from the base (a centre farther out or a smaller radius)")
    raise ConfigError("trajectory", f"the hand leaves the arm's reach at t = {t[i]:.6g} s: x_d = {_show(x[i])} is "
                                    f"{distance[i]:.4g} m from the base {_show(o)}, outside [{lo:.4g}, {hi:.4g}] m; "
                                    f"{fix}")


def _show(point: Array) -> str:
    return "[" + ", ".join(f"{float(c):.4g}" for c in point) + "]"


def _extrema(trajectory: Trajectory, origin: Array, t: Array, iterations: int = 60) -> Array:
    """The instants strictly between neighbouring samples `t` where g = (x_d − origin)·ẋ_d changes sign (the
    distance's extrema), refined by bisection."""
    def g(times: Array) -> Array:
        ref = trajectory(times)
        return np.sum((ref.q_des - origin) * ref.dq_des, axis=-1)

    gt = g(t)
    k = np.flatnonzero(gt[:-1] * gt[1:] < 0)
    a, b, ga = t[k], t[k + 1], gt[k]
    for _ in range(iterations):
        mid = 0.5 * (a + b)
        gm = g(mid)
        left = ga * gm <= 0  # the sign change is in [a, mid]
        a, b, ga = np.where(left, a, mid), np.where(left, mid, b), np.where(left, ga, gm)
    return 0.5 * (a + b)
