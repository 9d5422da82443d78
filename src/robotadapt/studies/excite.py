"""An optimised exciting trajectory for identification (`robotadapt excite`, docs/identification.md).

The trajectory is the finite Fourier series of Swevers, Ganseman, Tükel, De Schutter & Van Brussel, "Optimal robot
excitation and identification", IEEE TRA 13(5), 1997 (:func:`robotadapt.trajectories.fourier`), per joint i:

    q_i(t) = q_i0 + Σ_{l=1..K} a_il/(ω_f l) sin(ω_f l t) − b_il/(ω_f l) cos(ω_f l t),   ω_f = 2π/T.

It starts (and, being periodic, ends) at rest by construction: q̇_i(0) = Σ_l a_il = 0 and q̈_i(0) = ω_f Σ_l l b_il = 0
are solved for a_iK and b_iK, so the design vector x holds a_il, b_il for l < K and q_i0, n(2K − 1) numbers.

Objective, on N samples t_j = j T/N of one period: the stacked base regressor W = [Y_b(q_d, q̇_d, q̇_d, q̈_d)(t_j)]
((N n) × b, SI units; :mod:`robotadapt.robots.identifiability`) and its singular values σ:

- `cond` (default): minimise log cond W = log σ_max − log σ_min. The least-squares estimate's relative error is
  bounded by cond W times the relative torque noise, and the identification papers (Gautier & Khalil 1992, Swevers
  et al. 1997) report cond W; it depends on the units and on the choice of base parameters.
- `logdet`: maximise log det WᵀW = 2 Σ log σ (D-optimality), invariant to the parameters' units and to the choice of
  base parameters up to a constant, but it may buy a large det with one weak direction left.

The optimiser takes σ² as the eigenvalues λ of the b × b Gram matrix WᵀW (:func:`gram_scores`): the same objective, the
condition number of W (log cond W = ½ log λ_max/λ_min), from a small symmetric eigenproblem rather than the SVD of the
tall W, whose LAPACK call runs on OpenBLAS's threads, which stall when other jobs share the cores (the Panda's value
and gradient through the SVD took 7–86 ms a call on a busy 2-core machine, 3 ms with one BLAS thread; through WᵀW,
2 ms). λ_min is then accurate to about ε λ_max: its relative error ε cond²W is 1e-8 at cond W = 1e4, the gradient's
likewise, far finer than the optimiser needs. What is reported (:func:`score`) is the SVD of W.

Constraints, on the same samples, each normalised to ≤ 1: the position inside [lower, upper], |q̇| ≤ q̇_max,
|q̈| ≤ q̈_max and |τ| ≤ τ_max, τ the inverse dynamics at the model's nominal parameters (`default_phi`, the prior a user
has), each sample and joint a row. The first three are linear in x, so their Jacobian is a constant; τ's Jacobian is
∂τ/∂(q, q̇, q̈) at each sample (3n forward derivatives over all the samples at once: a sample's τ depends on its own
state only) times the constant ∂(q, q̇, q̈)/∂x. SLSQP minimises with the JAX gradient and that exact Jacobian
(compiled once, shared by the `starts` random feasible starts: random coefficients scaled by bisection to
`START_SHARE` of the largest feasible size, about the middle of the position range), at most `max_iter` iterations a
start and, with a `time_budget`, no start begun and no iteration begun after it: a run it cuts ends at its best
feasible point so far (its start, or an iterate). Of the runs' end points the best feasible one is kept (the lowest
objective; of infeasible ones only when none is feasible). It is then checked on a grid `FINE` times denser; where it
leaves a limit between the samples its coefficients are scaled down (q − q_0, q̇ and q̈ scale with them) by bisection
until the fine grid is inside, and what is reported is what the fine grid shows.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..robots.base import RobotModel
from ..robots.identifiability import base_parameters
from ..tracing import float64, jax_module
from ..trajectories import SumOfSines, Trajectory, fourier
from ..validation import ConfigError

Array = Any
KINDS = ("position", "velocity", "acceleration", "torque")
OBJECTIVES = ("cond", "logdet")
SAMPLES_PER_HARMONIC = 20  # default N: this many samples per period of the highest harmonic ...
ROWS_PER_PARAMETER = 4  # ... and at least this many equations per base parameter
FINE = 20  # the check's grid is this many times denser
START_SHARE = 0.7  # a start is this share of the largest feasible scaling of its random coefficients
MAXITER = 300
FTOL = 1e-10
FEASIBLE = 1e-6  # a sampled constraint counts as met up to this (normalised) violation
CAPPED = 9  # SLSQP's exit mode at its iteration cap


@dataclass(frozen=True, eq=False)
class Limits:
    """The bounds the design keeps, `fraction` of the given limits applied: `lower`, `upper` (n,) the position range
    (shrunk about its middle), `velocity`, `acceleration`, `torque` (n,) (inf: not constrained). `given` holds the limits
    before the fraction (position as (n, 2)), `source` per kind and joint "urdf", "model", "option" or "none"."""

    lower: Array
    upper: Array
    velocity: Array
    acceleration: Array
    torque: Array
    given: dict[str, Array | None]
    source: dict[str, tuple[str, ...]]
    fraction: float

    def bound(self, kind: str) -> Array:
        """The (n,) bound of a magnitude kind."""
        return {"velocity": self.velocity, "acceleration": self.acceleration, "torque": self.torque}[kind]

    def as_dict(self) -> dict[str, Any]:
        position = {"lower": self.lower.tolist(), "upper": self.upper.tolist(), "given": _listed(self.given["position"]),
                    "source": list(self.source["position"])}
        out: dict[str, Any] = {"fraction": self.fraction, "position": position}
        for kind in KINDS[1:]:
            out[kind] = {"bound": _listed(self.bound(kind)), "given": _listed(self.given[kind]),
                         "source": list(self.source[kind])}
        return out


def _listed(values: Array | None) -> Any:
    """An array as JSON: inf (no limit) as None."""
    if values is None:
        return None
    return [_listed(v) if np.ndim(v) else (float(v) if np.isfinite(v) else None) for v in values]


def resolve_limits(model: RobotModel, given: dict[str, Array | None], fraction: float = 0.9,
                   model_source: str = "model") -> Limits:
    """The bounds of the design: each kind from `given` (position (n, 2), the others (n,)) where not None, else from
    the model's `q_limits`, `dq_limits`, `tau_limits` (labelled `model_source`), else none; position limits are
    required. `fraction` (0, 1] shrinks every limit toward safety."""
    if not 0 < fraction <= 1:
        raise ConfigError("--fraction", f"expected a number in (0, 1], got {fraction:g}")
    n = model.n
    own = {"position": getattr(model, "q_limits", None), "velocity": getattr(model, "dq_limits", None),
           "acceleration": None, "torque": getattr(model, "tau_limits", None)}
    values, source = {}, {}
    for kind in KINDS:
        value, label = (given.get(kind), "option") if given.get(kind) is not None else (own[kind], model_source)
        values[kind] = None if value is None else np.asarray(value, dtype=float)
        source[kind] = (label if value is not None else "none",) * n
    if values["position"] is None:
        raise ConfigError("--position-limit", "the model has no joint limits: give --position-limit X (−X ≤ q ≤ X rad) "
                          "or LO:HI per joint, comma-separated")
    if values["torque"] is not None and model.default_phi is None:
        raise ConfigError("--torque-limit", "the model has no nominal parameters (default_phi) to compute τ with")
    mid, half = values["position"].mean(axis=1), 0.5 * np.diff(values["position"], axis=1)[:, 0]
    bounds = {kind: np.full(n, np.inf) if (v := values[kind]) is None else fraction * v for kind in KINDS[1:]}
    return Limits(mid - fraction * half, mid + fraction * half, bounds["velocity"], bounds["acceleration"],
                  bounds["torque"], values, source, float(fraction))


@dataclass(frozen=True, eq=False)
class Design:
    """The parametrisation of the module docstring: `n` joints, `harmonics` K ≥ 2, `period` T (s)."""

    n: int
    harmonics: int
    period: float

    def __post_init__(self) -> None:
        K = self.harmonics
        if isinstance(K, bool) or not float(K).is_integer() or K < 2:
            raise ConfigError("--harmonics", f"expected a whole number ≥ 2 (with one harmonic, starting at rest leaves "
                              f"no motion), got {K!r}")
        if not np.isfinite(self.period) or not self.period > 0:
            raise ConfigError("--period", f"must be a positive number of seconds, got {self.period!r}")
        object.__setattr__(self, "harmonics", int(K))

    @property
    def size(self) -> int:
        """The length n(2K − 1) of the design vector."""
        return self.n * (2 * self.harmonics - 1)

    @property
    def omega(self) -> Array:
        """ω_f l, l = 1..K (rad/s)."""
        return 2 * np.pi / self.period * np.arange(1, self.harmonics + 1)

    def coefficients(self, x: Array, xp: Any = np) -> tuple[Array, Array, Array]:
        """(a, b, q_0): the tables (n, K) with a_iK = −Σ_{l<K} a_il and b_iK = −Σ_{l<K} l b_il / K, and (n,)."""
        n, K = self.n, self.harmonics
        m = n * (K - 1)
        a, b = xp.reshape(x[:m], (n, K - 1)), xp.reshape(x[m : 2 * m], (n, K - 1))
        l = np.arange(1, K)
        a = xp.concat([a, -xp.sum(a, axis=1, keepdims=True)], axis=1)
        b = xp.concat([b, -(b @ l)[:, None] / K], axis=1)
        return a, b, x[2 * m :]

    def vector(self, a: Array, b: Array, offset: Array) -> Array:
        """The design vector of coefficients (the last harmonic dropped: it follows from the others)."""
        return np.concat([np.asarray(a)[:, :-1].ravel(), np.asarray(b)[:, :-1].ravel(), np.asarray(offset)])

    def motion(self, x: Array, t: Array, xp: Any = np) -> tuple[Array, Array, Array]:
        """(q_d, q̇_d, q̈_d) at the instants `t` (m,), each (m, n): the series above, linear in x."""
        a, b, offset = self.coefficients(x, xp)
        w = self.omega
        S, C = np.sin(np.outer(t, w)), np.cos(np.outer(t, w))
        return (offset + S @ (a / w).T - C @ (b / w).T, C @ a.T + S @ b.T, C @ (b * w).T - S @ (a * w).T)

    def trajectory(self, x: Array) -> SumOfSines:
        """The trajectory of `x`, as a scenario's `[trajectory] kind = "fourier"` builds it."""
        a, b, offset = self.coefficients(np.asarray(x, dtype=float))
        return fourier(self.n, self.period, a, b, offset)

    def grid(self, samples: int) -> Array:
        """`samples` instants j T / samples of one period."""
        return self.period * np.arange(samples) / samples


def stacked_regressor(model: RobotModel, independent: Array, q: Array, dq: Array, ddq: Array) -> Array:
    """W = [Y_b(q_d, q̇_d, q̇_d, q̈_d)] over the samples, shape (m n, b)."""
    Y = model.regressor(q, dq, dq, ddq)[..., independent]
    return Y.reshape(-1, len(independent))


def spectrum_scores(W: Array, xp: Any = np) -> tuple[Array, Array]:
    """(log cond W, log det WᵀW) from the singular values of W."""
    s = xp.linalg.svd(W, compute_uv=False)
    return xp.log(s[0]) - xp.log(s[-1]), 2 * xp.sum(xp.log(s))


def gram_scores(W: Array, xp: Any = np) -> tuple[Array, Array]:
    """(log cond W, log det WᵀW) from the eigenvalues of WᵀW, the squared singular values of W (module docstring)."""
    lam = xp.linalg.eigvalsh(W.T @ W)
    return 0.5 * (xp.log(lam[-1]) - xp.log(lam[0])), xp.sum(xp.log(lam))


@dataclass(frozen=True, eq=False)
class Envelope:
    """A trajectory on a grid `t` with the inverse dynamics at the nominal φ (`tau`, None without one), the extremes
    per joint and kind, and how far each kind goes toward its bound: `ratio[kind]` = max over joints and instants of
    |value|/bound (position: |q − middle|/half range); ≤ 1 meets it (NaN: not constrained)."""

    t: Array
    q: Array
    dq: Array
    ddq: Array
    tau: Array | None
    ratio: dict[str, float]

    @property
    def met(self) -> bool:
        return all(not r > 1.0 for r in self.ratio.values())

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"position": {"min": self.q.min(axis=0).tolist(), "max": self.q.max(axis=0).tolist()}}
        for kind, v in (("velocity", self.dq), ("acceleration", self.ddq), ("torque", self.tau)):
            out[kind] = None if v is None else np.abs(v).max(axis=0).tolist()
        return {"max_abs": out, "worst_ratio": {k: None if np.isnan(r) else r for k, r in self.ratio.items()},
                "limits_met": self.met}


def envelope(model: RobotModel, trajectory: Trajectory, t: Array, limits: Limits) -> Envelope:
    """The trajectory's :class:`Envelope` on `t`, by numpy (the trajectory object and the model's inverse dynamics)."""
    ref = trajectory(np.asarray(t, dtype=float))
    phi = model.default_phi
    tau = None if phi is None else np.asarray(model.inverse_dynamics(ref.q_des, ref.dq_des, ref.ddq_des, phi))
    mid, half = 0.5 * (limits.upper + limits.lower), 0.5 * (limits.upper - limits.lower)
    ratio = {"position": float(np.max(np.abs(ref.q_des - mid) / half))}
    for kind, v in (("velocity", ref.dq_des), ("acceleration", ref.ddq_des), ("torque", tau)):
        bound = limits.bound(kind)
        ratio[kind] = float(np.max(np.abs(v) / bound)) if v is not None and np.all(np.isfinite(bound)) else np.nan
    return Envelope(np.asarray(t), ref.q_des, ref.dq_des, ref.ddq_des, tau, ratio)


def score(model: RobotModel, independent: Array, trajectory: Trajectory, t: Array) -> tuple[float, float]:
    """(cond W, log det WᵀW) of a trajectory on the instants `t`, by numpy."""
    ref = trajectory(np.asarray(t, dtype=float))
    log_cond, log_det = spectrum_scores(stacked_regressor(model, independent, ref.q_des, ref.dq_des, ref.ddq_des))
    return float(np.exp(log_cond)), float(log_det)


class Programs:
    """The compiled objective (value and gradient) and constraints (values ≥ 0 and Jacobian) of one design, shared by
    every start; each traced and compiled once. Call within :func:`~robotadapt.tracing.float64`."""

    def __init__(self, model: RobotModel, design: Design, independent: Array, limits: Limits, t: Array,
                 objective: str) -> None:
        jax = jax_module()
        jnp = jax.numpy
        phi = model.default_phi
        mid, half = 0.5 * (limits.upper + limits.lower), 0.5 * (limits.upper - limits.lower)
        kinds = [k for k in KINDS[1:] if np.all(np.isfinite(limits.bound(k)))]
        torque = "torque" in kinds
        n = design.n
        # ∂(q, q̇, q̈)/∂x at each sample, (m, 3n, size): the motion is linear in x, its columns its values at each e_k
        motion = np.stack([np.concat(design.motion(e, t), axis=1) for e in np.eye(design.size)], axis=-1)
        scale = {"velocity": 1, "acceleration": 2}
        linear = [motion[:, :n] / half[:, None]] + [motion[:, scale[k] * n : (scale[k] + 1) * n]
                                                     / limits.bound(k)[:, None] for k in kinds if k != "torque"]
        self.linear_jacobian = np.concat([d.reshape(-1, design.size) for d in linear])

        def value(x: Array) -> Array:
            log_cond, log_det = gram_scores(stacked_regressor(model, independent, *design.motion(x, t, jnp)), jnp)
            return log_cond if objective == "cond" else -log_det

        def constraints(x: Array) -> Array:
            q, dq, ddq = design.motion(x, t, jnp)
            values = {"velocity": dq, "acceleration": ddq}
            if torque:
                values["torque"] = model.inverse_dynamics(q, dq, ddq, phi)
            rows = [(q - mid) / half] + [values[k] / limits.bound(k) for k in kinds]
            return 1.0 - jnp.concat([jnp.ravel(r) for r in rows] + [-jnp.ravel(r) for r in rows])

        def torque_jacobian(x: Array) -> Array:
            """∂(τ/τ_max)/∂x, (m n, size)."""
            state = design.motion(x, t, jnp)

            def column(e: Array) -> Array:  # ∂τ_j/∂s_jc at every sample j for one state coordinate c
                tangents = tuple(jnp.broadcast_to(e[i], s.shape) for i, s in enumerate(state))
                return jax.jvp(lambda q, dq, ddq: model.inverse_dynamics(q, dq, ddq, phi), state, tangents)[1]

            partial = jax.vmap(column)(jnp.eye(3 * n).reshape(3 * n, 3, n))  # (3n, m, n)
            return (jnp.einsum("cji,jcx->jix", partial, motion) / limits.torque[:, None]).reshape(-1, design.size)

        self.value_and_grad = jax.jit(jax.value_and_grad(value))
        self.constraints = jax.jit(constraints)
        self.torque_jacobian = jax.jit(torque_jacobian) if torque else None

    def objective(self, x: Array) -> tuple[float, Array]:
        f, g = self.value_and_grad(x)
        return float(f), np.asarray(g)

    def jacobian(self, x: Array) -> Array:
        """The Jacobian of the constraints 1 − (ρ, −ρ): (−∂ρ/∂x, ∂ρ/∂x), ρ the normalised rows (position, velocity
        and acceleration, constant, then τ's)."""
        J = self.linear_jacobian
        if self.torque_jacobian is not None:
            J = np.concat([J, np.asarray(self.torque_jacobian(x))])
        return np.concat([-J, J])

    def feasible(self, x: Array) -> bool:
        return bool(np.min(np.asarray(self.constraints(x))) >= -FEASIBLE)


def _largest_scale(feasible: Any, hi: float = 1.0, steps: int = 40) -> float:
    """The largest s in [0, ∞) with `feasible(s)` by doubling then bisection (0 when s = 0 is not feasible)."""
    if not feasible(0.0):
        return 0.0
    while feasible(hi) and hi < 1e6:
        hi *= 2
    lo = 0.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if feasible(mid) else (lo, mid)
    return lo


def _scaled(design: Design, x: Array, s: float) -> Array:
    """x with every coefficient a_il, b_il times s (the offsets kept)."""
    m = design.n * (design.harmonics - 1)
    return np.concat([s * x[: 2 * m], x[2 * m :]])


def _start(design: Design, programs: Programs, limits: Limits, rng: np.random.Generator) -> Array:
    """A random feasible start: coefficients ~ N(0, 1/l) about the middle of the position range, scaled."""
    n, K = design.n, design.harmonics
    spread = 1.0 / np.arange(1, K)
    x = np.concat([(rng.standard_normal((n, K - 1)) * spread).ravel(), (rng.standard_normal((n, K - 1)) * spread).ravel(),
                   0.5 * (limits.lower + limits.upper)])
    s = _largest_scale(lambda s: programs.feasible(_scaled(design, x, s)))
    return _scaled(design, x, START_SHARE * s)


class _Search:
    """The optimiser's runs, one per start: the best feasible point of the current run, each run's iterations, the
    progress bar and the time budget (:meth:`step`, SLSQP's callback, ends a run by StopIteration once the `deadline`
    has passed)."""

    def __init__(self, programs: Programs, starts: int, deadline: float, bar: Any) -> None:
        self.programs, self.starts, self.deadline, self.bar = programs, starts, deadline, bar
        self.best_objective = np.inf
        self.best: Array | None = None
        self.iterations: list[int] = []
        self.out_of_time = False

    def offer(self, x: Array, objective: float) -> None:
        """Keep `x` if it is feasible and better than the run's best so far."""
        if objective < self.best_objective and self.programs.feasible(x):
            self.best_objective, self.best = objective, np.array(x)

    def begin(self, x0: Array, objective: float) -> None:
        """A new run from `x0`."""
        self.iterations.append(0)
        self.best_objective, self.best = np.inf, None
        self.offer(x0, objective)
        self.bar.set_postfix_str(f"start {len(self.iterations)}/{self.starts}, objective {objective:.4g}")

    def step(self, intermediate_result: Any) -> None:
        """After each SLSQP iteration."""
        self.iterations[-1] += 1
        objective = float(intermediate_result.fun)
        self.offer(intermediate_result.x, objective)
        self.bar.update()
        self.bar.set_postfix_str(f"start {len(self.iterations)}/{self.starts}, objective {objective:.4g}, best "
                                 f"{self.best_objective:.4g}")
        if self.over():
            raise StopIteration

    def over(self) -> bool:
        """Whether the time budget is spent (and remember that it cut the search)."""
        self.out_of_time = self.out_of_time or time.perf_counter() > self.deadline
        return self.out_of_time


@dataclass(frozen=True, eq=False)
class Excitation:
    """The optimised trajectory (`x`, `design`; :meth:`trajectory`) with its scores on the `samples` grid (`cond`,
    `log_det`), its `fine` :class:`Envelope` (what `limits` it meets), `scale` the factor the coefficients were scaled
    down by to meet them between the samples (1: not needed), per start run the optimiser's `iterations`, its objective
    at the start and at the end and its `exits` (SLSQP's message, or the time budget's), of `starts` asked for, with at
    most `max_iter` iterations each within `time_budget` s (None: none); `stopped` says what ended the search
    ("converged", "iteration cap N", "time budget T s" or SLSQP's message); `seconds` taken."""

    design: Design
    x: Array
    objective: str
    samples: int
    cond: float
    log_det: float
    limits: Limits
    fine: Envelope
    scale: float
    iterations: tuple[int, ...]
    start_objectives: tuple[float, ...]
    final_objectives: tuple[float, ...]
    exits: tuple[str, ...]
    starts: int
    max_iter: int
    time_budget: float | None
    stopped: str
    seconds: float

    def trajectory(self) -> SumOfSines:
        return self.design.trajectory(self.x)

    def as_dict(self) -> dict[str, Any]:
        a, b, offset = self.design.coefficients(self.x)
        return {"objective": self.objective, "harmonics": self.design.harmonics, "period": self.design.period,
                "samples": self.samples, "a": a.tolist(), "b": b.tolist(), "offset": offset.tolist(),
                "q0": self.trajectory()(0.0).q_des.tolist(), "cond": self.cond, "log_det": self.log_det,
                **self.fine.as_dict(), "fine_samples": int(self.fine.t.size), "scale": self.scale,
                "stopped": self.stopped, "starts": self.starts, "starts_run": len(self.iterations),
                "max_iter": self.max_iter, "time_budget": self.time_budget, "iterations": list(self.iterations),
                "exits": list(self.exits), "start_objectives": list(self.start_objectives),
                "final_objectives": list(self.final_objectives), "seconds": self.seconds}


def default_samples(design: Design, base_count: int) -> int:
    """N: `SAMPLES_PER_HARMONIC` per period of the highest harmonic, at least `ROWS_PER_PARAMETER` rows per base
    parameter."""
    return max(SAMPLES_PER_HARMONIC * design.harmonics, -(-ROWS_PER_PARAMETER * base_count // design.n))


def _stopped(exits: list[tuple[int, str]], out_of_time: bool, max_iter: int, time_budget: float | None) -> str:
    """What ended the search, from each run's (SLSQP exit mode, message)."""
    if out_of_time:
        return f"time budget {time_budget:g} s"
    if any(mode == CAPPED for mode, _ in exits):
        return f"iteration cap {max_iter}"
    return next((f"SLSQP: {message}" for mode, message in exits if mode != 0), "converged")


@float64
def excite(model: RobotModel, design: Design, limits: Limits, objective: str = "cond", samples: int | None = None,
           starts: int = 3, rng: np.random.Generator | None = None, max_iter: int = MAXITER,
           time_budget: float | None = None, progress: bool = False) -> Excitation:
    """The exciting trajectory of the module docstring for `model`: `starts` SLSQP runs of at most `max_iter`
    iterations from random feasible starts drawn from `rng` (default seed 0), within `time_budget` seconds (None: no
    limit), the best feasible point kept, checked and scaled on the fine grid. `progress`: a progress bar on stderr
    when it is a terminal."""
    import scipy.optimize
    from threadpoolctl import threadpool_limits
    from tqdm import tqdm

    clock = time.perf_counter()
    if objective not in OBJECTIVES:
        raise ConfigError("--objective", f"expected one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if isinstance(starts, bool) or not isinstance(starts, int) or starts < 1:
        raise ConfigError("--starts", f"expected a whole number ≥ 1, got {starts!r}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
        raise ConfigError("--max-iter", f"expected a whole number ≥ 1 of SLSQP iterations per start, got {max_iter!r}")
    if time_budget is not None and (isinstance(time_budget, bool) or not isinstance(time_budget, int | float)
                                    or not 0 < time_budget < np.inf):
        raise ConfigError("--time-budget", f"expected a positive number of seconds, got {time_budget!r}")
    independent = np.array(base_parameters(model).independent)
    b = independent.size
    samples = default_samples(design, b) if samples is None else samples
    if isinstance(samples, bool) or not isinstance(samples, int) or samples * design.n < b:
        raise ConfigError("--samples", f"expected a whole number with samples × {design.n} joints ≥ the {b} base "
                          f"parameters (at least {-(-b // design.n)}), got {samples!r}")
    rng = np.random.default_rng(0) if rng is None else rng
    quiet = not (progress and sys.stderr.isatty())  # as `robotadapt tune`: a progress bar on a terminal only
    # one BLAS thread: SLSQP's and the Gram matrix's calls are small, and OpenBLAS's pool stalls them beside another job
    with tqdm(total=starts * max_iter, disable=quiet, unit="it", file=sys.stderr, leave=False) as bar, \
            threadpool_limits(1, "blas"):
        bar.set_postfix_str("compiling")
        programs = Programs(model, design, independent, limits, design.grid(samples), objective)
        bounds = {"type": "ineq", "fun": lambda x: np.asarray(programs.constraints(x)), "jac": programs.jacobian}
        search = _Search(programs, starts, np.inf if time_budget is None else clock + time_budget, bar)
        runs: list[tuple[bool, float, Array, float, tuple[int, str]]] = []
        while len(runs) < starts and not (runs and search.over()):
            x0 = _start(design, programs, limits, rng)
            f0 = programs.objective(x0)[0]
            search.begin(x0, f0)
            res = scipy.optimize.minimize(programs.objective, x0, jac=True, method="SLSQP", constraints=[bounds],
                                          callback=search.step, options={"maxiter": max_iter, "ftol": FTOL})
            x, f = res.x, float(res.fun)
            if search.out_of_time and search.best is not None:  # cut by the budget: the run's best feasible point
                x, f = search.best, search.best_objective
            bar.update(max_iter - search.iterations[-1])
            exit_message = "time budget" if search.out_of_time else str(res.message)
            runs.append((not programs.feasible(x), f, x, f0, (int(res.status), exit_message)))
    x = min(runs, key=lambda r: (r[0], r[1]))[2]  # feasible first, then the lowest objective
    fine_t = design.grid(FINE * samples)
    fine = envelope(model, design.trajectory(x), fine_t, limits)
    scale = 1.0
    if not fine.met:
        scale = _largest_scale(lambda s: s <= 1 and envelope(model, design.trajectory(_scaled(design, x, s)), fine_t,
                                                               limits).met, hi=1.0)
        if scale > 0:
            x = _scaled(design, x, scale)
            fine = envelope(model, design.trajectory(x), fine_t, limits)
    cond, log_det = score(model, independent, design.trajectory(x), design.grid(samples))
    return Excitation(design, x, objective, samples, cond, log_det, limits, fine, scale, tuple(search.iterations),
                      tuple(r[3] for r in runs), tuple(r[1] for r in runs), tuple(r[4][1] for r in runs), starts,
                      max_iter, None if time_budget is None else float(time_budget),
                      _stopped([r[4] for r in runs], search.out_of_time, max_iter, time_budget),
                      time.perf_counter() - clock)


def before(model: RobotModel, trajectory: Trajectory, t_final: float, design: Design, samples: int,
           limits: Limits) -> dict[str, Any]:
    """A trajectory to compare with the design's (a scenario's own), scored the same way: cond W and log det WᵀW over
    its `horizon` (its period, else `t_final`) at the design's density of `samples` per period, and its
    :class:`Envelope` against the same `limits` on a grid `FINE` times denser."""
    period = getattr(trajectory, "period", None)
    horizon = float(period) if period else float(t_final)
    count = max(samples, int(round(samples * horizon / design.period)))
    grid = horizon * np.arange(count) / count
    cond, log_det = score(model, np.array(base_parameters(model).independent), trajectory, grid)
    fine = envelope(model, trajectory, horizon * np.arange(FINE * count) / (FINE * count), limits)
    return {"cond": cond, "log_det": log_det, "horizon": horizon, "samples": count, **fine.as_dict()}

