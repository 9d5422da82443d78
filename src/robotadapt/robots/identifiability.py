"""Base parameters: the combinations of a model's standard parameters that its dynamics can tell apart.

The regressor of an n-joint arm with 10 standard parameters per link has dependent columns: some parameters never act
(the first link's mass), some only in fixed combinations (I_zz,1 + I_yy,2 + …). The base parameters φ_b = K φ are a
minimal set with

    Y(q, q̇, v, a) = Y_b(q, q̇, v, a) K   on every state,   so   Y φ = Y_b φ_b

(Gautier & Khalil, "Direct calculation of minimum set of inertial parameters of serial robots", IEEE TRA 6(3), 1990;
Gautier, "Numerical calculation of the base inertial parameters of robots", J. Robotic Systems 8(4), 1991). The numerical
method of the latter: stack Y over random states, scale its columns to unit norm (so the units of the parameters do not
matter), and take Y = Q R. |R_ii| is the part of column i the columns before it do not explain: column i is kept when
|R_ii| > `tol`, else it is a combination Y_2 = Y_1 β of the kept columns before it (β by least squares). In the
parameters' own order (link by link) this is the textbook grouping: each base parameter is a standard parameter with the
later links' parameters it cannot be told from grouped into it ("Izz1 + 0.25·m2 + 0.25·m3"). (QR with column pivoting
finds the same rank but picks representatives by residual norm, which scrambles that grouping; on every arm shipped the
kept |R_ii| are ≥ 0.5 and the dropped ≤ 1e-9, so the order costs no robustness.) K has an identity on the kept columns
and β on the others. M, V_m, G and F depend on φ only through K φ, so a controller that adapts φ_b loses nothing
(:class:`BaseParameterModel`).

Friction columns (robotadapt.robots.dh.SerialChain) are per joint and depend on q̇ alone: each is independent of the
rigid-body columns, which all involve q or q̈. The offset column (𝟙 on its joint) is constant: gravity's columns of a
revolute joint have no constant part (G_i = ∂U/∂q_i of a U periodic in q_i averages to zero over q_i), and the masses
that give a prismatic joint a constant gravity torque also give it inertia (m q̈), so it stays independent on data
that accelerate the joints — but on data held at rest (q̈ = q̇ = 0) the offset of a joint whose gravity torque is
constant cannot be told from the masses it carries. The Coulomb and smooth Coulomb columns differ only where |q̇| is
a few v_s or less (tanh(q̇/v_s) = sgn q̇ beyond): independent, but nearly collinear unless the data move slowly often,
so identify one of the two unless the log has many slow reversals.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..pytree import Module
from ..validation import ConfigError, as_scalar, check_switch
from .base import Array, RobotModel

TOL = 1e-8  # a unit column is kept when |R_ii| > TOL; coefficients |β_ij| below TOL (scaled units) are zero


@dataclass(frozen=True, eq=False)
class BaseParameters(Module):
    """The result of :func:`base_parameters`.

    `K` (b × p) maps standard to base parameters, φ_b = K φ; `independent` lists the b columns of Y that form Y_b,
    ascending (the standard parameter each base parameter is named after); `names` reads each row of K
    ("Izz1 + Iyy2 + 0.0841·m3", coefficients in SI units). `margin` is (smallest kept, largest dropped) |R_ii|: the
    decision is safe when the two are orders of magnitude apart around `tol`. `residual` is max |Y − Y_b K| / max |Y|
    on the sampled states (round-off when the decision is right). With `friction=False` the friction parameters (the
    columns of F(q̇) = `model.friction`, or of Y(q, q̇, 0, 0) − Y(q, 0, 0, 0), which misses a constant offset column)
    are left out: their columns of K are zero.
    """

    model: RobotModel
    K: Array
    independent: tuple[int, ...]
    names: tuple[str, ...]
    friction: bool
    tol: float
    margin: tuple[float, float]
    residual: float

    @property
    def count(self) -> int:
        """The number b of base parameters."""
        return len(self.independent)

    def base(self, phi: Array) -> Array:
        """φ_b = K φ, shape `(..., b)`."""
        return np.asarray(phi, dtype=float) @ self.K.T

    def standard(self, phi_b: Array) -> Array:
        """A φ with K φ = φ_b: φ_b on the independent entries, zero elsewhere (any such φ has the same dynamics)."""
        phi_b = np.asarray(phi_b, dtype=float)
        return phi_b @ self._selection

    @cached_property
    def _selection(self) -> Array:
        E = np.zeros((self.count, self.K.shape[1]))
        E[np.arange(self.count), list(self.independent)] = 1.0
        return E


def base_parameters(model: RobotModel, friction: bool = True, rng: np.random.Generator | None = None,
                    samples: int | None = None, tol: float | None = None) -> BaseParameters:
    """The base parameters of `model` (see the module docstring).

    `samples` random states (default enough for 4 rows per parameter; q uniform in [−π, π], q̇, v, a standard normal,
    drawn from `rng`, default seed 0) give the stacked regressor. `friction=False` analyses the rigid-body part alone.
    """
    import scipy.linalg  # here, not at the top: importing the models stays light

    check_switch(friction, "friction")
    tol = as_scalar(TOL if tol is None else tol, "tol", positive=True, maximum=1e-2)
    rng = np.random.default_rng(0) if rng is None else rng
    n, p = model.n, model.p
    samples = -(-4 * p // n) + 10 if samples is None else samples
    if isinstance(samples, bool) or not isinstance(samples, int) or samples * n < p:
        raise ConfigError("samples", f"expected a whole number of at least p/n = {-(-p // n)} states, got {samples!r}")
    q = rng.uniform(-np.pi, np.pi, (samples, n))
    dq, v, a = rng.standard_normal((3, samples, n))
    Y = model.regressor(q, dq, v, a).reshape(-1, p)
    if not friction:
        zero = 0.0 * dq
        Yf = (model.regressor(q, dq, zero, zero) - model.regressor(q, zero, zero, zero)).reshape(-1, p)
        F = np.asarray(model.friction(dq[:, None, :], np.eye(p)))  # F(q̇; e_k), (samples, p, n): an offset's too
        acts = np.maximum(np.max(np.abs(Yf), axis=0), np.max(np.abs(F), axis=(0, 2)))
        Y = np.where(acts > tol * np.max(np.abs(Y)), 0.0, Y)
    scale = np.linalg.norm(Y, axis=0)
    idle = scale <= tol * scale.max()  # parameters that never act (round-off alone must not be scaled up)
    Y, scale = np.where(idle, 0.0, Y), np.where(idle, 1.0, scale)
    (R,) = scipy.linalg.qr(Y / scale, mode="r")
    d = np.abs(np.diag(R))  # the part of each unit column that the columns before it do not explain
    kept, dropped = np.flatnonzero(d > tol), np.flatnonzero(d <= tol)
    beta = scipy.linalg.lstsq(R[:p, kept], R[:p, dropped])[0] if dropped.size else np.zeros((kept.size, 0))  # Y_2 = Y_1 β
    K = np.zeros((kept.size, p))
    K[np.arange(kept.size), kept] = 1.0
    K[:, dropped] = np.where(np.abs(beta) > tol, beta, 0.0) * scale[dropped] / scale[kept, None]
    residual = float(np.max(np.abs(Y - Y[:, kept] @ K)) / np.max(np.abs(Y)))
    margin = (float(d[kept].min()), float(d[dropped].max()) if dropped.size else 0.0)
    return BaseParameters(model, K, tuple(int(j) for j in kept), _names(K, kept, model.param_names), friction, tol,
                          margin, residual)


def _names(K: Array, kept: Array, names: tuple[str, ...]) -> tuple[str, ...]:
    """Each row of K as "c + a − 0.3·b": its own standard parameter first, then the ones grouped into it."""
    rows = []
    for row, own in zip(K, kept, strict=True):
        text = names[own]
        for j in np.flatnonzero(row):
            if j != own:
                coef = f"{abs(row[j]):.4g}"
                text += (" − " if row[j] < 0 else " + ") + ("" if coef == "1" else coef + "·") + names[j]
        rows.append(text)
    return tuple(rows)


@dataclass(frozen=True, eq=False)
class BaseParameterModel(RobotModel):
    """`basis.model` with the base parameters φ_b as its parameter vector: Y_b = the independent columns of Y, and
    M(q, φ_b) etc. from the standard model at any φ with K φ = φ_b. Every controller can adapt φ_b unchanged."""

    basis: BaseParameters

    @property
    def n(self) -> int:
        return self.basis.model.n

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.basis.names

    @property
    def default_phi(self) -> Array | None:
        phi = self.basis.model.default_phi
        return None if phi is None else self.basis.base(phi)

    def mass_matrix(self, q: Array, phi: Array) -> Array:
        return self.basis.model.mass_matrix(q, self.basis.standard(phi))

    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        return self.basis.model.coriolis_matrix(q, dq, self.basis.standard(phi))

    def gravity(self, q: Array, phi: Array) -> Array:
        return self.basis.model.gravity(q, self.basis.standard(phi))

    def friction(self, dq: Array, phi: Array) -> Array:
        return self.basis.model.friction(dq, self.basis.standard(phi))

    def _select(self, Y: Array) -> Array:
        return Y[..., list(self.basis.independent)]

    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        return self._select(self.basis.model.regressor(q, dq, v, a))

    def momentum_regressor(self, q: Array, dq: Array) -> Array:
        return self._select(self.basis.model.momentum_regressor(q, dq))

    def remainder_regressor(self, q: Array, dq: Array) -> Array:
        return self._select(self.basis.model.remainder_regressor(q, dq))
