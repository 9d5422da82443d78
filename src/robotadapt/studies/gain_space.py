"""The gains a tuning varies (`robotadapt tune`, docs/tuning.md): the objectives, the parametrisation that keeps every
gain positive definite, and the checks that a scenario field is a gain the closed loop can be differentiated in.

A scalar gain k = exp θ, a diagonal one diag(exp θ_i), a full matrix L Lᵀ with L lower triangular and log-parametrised
diagonal (Cholesky): every θ gives a symmetric positive definite gain, and L-BFGS-B needs no constraint for it (a box
`--vary FIELD=LO:HI` on a scalar or diagonal gain is a box on θ).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields, is_dataclass
from functools import reduce
from typing import Any, NamedTuple

import numpy as np

from .. import pytree
from ..analysis.metrics import OBJECTIVES
from ..tracing import jax_module
from ..validation import ConfigError
from .scenarios import Scenario
from .scenarios.build import setup
from .scenarios.loader import assignment, override
from .sweep import parse_random

Array = Any


class Objective(NamedTuple):
    """A weighted sum Σ w_k J_k of the objectives of :data:`OBJECTIVES`; `text` as given."""

    text: str
    terms: tuple[tuple[float, str], ...]

    def value(self, values: dict[str, Any]) -> Any:
        return sum(w * values[name] for w, name in self.terms)

    def of_metrics(self, m: dict[str, Any]) -> float:
        """The objective from a run's :func:`robotadapt.analysis.metrics.metrics` (what `robotadapt run` writes)."""
        return float(sum(w * m[OBJECTIVES[name]] for w, name in self.terms))


def parse_objective(text: str) -> Objective:
    """`rms_error`, `ise`, `final_error`, `energy`, or a weighted sum of them such as `rms_error+1e-6*energy`."""
    terms = []
    for part in text.replace(" ", "").split("+"):
        weight, star, name = part.rpartition("*")
        try:
            w = float(weight) if star else 1.0
        except ValueError:
            w = float("nan")
        if name not in OBJECTIVES or not (np.isfinite(w) and w > 0):
            raise ConfigError("--objective", f"unknown objective {text!r}; use {', '.join(OBJECTIVES)} or a weighted "
                              "sum with positive weights such as rms_error+1e-6*energy")
        terms.append((w, name))
    return Objective(text, tuple(terms))


def _box(option: str, spec: str) -> tuple[str, Any, Any]:
    """`section.key=LO:HI` parsed as a sweep's random axis (:func:`robotadapt.studies.sweep.parse_random`), errors
    naming `option`."""
    try:
        return parse_random(spec)
    except ConfigError as exc:
        raise ConfigError(option, exc.reason) from None


def _lookup(data: dict[str, Any], key: str) -> Any:
    node: Any = data
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


@dataclass(frozen=True, eq=False)
class Gain:
    """One varied gain: its scenario field, the attribute path in the closed loop, its form (`scalar`, `diagonal`,
    `matrix`), its size, the box of its entries (scalar, diagonal) and the affine map of the law's initial state in it
    (x0 = x0_0 + J vec(G − G0), zero for most laws; the composite law's P(0) = P0)."""

    field: str
    path: tuple[str, ...]
    form: str
    dim: int
    initial: Array  # the gain as the law holds it (a float for a scalar law field, else an n×n matrix)
    lower: Array | None = None  # box of the entries, (size,)
    upper: Array | None = None
    x0_jacobian: Array | None = None  # (s, size of vec(G))

    @property
    def size(self) -> int:
        return {"scalar": 1, "diagonal": self.dim, "matrix": self.dim * (self.dim + 1) // 2}[self.form]

    def theta0(self) -> Array:
        g = np.atleast_2d(self.initial)
        if self.form == "scalar":
            return np.log([g[0, 0]])
        if self.form == "diagonal":
            return np.log(np.diag(g))
        L = np.linalg.cholesky(g)
        L[np.diag_indices(self.dim)] = np.log(np.diag(L))
        return L[np.tril_indices(self.dim)]

    def gain(self, theta: Array) -> Array:
        """The gain as the law holds it, from θ (numpy or JAX): exp, diag(exp), or L Lᵀ."""
        xp = jax_module().numpy if not isinstance(theta, np.ndarray) else np
        if self.form == "scalar":
            k = xp.exp(theta[0])
            return k if np.ndim(self.initial) == 0 else k * xp.eye(self.dim)
        if self.form == "diagonal":
            return xp.diag(xp.exp(theta))
        rows, cols = np.tril_indices(self.dim)
        entries = xp.where(rows == cols, xp.exp(theta), theta)
        L = xp.zeros((self.dim, self.dim)).at[rows, cols].set(entries) if xp is not np else _tril(entries, self.dim)
        return L @ L.T

    def value(self, theta: Array) -> Any:
        """The gain as the scenario writes it: a number, a list (the diagonal) or a matrix."""
        g = np.asarray(self.gain(np.asarray(theta, dtype=float)), dtype=float)
        if self.form == "scalar":
            return readable(float(np.exp(theta[0])))
        return [readable(v) for v in np.diag(g)] if self.form == "diagonal" else [[readable(v) for v in row] for row in g]

    def bounds(self) -> list[tuple[float | None, float | None]]:
        if self.lower is None or self.upper is None:
            return [(None, None)] * self.size
        return [(float(np.log(lo)), float(np.log(hi))) for lo, hi in zip(self.lower, self.upper, strict=True)]


def _tril(entries: Array, n: int) -> Array:
    L = np.zeros((n, n))
    L[np.tril_indices(n)] = entries
    return L


def _form(value: Any, field_name: str) -> str:
    shape = np.shape(value) if isinstance(value, int | float | list) and not isinstance(value, bool) else None
    if shape is None or len(shape) > 2 or (len(shape) == 2 and shape[0] != shape[1]):
        raise ConfigError(field_name, f"is not a gain (a positive number, a diagonal list or an SPD matrix), got "
                          f"{value!r}; tune controller gains such as controller.Kv, controller.Lam, controller.Gamma")
    return ("scalar", "diagonal", "matrix")[len(shape)]


def _comparable(controller: Any, path: tuple[str, ...]) -> tuple[Any, list[Array]]:
    """A fresh controller less its models and the gain at `path`, as (structure, leaves) of its fields
    (:func:`robotadapt.pytree.flatten` without the derived constants, which a traced gain recomputes): two builds that
    differ only in that gain compare equal unless the law derives other fields from it at construction."""

    def blank(obj: Any, at: tuple[str, ...]) -> Any:
        if is_dataclass(obj) and not isinstance(obj, type):
            for f in fields(obj):
                inner = at[1:] if at[:1] == (f.name,) else ()
                value = None if at == (f.name,) or f.name == "model" else blank(getattr(obj, f.name), inner)
                obj = pytree.replace(obj, (f.name,), value)
        return obj

    leaves, structure = pytree.flatten(blank(controller, path), with_derived=False)
    return structure, leaves


def locate(scenario: Scenario, spec: str) -> Gain:
    """The gain `--vary` names (`controller.Kv` or `controller.Kv=LO:HI`), checked: it is a gain of the law, the law
    uses it as it is (no other constant of the law is derived from it) and its initial state is affine in it."""
    name, _, box = spec.partition("=")
    name = name.strip()
    data = scenario.setup.data
    value = _lookup(data, name)
    parts = name.split(".")
    if parts[0] != "controller" or len(parts) < 2 or value is None:
        keys = ", ".join(f"controller.{k}" for k, v in data["controller"].items() if k != "kind" and v is not None)
        raise ConfigError("--vary", f"{name!r} is not a gain of the scenario's controller; its keys: {keys}")
    form = _form(value, name)
    ctrl = scenario.setup.controller
    owner = reduce(lambda obj, key: getattr(obj, key, None), parts[1:-1], ctrl)
    why = getattr(type(owner), "untuned", {}).get(parts[-1])  # a law's own reason not to tune a constant
    if why:
        raise ConfigError(name, why)
    attr = getattr(owner, parts[-1], None)
    if not (isinstance(attr, float) or (isinstance(attr, np.ndarray) and attr.ndim in (0, 2))):
        raise ConfigError(name, "is not a gain the law holds as a number or a matrix")
    if not (np.all(np.linalg.eigvalsh(np.atleast_2d(attr)) > 0)):
        raise ConfigError(name, f"is not positive definite ({value!r}): only positive gains are tuned")
    lower = upper = None
    if box:
        if form == "matrix":
            raise ConfigError("--vary", f"{name}: a box applies to a scalar or diagonal gain, not a full matrix")
        _, lo, hi = _box("--vary", f"{name}={box}")
        size = 1 if form == "scalar" else len(value)
        lower, upper = np.broadcast_to(lo, (size,)).astype(float), np.broadcast_to(hi, (size,)).astype(float)
        if not np.all(lower > 0):
            raise ConfigError("--vary", f"{name}: a gain's box must be positive, got {box}")
    gain = Gain(name, tuple(parts), form, int(np.atleast_2d(attr).shape[0]), attr, lower, upper)
    return _checked(scenario, gain, value)


def _checked(scenario: Scenario, gain: Gain, value: Any) -> Gain:
    """Refuse a gain whose change alters other constants of the law; add the affine map of the initial state in it."""
    trial = copy.deepcopy(scenario.data)
    theta = gain.theta0()
    nudged = gain.value(theta + 0.1 * (1.0 + np.arange(theta.size)) / theta.size)  # unequal: a scalar-valued list varies
    override(trial, assignment(gain.field, nudged))
    other = setup(trial).controller
    a, b = _comparable(other, gain.path[1:]), _comparable(setup(copy.deepcopy(scenario.data)).controller, gain.path[1:])
    if a[0] != b[0] or not all(np.array_equal(x, y) for x, y in zip(a[1], b[1], strict=True)):
        raise ConfigError(gain.field, "the law derives other constants from this gain, so it cannot be differentiated "
                          "as one; tune another gain")
    s, ctrl = scenario.setup, scenario.setup.controller

    def x0(g: Array) -> Array:
        return np.asarray(pytree.replace(ctrl, gain.path[1:], g).initial_state(s.q0, s.dq0), dtype=float)

    base, flat = x0(gain.initial), np.asarray(gain.initial, dtype=float).reshape(-1)

    def unit(k: int) -> Array:  # e_k, one at a time: Γ of the Panda has 4900 entries
        e = np.zeros(flat.size)
        e[k] = 1.0
        return e

    columns = [x0(np.reshape(flat + unit(k), np.shape(gain.initial))) - base for k in range(flat.size)]
    jac = np.stack(columns, axis=-1)
    if not np.any(jac):
        return gain
    step = np.random.default_rng(0).normal(size=flat.size)
    if not np.allclose(x0(np.reshape(flat + step, np.shape(gain.initial))) - base, jac @ step, rtol=1e-9, atol=1e-12):
        raise ConfigError(gain.field, "the law's initial state depends on this gain non-linearly; tune another gain")
    return Gain(gain.field, gain.path, gain.form, gain.dim, gain.initial, gain.lower, gain.upper, jac)


def draw_over(scenario: Scenario, spec: str, samples: int, seed: int) -> tuple[str, Array]:
    """`--over plant.phi=LO:HI`: `samples` true-parameter sets drawn uniformly in the box, `(samples, p)`."""
    key, lo, hi = _box("--over", spec)
    if key != "plant.phi":
        raise ConfigError("--over", f"robust tuning draws the true parameters: plant.phi=LO:HI, got {key!r}")
    if isinstance(samples, bool) or samples < 1:
        raise ConfigError("--samples", f"must be a positive whole number, got {samples!r}")
    for bound in (lo, hi):
        try:
            scenario.variant(assignment(key, bound))
        except ConfigError as exc:
            raise ConfigError("--over", f"{key}={bound!r} does not build: {exc}") from None
    p = scenario.setup.plant.phi.size
    rng = np.random.default_rng(seed)
    return key, rng.uniform(np.broadcast_to(lo, (p,)), np.broadcast_to(hi, (p,)), size=(samples, p))


def readable(value: float) -> float:
    """`value` to 12 significant digits: exp(log 50) is written 50, not 49.99999999999999 (a change of 1e-12 relative,
    far inside what a gain can matter)."""
    return float(f"{float(value):.12g}")


def tuned_scenario(scenario: Scenario, gains: list[Gain], theta: Array, phi: Array | None = None) -> Scenario:
    """The scenario with the gains of θ (and the true parameters `phi`, when given)."""
    data = copy.deepcopy(scenario.data)
    data.pop("study", None)
    for gain, part in zip(gains, split(gains, theta), strict=True):
        override(data, assignment(gain.field, gain.value(part)))
    if phi is not None:
        override(data, assignment("plant.phi", [float(v) for v in phi]))
    return Scenario(scenario.name, data, setup(data))


def split(gains: list[Gain], theta: Array) -> list[Array]:
    """θ cut into each gain's part."""
    edges = np.cumsum([0] + [g.size for g in gains])
    return [theta[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]
