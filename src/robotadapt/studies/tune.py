"""Tuning a law's gains by differentiating through the closed loop (`robotadapt tune`, docs/tuning.md).

The gains named by `--vary` are mapped from free parameters θ that keep them positive definite
(:mod:`robotadapt.studies.gain_space`). The objective (`rms_error`, `ise`, `final_error`, `energy` or a weighted sum,
:data:`robotadapt.analysis.metrics.OBJECTIVES`) and the peak torque come from the logged signals of a differentiable
run (:class:`robotadapt.sim.gradient.Rollout`) by the same code that scores a forward run
(:func:`robotadapt.analysis.metrics.objective_terms`); `jax.value_and_grad` gives their gradient in θ. scipy's L-BFGS-B
minimises J(θ)/J(θ₀), within the box of `--vary FIELD=LO:HI` when given.

The torque budget max_{i,t} |τ_i(t)| ≤ T enters through an augmented Lagrangian on the smooth maximum
g(θ) = LSE_β(|τ|/T) − 1 ≤ 0 (log-sum-exp over every sample, β = `SHARPNESS`, never below the true maximum):
L-BFGS-B minimises Ĵ + (max(0, μ + ρ g)² − μ²)/(2ρ), then μ ← max(0, μ + ρ g) and ρ grows while g stays positive. The
answer is the best evaluated θ whose exact peak torque meets the budget (or, when none does, the one with the smallest
peak), checked and scored again by a normal forward run of the tuned scenario — the numbers tune.json reports and
`robotadapt run` reproduces. Robust tuning averages the objective over true-parameter sets drawn in a box (vmapped),
the budget over all of them.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field, fields, is_dataclass, replace
from functools import reduce
from typing import Any, NamedTuple

import numpy as np

from .. import pytree
from ..analysis.metrics import OBJECTIVES, metrics, objective_terms
from ..plant.mujoco import MujocoPlant
from ..sim.gradient import Rollout, check_differentiable
from ..sim.integrators import RK4, Sampled
from ..sim.loop import ClosedLoop
from ..tracing import float64, jax_module
from ..validation import ConfigError
from .gain_space import Gain, Objective, draw_over, locate, parse_objective, split, tuned_scenario
from .scenarios import Scenario

Array = Any
SHARPNESS = 200.0  # β of the smooth maximum LSE_β(|τ|/T): above the true maximum by at most log(samples)/β
DIVERGED = 1e10  # the scaled objective of a run that diverged (the line search steps back)
OUTER = 6  # most augmented-Lagrangian rounds
RHO0 = 100.0  # the first penalty weight ρ (on the objective scaled to 1 at the start)
FORWARD_MODE = 8  # gradients by forward mode up to this many θ entries, by reverse mode beyond
FTOL = 1e-12  # L-BFGS-B stops a round when the scaled objective improves by less than this
AUTO_SURFACE = 9  # points per axis of the surface drawn when exactly two scalar gains are tuned
SCREEN, SPREAD = 64, 10.0  # the batched screen's forward runs, and its range about θ₀ of a gain without a box
WIDTH0, NARROWING = 0.1, 10.0  # a switching law's surrogate: its first width, and the factor of each round after


@dataclass(frozen=True, eq=False)
class Iteration:
    """One optimiser iteration: the objective, the exact peak torque and the gradient norm of what L-BFGS-B minimised,
    at θ; `runs` simulated so far."""

    objective: float
    max_abs_torque: float
    gradient_norm: float
    theta: Array
    runs: int


def closed_loop(scenario: Scenario) -> ClosedLoop:
    """The scenario's closed loop as a run steps it (a law's tables prepared), or a ConfigError when tuning cannot
    differentiate it: not the fixed-step RK4 in continuous time, or a law or model :func:`check_differentiable`
    refuses."""
    s = scenario.setup
    if not isinstance(s.integrator, RK4 | Sampled):
        raise ConfigError("simulation.method", "tuning differentiates fixed steps (RK4, or the sampled-data ticks); "
                          "use method = 'rk4'")
    if isinstance(s.plant, MujocoPlant):
        raise ConfigError("plant.engine", "MuJoCo steps its plant on the host, outside JAX: tune with plant.engine = "
                          "'robotadapt', then check the gains on MuJoCo")
    ctrl = s.controller
    h = s.integrator.control_period if isinstance(s.integrator, Sampled) else s.integrator.dt
    ctrl = ctrl.prepare(s.trajectory, h, s.t_final)
    loop = ClosedLoop(s.plant, ctrl, s.plant.model.n)
    check_differentiable(loop)
    return loop


def switching_parts(obj: Any, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """The paths (from the controller) of the parts of a law that switch or kink — k_d sgn(r) (6.7.6), the σ ramp of
    (6.7.14) — found by their `surrogate(width)` hook: the smooth stand-ins tuning differentiates (module docstring)."""
    if callable(getattr(obj, "surrogate", None)):
        return [path]
    if not is_dataclass(obj) or isinstance(obj, type):
        return []
    return [p for f in fields(obj) if f.name != "model" for p in switching_parts(getattr(obj, f.name), path + (f.name,))]


def smoothed(loop: ClosedLoop, parts: list[tuple[str, ...]], width: Any) -> ClosedLoop:
    """`loop` with each switching part replaced by its surrogate of `width` (traced or not)."""
    for part in parts:
        path = ("controller",) + part
        component: Any = reduce(getattr, path, loop)
        loop = pytree.replace(loop, path, pytree.replace(component.surrogate(1.0), ("width",), width))
    return loop


class Problem:
    """The differentiable objective of a scenario in the varied gains: `evaluate(θ, μ, ρ, width)` → (augmented
    objective, its gradient, the objective, the exact peak torque, whether every run stayed finite), one jitted program.
    For a law that switches (`switching_parts`), the program runs its smooth surrogate of the given width;
    `objectives` always runs the exact law."""

    def __init__(self, scenario: Scenario, gains: list[Gain], objective: Objective, max_torque: float | None,
                 phis: Array | None = None) -> None:
        s = scenario.setup
        self.loop = closed_loop(scenario)
        ctrl = self.loop.controller
        self.gains, self.objective, self.max_torque = gains, objective, max_torque
        self.rollout = Rollout.make(self.loop, s.trajectory, s.integrator, s.t_final, 1)  # every step, as metrics
        seen = (s.q0, s.dq0)
        if isinstance(s.integrator, Sampled) and s.plant.sensor is not None:  # what the law measures first
            seen = s.plant.sensor.first_measurement(s.q0, s.dq0, s.integrator.control_period)
        self.switching = switching_parts(ctrl)
        self.x0 = ctrl.initial_state(*seen)
        self.s0 = s.plant.initial_state(s.q0, s.dq0)
        self.trajectory, self.max_state = s.trajectory, s.max_state
        self.phis = s.plant.phi[None] if phis is None else np.asarray(phis, dtype=float)
        jax = jax_module()
        self.theta0 = np.concatenate([g.theta0() for g in gains])
        self.scale = 1.0  # the objective at θ₀ once known: L-BFGS-B sees J/J(θ₀)
        self.forward_mode = self.theta0.size <= FORWARD_MODE
        self._program = jax.jit(self._forward_mode if self.forward_mode else
                                jax.value_and_grad(self._augmented, has_aux=True))
        self._forward: Any = None

    def admissible(self, theta: Array) -> bool:
        """Whether the law accepts the gains of θ as it accepts a scenario's: its construction-time checks (e.g.
        adaptive computed torque's k_v > ½ for the book's P, (6.2.16)), which the traced program does not run. A point
        outside is scored as a run that failed, so the line search steps back and no such gains are written."""
        ctrl = self.loop.controller
        try:
            for gain, part in zip(self.gains, split(self.gains, theta), strict=True):
                ctrl = _rebuilt(ctrl, gain.path[1:], gain.gain(np.asarray(part, dtype=float)))
        except ConfigError:
            return False
        return True

    def terms(self, theta: Array, phi: Array, width: Array | None = None) -> tuple[dict[str, Array], Array, Array]:
        """The objective terms of one run with the gains of θ and the true φ (traced), |τ_i(t_k)|/T at every sample and
        whether the run stayed finite and within `max_state`; a switching law's surrogate of `width` when given."""
        jnp = jax_module().numpy
        loop = pytree.replace(self.loop, ("plant", "phi"), phi)
        if width is not None and self.switching:
            loop = smoothed(loop, self.switching, width)
        x0 = jnp.asarray(self.x0)
        for gain, part in zip(self.gains, split(self.gains, theta), strict=True):
            g = gain.gain(part)
            loop = pytree.replace(loop, gain.path, g)
            if gain.x0_jacobian is not None:
                x0 = x0 + gain.x0_jacobian @ (jnp.reshape(g, (-1,)) - np.reshape(gain.initial, (-1,)))
        t, e, tau, ok = self.rollout.scores(loop, jnp.concatenate([jnp.asarray(self.s0), x0]), self.max_state)
        values = objective_terms(t, e, tau)
        return values, jnp.abs(tau) / (self.max_torque or 1.0), ok

    def _augmented(self, theta: Array, mu: Array, rho: Array, scale: Array,
                   width: Array) -> tuple[Array, tuple[Array, ...]]:
        jax = jax_module()
        jnp = jax.numpy
        values, ratio, ok = jax.vmap(lambda phi: self.terms(theta, phi, width))(self.phis)
        objective = jnp.mean(self.objective.value(values))
        g = jax.scipy.special.logsumexp(SHARPNESS * ratio) / SHARPNESS - 1.0  # over every sample of every run
        penalty = (jnp.maximum(0.0, mu + rho * g) ** 2 - mu**2) / (2.0 * rho) if self.max_torque else 0.0 * g
        return objective / scale + penalty, (objective, jnp.max(values["max_abs_torque"]), g, jnp.all(ok))

    def _forward_mode(self, *args: Array) -> tuple[tuple[Array, tuple[Array, ...]], Array]:
        """`value_and_grad` of the augmented objective by forward mode (the θ entries' tangents carried through the run
        with it, vmapped): for few gains about half the time of reverse mode through the checkpointed blocks
        (docs/tuning.md#how), and no stored blocks."""
        jax = jax_module()

        def with_value(theta: Array, *rest: Array) -> tuple[Array, tuple[Array, tuple[Array, ...]]]:
            value, aux = self._augmented(theta, *rest)
            return value, (value, aux)

        grad, out = jax.jacfwd(with_value, has_aux=True)(*args)
        return out, grad

    @float64
    def objectives(self, thetas: Array) -> tuple[Array, Array]:
        """The objective (mean over the true-parameter sets) and the exact peak torque at each row of `thetas`
        `(k, size)`, forward only (vmapped); NaN where a run diverged."""
        jax = jax_module()
        jnp = jax.numpy
        if self._forward is None:
            def one(theta: Array) -> tuple[Array, Array]:
                values, ratio, ok = jax.vmap(lambda phi: self.terms(theta, phi))(self.phis)
                bad = ~jnp.all(ok)
                return (jnp.where(bad, jnp.nan, jnp.mean(self.objective.value(values))),
                        jnp.where(bad, jnp.nan, jnp.max(values["max_abs_torque"])))

            self._forward = jax.jit(jax.vmap(one))
        objective, peak = self._forward(np.asarray(thetas, dtype=float))
        return np.asarray(objective), np.asarray(peak)

    @float64
    def evaluate(self, theta: Array, mu: float = 0.0, rho: float = 1.0,
                 width: float = WIDTH0) -> tuple[float, Array, float, float, float, bool]:
        """(scaled augmented objective, its gradient, objective, exact peak torque, smooth constraint g, finite); of the
        surrogate of `width` for a switching law."""
        (value, (objective, peak, g, ok)), grad = self._program(np.asarray(theta, dtype=float), mu, rho, self.scale,
                                                                width)
        return float(value), np.asarray(grad), float(objective), float(peak), float(g), bool(ok)


    @float64
    def peak_elasticity(self, theta: Array) -> dict[str, float]:
        """∂ ln(max |τ|) / ∂ ln(gain) at θ for every tuned entry (θ holds the log gains), the peak smoothed as the
        budget's constraint is (log-sum-exp over every sample of every run): which gain drives the peak, and how hard
        (0.8: 10 % less of it, about 8 % less peak)."""
        jax = jax_module()

        def log_peak(theta: Array) -> Array:
            _, ratio, _ = jax.vmap(lambda phi: self.terms(theta, phi))(self.phis)
            return jax.numpy.log(jax.scipy.special.logsumexp(SHARPNESS * ratio) / SHARPNESS)

        grad = np.asarray(jax.grad(log_peak)(np.asarray(theta, dtype=float)))
        names = [g.field if g.size == 1 else f"{g.field}[{i}]" for g in self.gains for i in range(g.size)]
        return {name: float(v) for name, v in zip(names, grad, strict=True)}


def _rebuilt(obj: Any, path: tuple[str, ...], value: Any) -> Any:
    """`obj` with the field at `path` set to `value` by `dataclasses.replace` along the path: constructed again, so
    with the law's checks (a ConfigError), unlike :func:`~robotadapt.pytree.replace`."""
    inner = value if len(path) == 1 else _rebuilt(getattr(obj, path[0]), path[1:], value)
    return replace(obj, **{path[0]: inner})


class _OutOfRuns(Exception):
    pass


class Evaluation(NamedTuple):
    """One evaluated θ: the objective and the exact peak torque there, and the seconds since the search began."""

    theta: Array
    objective: float
    peak: float
    seconds: float


@dataclass(eq=False)
class Search:
    """The optimiser's state: every evaluation (θ, objective, peak torque), the iterations and the run count."""

    problem: Problem
    max_runs: int
    bar: Any
    runs: int = 0
    iterations: list[Iteration] = field(default_factory=list)
    evaluated: list[Evaluation] = field(default_factory=list)
    seen: dict[bytes, tuple[float, float, float, float]] = field(default_factory=dict)  # θ → J, peak, ‖∇‖, g
    rescored: int = 0  # forward runs of the exact law that scored a switching law's evaluations again
    screened: int = 0  # forward runs of the batched screen that chose the start
    began: float = field(default_factory=time.perf_counter)
    last: tuple[Any, float, Array] | None = None  # (θ, μ, ρ, width, scale), value, gradient of the last evaluation
    converged: bool = False  # the last round ended by L-BFGS-B's own test, not by --max-runs

    def fun(self, theta: Array, mu: float, rho: float, width: float) -> tuple[float, Array]:
        """The scaled augmented objective and its gradient at θ (one run per true-parameter set; a switching law's
        surrogate of `width`); the last point asked again (a round's start) costs no run."""
        key = (np.asarray(theta, dtype=float).tobytes(), mu, rho, width, self.problem.scale)
        if self.last is not None and self.last[0] == key:
            return self.last[1], self.last[2].copy()
        if self.runs + len(self.problem.phis) > self.max_runs:
            raise _OutOfRuns
        if not self.problem.admissible(theta):
            return DIVERGED, np.zeros_like(theta)
        value, grad, objective, peak, g, ok = self.problem.evaluate(theta, mu, rho, width)
        self.runs += len(self.problem.phis)
        self.bar.update(len(self.problem.phis))
        if not (ok and np.isfinite(value)):
            return DIVERGED, np.zeros_like(theta)
        self.evaluated.append(Evaluation(np.array(theta), objective, peak, time.perf_counter() - self.began))
        with np.errstate(over="ignore"):  # a gradient near divergence may overflow its norm
            self.seen[np.asarray(theta).tobytes()] = (objective, peak, float(np.linalg.norm(grad)), g)
        self.last = (key, value, grad)
        return value, grad.copy()

    def record(self, theta: Array) -> None:
        """The callback of each L-BFGS-B iteration: log the iterate."""
        hit = self.seen.get(np.asarray(theta).tobytes())
        if hit is not None:
            self.iterations.append(Iteration(*hit[:3], np.array(theta), self.runs))

    def constraint(self, theta: Array) -> float:
        """The smooth constraint g at an evaluated θ (+inf if it diverged)."""
        hit = self.seen.get(np.asarray(theta).tobytes())
        return np.inf if hit is None else hit[3]

    def rescore(self) -> None:
        """A switching law's evaluations scored again by forward runs of the exact law (vmapped): the surrogate only
        guided the search, the answer is chosen on the law itself; θ whose exact run diverges are dropped."""
        if not (self.problem.switching and self.evaluated):
            return
        objective, peak = self.problem.objectives(np.stack([e.theta for e in self.evaluated]))
        self.rescored = len(self.evaluated) * len(self.problem.phis)
        self.evaluated = [e._replace(objective=float(j), peak=float(p))
                          for e, j, p in zip(self.evaluated, objective, peak, strict=True) if np.isfinite(j)]

    def screen(self, thetas: Array) -> Array:
        """The batched screen (forward runs of the exact law, vmapped): every row of `thetas` scored, kept as an
        evaluation; returns the row of least objective within the budget, else of least peak torque."""
        thetas = np.array([th for th in thetas if self.problem.admissible(th)] or thetas[:1])
        objective, peak = self.problem.objectives(thetas)
        self.screened = thetas.shape[0] * len(self.problem.phis)
        now = time.perf_counter() - self.began
        found = [Evaluation(th, float(j), float(p), now) for th, j, p in zip(thetas, objective, peak, strict=True)
                 if np.isfinite(j)]
        self.evaluated.extend(found)
        chosen = _chosen(found, self.problem.max_torque)
        return thetas[0] if chosen is None else chosen.theta

    def reached(self, objective: float, budget: float | None) -> Evaluation | None:
        """The first evaluation within the budget whose objective is at most `objective` (benchmarks)."""
        return next((e for e in self.evaluated if e.objective <= objective and (budget is None or e.peak <= budget)),
                    None)

    def best(self, budget: float | None) -> Array:
        """The evaluated θ of least objective that meets the budget exactly, else the one of least peak torque."""
        chosen = _chosen(self.evaluated, budget)
        return self.problem.theta0 if chosen is None else chosen.theta


def _chosen(evaluations: list[Evaluation], budget: float | None) -> Evaluation | None:
    """The evaluation of least objective whose exact peak torque meets the budget, else the one of least peak."""
    fits = [e for e in evaluations if budget is None or e.peak <= budget]
    if fits:
        return min(fits, key=lambda e: e.objective)
    return min(evaluations, key=lambda e: e.peak) if evaluations else None


def screen_points(problem: Problem, count: int, seed: int = 0) -> Array:
    """`count` rows of θ for the batched screen: θ₀ (clipped into the boxes) first, then a Latin hypercube over each
    entry's box, or over ±ln `SPREAD` around θ₀ for an unboxed log gain (a Cholesky factor's off-diagonal entries stay)."""
    from scipy.stats import qmc

    lo: list[float] = []
    hi: list[float] = []
    spread: list[float] = []
    for g in problem.gains:
        logs = np.ones(g.size, bool) if g.form != "matrix" else np.equal(*np.tril_indices(g.dim))
        for (a, b), is_log in zip(g.bounds(), logs, strict=True):
            lo.append(-np.inf if a is None else a)
            hi.append(np.inf if b is None else b)
            spread.append(np.log(SPREAD) if is_log else 0.0)
    lower, upper, half = np.array(lo), np.array(hi), np.array(spread)
    theta0 = np.clip(problem.theta0, lower, upper)
    boxed = np.isfinite(lower) & np.isfinite(upper)
    start, end = np.where(boxed, lower, theta0 - half), np.where(boxed, upper, theta0 + half)
    unit = qmc.LatinHypercube(d=theta0.size, seed=seed).random(max(count - 1, 0))
    return np.vstack([theta0, start + unit * (end - start)])


def optimise(problem: Problem, max_runs: int, progress: bool = False, screen: int = SCREEN) -> Search:
    """A batched screen of `screen` forward runs chooses the start (none for `screen` ≤ 1); then L-BFGS-B on the scaled
    objective, with a budget in augmented-Lagrangian rounds (module docstring)."""
    from scipy.optimize import minimize
    from tqdm import tqdm

    bounds = [b for g in problem.gains for b in g.bounds()]
    quiet = not (progress and sys.stderr.isatty())
    with tqdm(total=max_runs, disable=quiet, unit="run", file=sys.stderr, leave=False) as bar:
        search = Search(problem, max_runs, bar)
        points = screen_points(problem, max(screen, 1))
        theta = search.screen(points) if screen > 1 else points[0]
        mu, rho, width = 0.0, RHO0, WIDTH0
        rounds = OUTER if problem.max_torque or problem.switching else 1
        try:
            known = [e.objective for e in search.evaluated if np.array_equal(e.theta, theta)]
            if not known or problem.switching:  # the scale is the start's objective (the surrogate's for a switching law)
                before = len(search.evaluated)
                search.fun(theta, mu, rho, width)
                known = [search.evaluated[-1].objective] if len(search.evaluated) > before else [1.0]
            problem.scale = known[0] if np.isfinite(known[0]) and known[0] > 0 else 1.0
            search.record(theta)
            for k in range(rounds):
                left = max_runs - search.runs  # a switching law's rounds share the runs: each narrows the surrogate
                out = minimize(search.fun, theta, args=(mu, rho, width), jac=True, method="L-BFGS-B", bounds=bounds,
                               callback=search.record,
                               options={"maxfun": max(1, left // (rounds - k) if problem.switching else left),
                                        "gtol": 1e-9, "ftol": FTOL})
                theta, g = out.x, search.constraint(out.x)
                search.converged = bool(out.success)
                met = problem.max_torque is None or (g <= 1e-4 and abs(mu * g) < 1e-4)
                if met and not problem.switching:
                    break
                if not met:
                    mu, rho = max(0.0, mu + rho * g), rho * (10.0 if g > 0 else 1.0)
                width /= NARROWING
        except _OutOfRuns:
            search.converged = False
    search.rescore()
    return search


@dataclass(frozen=True, eq=False)
class Score:
    """A forward run (or one per true-parameter set) of a scenario, scored: the objective (mean over the sets), its
    terms, the exact peak torque (max over the sets), the statuses, and the nominal run."""

    objective: float
    terms: dict[str, float]
    max_abs_torque: float
    ok: bool
    result: Any
    per_sample: list[float]


def score(scenario: Scenario, objective: Objective, phis: Array | None = None) -> Score:
    """Score the scenario by normal forward runs (the default engine, as `robotadapt run`): the numbers tune.json
    reports."""
    runs = [scenario] if phis is None else [tuned_scenario(scenario, [], np.zeros(0), phi) for phi in phis]
    rows = []
    nominal = scenario.run()
    for s in runs:
        res = nominal if s is scenario else s.run()
        with np.errstate(all="ignore"):  # a diverged run's last samples may overflow
            m = metrics(res)
        rows.append((objective.of_metrics(m), {k: m[v] for k, v in OBJECTIVES.items()}, max(m["max_abs_torque"]),
                     res.ok))
    values = [r[0] for r in rows]
    terms = {k: float(np.mean([r[1][k] for r in rows])) for k in OBJECTIVES}
    return Score(float(np.mean(values)), terms, float(max(r[2] for r in rows)), all(r[3] for r in rows), nominal,
                 values)


@dataclass(frozen=True, eq=False)
class Tuned:
    """What `robotadapt tune` found: the tuned scenario and gains, its score and the starting one, the iterations, the
    runs simulated and the wall time; `feasible` when the final forward runs meet the budget."""

    scenario: Scenario
    objective: Objective
    gains: list[Gain]
    theta: Array
    before: Score
    after: Score
    search: Search
    max_torque: float | None
    over: Array | None
    wall_time: float  # the tuning, the surface apart
    surface: Surface | None

    @property
    def peak_elasticity(self) -> dict[str, float] | None:
        """Where the budget is not met: ∂ ln max|τ| / ∂ ln gain at the answer (:meth:`Problem.peak_elasticity`)."""
        return None if self.feasible or self.max_torque is None else self.search.problem.peak_elasticity(self.theta)

    @property
    def forward_runs(self) -> int:
        """The forward runs: the batched screen, those that scored the start and the answer (one per true-parameter set
        each) and, for a switching law, its evaluations scored again on the exact law."""
        return len(self.before.per_sample) + len(self.after.per_sample) + self.search.rescored + self.search.screened

    @property
    def feasible(self) -> bool:
        return self.after.ok and (self.max_torque is None or self.after.max_abs_torque <= self.max_torque)

    def summary(self) -> dict[str, Any]:
        """tune.json: objective, max_abs_torque, gains, iterations (objective, constraint, gradient norm), wall_time;
        `runs` counts every simulation: `differentiated_runs` (what --max-runs bounds, what the figure counts) and
        `forward_runs`, the normal runs that score the start and the answer; `converged` the search ended by its own
        test with an answer within the budget (`search_converged`: by its own test, whatever the budget)."""
        return {
            "scenario": self.scenario.name, "objective": self.after.objective, "objective_expression": self.objective.text,
            "terms": self.after.terms, "max_abs_torque": self.after.max_abs_torque, "max_torque": self.max_torque,
            "feasible": self.feasible,
            "gains": {g.field: g.value(part) for g, part in zip(self.gains, split(self.gains, self.theta), strict=True)},
            "initial": {"objective": self.before.objective, "max_abs_torque": self.before.max_abs_torque,
                        "gains": {g.field: g.value(g.theta0()) for g in self.gains}},
            "iterations": [{"objective": it.objective, "max_abs_torque": it.max_abs_torque,
                            "gradient_norm": it.gradient_norm, "runs": it.runs} for it in self.search.iterations],
            "runs": self.search.runs + self.forward_runs,
            "differentiated_runs": self.search.runs, "forward_runs": self.forward_runs,
            "screened_runs": self.search.screened,
            "converged": bool(self.search.converged and self.feasible),  # ended by its own test, within the budget
            "search_converged": self.search.converged,
            "peak_elasticity": self.peak_elasticity,
            "over": None if self.over is None else {"plant.phi": self.over.tolist(),
                                                    "objective_per_sample": self.after.per_sample},
            "wall_time": self.wall_time,
            "surface": None if self.surface is None else {
                "x": {self.surface.x_field: self.surface.x.tolist()}, "y": {self.surface.y_field: self.surface.y.tolist()},
                "objective": self.surface.objective.tolist(), "max_abs_torque": self.surface.max_abs_torque.tolist()},
        }


def tune(scenario: Scenario, vary: list[str], objective: str, max_torque: float | None = None, *,
         over: str | None = None, samples: int = 8, seed: int = 0, max_runs: int = 100,
         surface_points: int | None = None, progress: bool = False, screen: int = SCREEN) -> Tuned:
    """Tune the gains `vary` names to minimise `objective` under the torque budget `max_torque` (N·m or N), over
    `samples` true-parameter sets drawn in the box `over` when given; at most `max_runs` differentiated runs. With
    `surface_points` K > 0, the objective over a K × K grid of the first two scalar gains (:func:`surface`, checked
    before the search); None: `AUTO_SURFACE` when exactly two scalar gains are tuned, else none."""
    wall = time.perf_counter()
    if not vary:
        raise ConfigError("--vary", "name at least one gain to tune, e.g. --vary controller.Kv")
    if max_torque is not None and not (np.isfinite(max_torque) and max_torque > 0):
        raise ConfigError("--max-torque", f"must be a positive number of N·m, got {max_torque!r}")
    if isinstance(max_runs, bool) or max_runs < 2:
        raise ConfigError("--max-runs", f"must be at least 2, got {max_runs!r}")
    goal = parse_objective(objective)
    closed_loop(scenario)
    gains = [locate(scenario, spec) for spec in vary]
    fields = [g.field for g in gains]
    if len(set(fields)) < len(fields):
        raise ConfigError("--vary", f"a gain is named twice: {', '.join(fields)}")
    if surface_points is None:
        surface_points = AUTO_SURFACE if len(gains) == 2 and all(g.form == "scalar" for g in gains) else 0
    if surface_points:
        surface_axes(gains, surface_points)
    phis = None if over is None else draw_over(scenario, over, samples, seed)[1]
    problem = Problem(scenario, gains, goal, max_torque, phis)
    before = score(scenario, goal, phis)
    search = optimise(problem, max_runs, progress, screen)
    theta = search.best(max_torque)
    tuned = tuned_scenario(scenario, gains, theta)
    after = score(tuned, goal, phis)
    wall = time.perf_counter() - wall
    grid = surface(problem, search, theta, surface_points) if surface_points else None
    return Tuned(tuned, goal, gains, theta, before, after, search, max_torque, phis, wall, grid)


@dataclass(frozen=True, eq=False)
class Surface:
    """The objective and the exact peak torque over a grid of two scalar gains (the others at their tuned values):
    `x` (k,) and `y` (k,) the gains' values, `objective`, `max_abs_torque` (k, k) indexed [x, y]; `i`, `j` their
    entries in θ."""

    x_field: str
    y_field: str
    i: int
    j: int
    x: Array
    y: Array
    objective: Array
    max_abs_torque: Array


def surface_axes(gains: list[Gain], points: int) -> list[int]:
    """The indices of the scalar gains a surface of `points` × `points` can be drawn over, or a ConfigError."""
    scalars = [k for k, g in enumerate(gains) if g.form == "scalar"]
    if len(scalars) < 2:
        raise ConfigError("--surface", "needs two scalar gains among --vary (e.g. controller.Kv and controller.Lam)")
    if isinstance(points, bool) or points < 2:
        raise ConfigError("--surface", f"needs at least 2 points per axis, got {points!r}")
    return scalars


def surface(problem: Problem, search: Search, theta: Array, points: int) -> Surface:
    """The tuning surface over the first two scalar gains: a log grid of `points` × `points` over their box (else a
    decade around the path), points² forward runs in vmapped rows."""
    scalars = surface_axes(problem.gains, points)
    offsets = np.cumsum([0] + [g.size for g in problem.gains])
    (a, b), grids = scalars[:2], []
    path = np.array([it.theta for it in search.iterations] + [theta, problem.theta0])
    for k in (a, b):
        g, col = problem.gains[k], offsets[k]
        lo, hi = (np.log(g.lower[0]), np.log(g.upper[0])) if g.lower is not None and g.upper is not None else (
            path[:, col].min() - np.log(3.0), path[:, col].max() + np.log(3.0))
        grids.append(np.linspace(lo, hi, points))
    objective, peak = np.empty((points, points)), np.empty((points, points))
    for row, u in enumerate(grids[0]):
        thetas = np.tile(theta, (points, 1))
        thetas[:, offsets[a]], thetas[:, offsets[b]] = u, grids[1]
        objective[row], peak[row] = problem.objectives(thetas)
    return Surface(problem.gains[a].field, problem.gains[b].field, int(offsets[a]), int(offsets[b]),
                   np.exp(grids[0]), np.exp(grids[1]), objective, peak)
