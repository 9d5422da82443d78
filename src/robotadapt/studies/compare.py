"""The comparison of every law of chapters 6–7 on one scenario's arm, trajectory and disturbance (`robotadapt compare`):
the lineup, and one row of metrics per law (tables only; :mod:`robotadapt.report.html` draws and writes the report).

**The reference.** The scenario's own controller runs exactly as the scenario gives it, in place of the lineup entry of
the same kinds (or as the entry "scenario" when none matches); its row says so (`reference`, and its source).

**The lineup.** Each law declares its entries in its own class (`lineup`, :mod:`robotadapt.controllers.registry`),
with the book's gains, chosen for the book's two-link arm (λ_max M(0) = 12.15 kg m² at Example 6.3.1's start), and
its place (`rank`); :func:`contenders` gathers them in that order. On the scenario's arm every other law takes

1. from the scenario's law each gain that plays the same part there, when both laws are of one `family`: Γ of a
   gradient update φ̂̇ = Γ(·)ᵀr (Tables 6.3.1, 6.4.1, 7.2.1); Λ, K_v, Ψ, … of the chapter-6 laws ("6"), whose
   r = ė + Λe (6.3.8), (6.4.2); K_v, K_p, k_a, k_L of the §7.2 laws ("7.2"), whose r = ė + e (7.2.6); computed torque's
   laws share none. PD's K_p is K_v Λ of what it got (Λ of Example 6.3.1 unless the scenario has one);
2. every other gain the book's times s^k: s the arm's scale, k the power of the inertia the gain's unit carries (the
   law's `powers`): 1 for torque gains (K_v, K_p, k_a, k_L, k_d) and adaptation gains (Γ, P(0), K_I, F_p: φ scales as
   M, the regressor does not) and for the projection box of Table 6.2.1; 2 for adaptive computed torque's Γ ((6.2.19)
   carries M̂⁻¹); 0 for rates (Λ, Ψ, a) and computed torque's K_p, K_v (they act through M̂, (6.2.2), (6.2.5)). The
   scale is s = λ_min(K_v) / k_v,book when the scenario's law has a K_v on r (k_v,book: the K_v of the family's entry
   with a `book_kv`, 10 of Example 6.3.1 for the chapter-6 laws, 50 of Examples 7.2.1–7.2.2 for §7.2; λ_min, the rate
   of (6.3.17), so that no joint gets a larger factor than the scenario gives it), else λ_max M(q0) / 12.15, the arm's
   inertia at its start over the book arm's. (k_d must also exceed the scenario's disturbance, (6.7.8): not checked.)

So on an arm whose M, V_m, G are s times the book arm's, with the scenario's K_v, Γ and φ̂(0) s times the book's, every
law but composite adaptation (whose one P weighs a torque error and r alike, (6.6.28)) gives the book's e(t); on the
book's arm s = 1 and the lineup is the book's. Each row's source names what was taken and what scaled, and by what s.

**One initial estimate.** Every law with an estimate starts from the scenario's law's φ̂(0) (0 when it has none, the
default of `phi_hat0`; the rows say so), the fixed laws (6.2.2), (6.3.5) keep it. Adaptive computed torque takes it projected
into its box (its note says how many entries moved) and is skipped when the box leaves the true φ outside; computed
torque is skipped when φ̂(0) makes M̂(q0) singular. A skipped law's reason is one short line (`brief`).

**The repetitive law** runs on the scenario's step and control period h: when h does not divide T its delay line holds
N = round(T/h) samples (:class:`~robotadapt.controllers.repetitive.Repetitive` with `rounded_delay`), a delay N·h within
h/2 of T, which its note states.
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..analysis.metrics import metrics
from ..analysis.monitors import convergence_time
from ..controllers.registry import Contender, OfTruth, registered
from ..grid import Grid
from ..robots.base import RobotModel
from ..robots.two_link import TwoLinkArm
from ..sim.integrators import Sampled, SolveIVP
from ..sim.result import SimulationResult
from ..validation import ConfigError, as_gain
from .scenarios import Scenario
from .scenarios.build import NESTED, canonical_kind, constructor, keys, setup

_BOOK_PHI = (0.8, 2.3)  # the book's two-link arm, m1, m2 (kg) [BT]: the arm the lineup's gains were chosen for
#: the letters a law may take from the scenario's law of its family (Γ from either family of gradient laws)
_SHARED = ("Lam", "Kv", "Kp", "Ka", "kL", "Gamma", "Psi", "a", "P0", "K_I", "F_p", "kd")


def contenders(space: str | None = None) -> dict[str, Contender]:
    """The comparison's lineup: every registered law's entries (its `lineup`), by rank, then name; `space` ("joint",
    "task"): only the laws whose reference lives there (`Law.space`)."""
    found = [c for law in registered("controller").values() for c in law.lineup
             if space is None or getattr(law, "space", "joint") == space]
    return {c.name: c for c in sorted(found, key=lambda c: (c.rank, c.name))}


def _space(section: dict[str, Any]) -> str:
    """Where the law of a [controller] table tracks its reference: "joint" or "task" (`Law.space`)."""
    return getattr(constructor("controller", section.get("kind"), "controller.kind")[0], "space", "joint")


def _books() -> dict[str, Contender]:
    """Each family's entry whose K_v is k_v,book, the denominator of the arm's scale (module docstring)."""
    return {law.family: c for law in registered("controller").values() for c in law.lineup if c.book_kv and law.family}


_ARRAY = re.compile(r"\[(?:[-+0-9.,;:eE\s…]|inf|nan)*\]")  # an array's repr in a message: [1. 2.], [[0.1 …]]


def number_text(v: Any) -> str:
    """A number or list of numbers to 4 significant digits (an integer, a count, in full: 20001, not 2e+04), text as
    is, None as —, a record as its fields."""
    if v is None:
        return "—"
    if isinstance(v, bool | str):
        return str(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(number_text(x) for x in v) + "]"
    if isinstance(v, dict):  # a record (a run's stop, its plant's effects)
        return ", ".join(f"{k} = {number_text(x)}" for k, x in v.items())
    if isinstance(v, int):
        return str(v)
    return f"{v:.4g}"


def flat(section: Any, prefix: str = "") -> list[str]:
    """`key = value` items of a (nested) scenario table, nested keys dotted."""
    if not isinstance(section, dict):
        return [f"{prefix} = {number_text(section)}"]
    return [item for k, v in section.items() for item in flat(v, f"{prefix}.{k}" if prefix else k)]


def brief(exc: ConfigError, limit: int = 160) -> str:
    """A refusal as one line of at most `limit` characters: its field and reason, every array's repr cut to …."""
    text = " ".join(str(exc).split())
    while (short := _ARRAY.sub("…", text)) != text:
        text = short
    return text if len(text) <= limit else text[: limit - 1] + "…"


@dataclass(frozen=True, eq=False)
class Entry:
    """One controller of a comparison: its scenario (the common setting with this controller), label, source, what was
    changed for it (`note`, e.g. the repetitive law's delay line) and whether it is the scenario's own (`reference`)."""

    name: str
    label: str
    source: str
    scenario: Scenario
    note: str = ""
    reference: bool = False


@dataclass(frozen=True, eq=False)
class Row:
    entry: Entry
    result: SimulationResult
    metrics: dict[str, Any]


def _kinds(section: Any, registry: str = "controller") -> tuple[Any, ...]:
    """A controller section's kind and the kinds of its servo, law and base, each by its registered name (an alias, or
    a user's `"module:Class"` whose class registered a kind, by that kind): what identifies a lineup entry."""
    if not isinstance(section, dict):
        return (section,)
    kind, law = canonical_kind(registry, section.get("kind")), _law(section, registry)
    own = getattr(law, "kind", None) if getattr(law, "registry", None) == registry else None
    if own is not None and registered(registry).get(own) is law:
        kind = own
    return (kind,) + tuple(_kinds(section[k], NESTED[k]) for k in NESTED if k in section)


def _fill(section: Any, phi: np.ndarray | None) -> Any:
    """A copy of a lineup section with every :class:`OfTruth` value evaluated at the true φ (None: not known in the
    controller's parameters)."""
    if isinstance(section, dict):
        return {k: _fill(v, phi) for k, v in section.items()}
    if not isinstance(section, OfTruth):
        return copy.deepcopy(section)
    if phi is None:
        raise ConfigError("plant.robot", "the true arm lacks some of the controller's parameters: no bound from φ")
    return section.value(phi)


def _law(section: Any, registry: str = "controller") -> Any:
    """The class (or function) a section's kind names in `registry` (a user's `"module:Class"` too); None without one."""
    if not isinstance(section, dict):
        return None
    try:
        return constructor(registry, section.get("kind"), f"{registry}.kind")[0]
    except ConfigError:
        return None


def _family(section: Any) -> str | None:
    return getattr(_law(section), "family", None)


def _gains(section: dict[str, Any], law: Any) -> list[tuple[tuple[str, ...], Any, int]]:
    """(path, role, power) of each key of a controller section of `law`, its servo's, law's and base's: the role under
    which it is shared with the laws of its family (None: its own) and the power of the arm's scale it carries (the
    law's `powers`; a servo's and an update law's gains are the law's own)."""
    out: list[tuple[tuple[str, ...], Any, int]] = []
    family, powers = getattr(law, "family", None), getattr(law, "powers", {})
    for key, value in section.items():
        if key in NESTED and isinstance(value, dict):
            inner = _law(value) if key == "base" else law
            out += [((key, *path), role, power) for path, role, power in _gains(value, inner)]
        elif law is not None:
            role = None if family is None or key not in _SHARED else ("Γ" if key == "Gamma" else family, key)
            out.append(((key,), role, powers.get(key, 0)))
    return out


def _at(section: dict[str, Any], path: tuple[str, ...]) -> Any:
    for key in path:
        section = section[key]
    return section


def _put(section: dict[str, Any], path: tuple[str, ...], value: Any) -> None:
    _at(section, path[:-1])[path[-1]] = copy.deepcopy(value)


def _same(a: Any, b: Any) -> bool:
    try:
        return bool(np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float)))
    except (TypeError, ValueError):  # a table such as Gamma = {scale = 10}
        return False


def _times(value: Any, factor: float) -> Any:
    arr = np.asarray(value, dtype=float) * factor
    return arr.tolist() if arr.ndim else float(arr)


def _product(Kv: Any, Lam: Any, n: int) -> Any:
    """K_p = K_v Λ as a scenario writes a gain: a number, a diagonal's list, or a matrix."""
    K = as_gain(Kv, n, "controller.Kv") @ as_gain(Lam, n, "controller.Lam")
    d = np.diag(K)
    if np.count_nonzero(K - np.diag(d)):
        return K.tolist()
    return float(d[0]) if np.all(d == d[0]) else d.tolist()


@dataclass(frozen=True, eq=False)
class _Arm:
    """What the lineup takes from the scenario (module docstring): its law's gains by role, the arm's scale s and why,
    the common φ̂(0) (and whether the scenario's law has one), the true φ in the controller's parameters (None when
    the true arm lacks some), the controller's model and q(0)."""

    shared: dict[Any, Any]
    scale: float
    why: str
    phi_hat0: np.ndarray
    estimated: bool
    phi: np.ndarray | None
    model: RobotModel
    q0: np.ndarray

    @classmethod
    def of(cls, base: Scenario) -> _Arm:
        s, own = base.setup, base.data["controller"]
        model: RobotModel = s.controller.model
        family = _family(own)
        shared = {role: _at(own, path) for path, role, _ in _gains(own, _law(own)) if role is not None}
        entry = _books().get(family) if family is not None else None
        if entry is not None and (family, "Kv") in shared:
            source, book = entry.book_kv, entry.section["Kv"]
            low = float(np.linalg.eigvalsh(as_gain(shared[family, "Kv"], model.n, "controller.Kv")).min())
            scale, why = low / book, f"the scenario's λ_min(K_v) = {low:.4g} over {source}'s {book:g}"
        else:
            mu = float(np.linalg.eigvalsh(s.plant.model.mass_matrix(s.q0, s.plant.phi)).max())
            mu_book = float(np.linalg.eigvalsh(TwoLinkArm().mass_matrix(np.zeros(2), np.array(_BOOK_PHI))).max())
            scale, why = mu / mu_book, f"λ_max M(q0) = {mu:.4g} over the book arm's {mu_book:.4g} kg m²"
        own_estimate = getattr(s.controller, "phi_hat0", None)
        truth = dict(zip(s.plant.model.param_names, s.plant.phi, strict=True))
        phi = np.array([truth[k] for k in model.param_names]) if set(model.param_names) <= truth.keys() else None
        phi_hat0 = np.zeros(model.p) if own_estimate is None else np.array(own_estimate, dtype=float)
        return cls(shared, scale, why, phi_hat0, own_estimate is not None, phi, model, s.q0)


def _estimate(arm: _Arm, section: dict[str, Any]) -> list[str]:
    """Give a law with an estimate (`section`) the common φ̂(0); the notes when it cannot take it as it is, or a
    ConfigError when it cannot take it at all (module docstring)."""
    phi_hat0, p = arm.phi_hat0, arm.model.p
    notes = [] if arm.estimated else ["φ̂(0) = 0: the scenario's law has no estimate"]
    law = registered("controller").get(section["kind"])
    if law is not None and law.nominal:  # a baseline compensates with the nominal model
        nominal = arm.model.default_phi
        if nominal is not None:
            phi_hat0, notes = np.asarray(nominal, dtype=float), ["φ̂ = the model's nominal values"]
        elif arm.phi is not None:
            phi_hat0, notes = arm.phi, ["φ̂ = the true φ (the model has no nominal values)"]
    if section["kind"] == "adaptive_computed_torque":
        lo, hi = (np.broadcast_to(np.asarray(section[k], dtype=float), (p,)) for k in ("phi_min", "phi_max"))
        if arm.phi is None:
            raise ConfigError("plant.robot", "the true arm lacks some of the controller's parameters: no box to check")
        outside = int(np.count_nonzero((arm.phi < lo) | (arm.phi > hi)))
        if outside:
            raise ConfigError("controller.phi_min", f"the box phi_min = {lo.min():.4g}, phi_max = {hi.max():.4g} leaves "
                              f"{outside} of {p} true parameters outside; the projection (Table 6.2.1) needs φ in it")
        projected = np.clip(phi_hat0, lo, hi)
        moved = int(np.count_nonzero(projected != phi_hat0))
        if moved:
            notes.append(f"φ̂(0): {moved} of {p} entries projected into the box (Table 6.2.1: M̂ stays invertible)")
        phi_hat0 = projected
    if section["kind"] == "computed_torque":
        eig = np.linalg.eigvalsh(arm.model.mass_matrix(arm.q0, phi_hat0))
        if eig.min() <= 1e-9 * np.abs(eig).max():
            raise ConfigError("controller.phi_hat0", "the common φ̂(0) makes M̂(q0) singular: (6.2.2) with a fixed φ̂ "
                              "needs M̂ > 0 to apply its feedback")
    section["phi_hat0"] = phi_hat0.tolist()
    return notes


def _contender(arm: _Arm, c: Contender) -> tuple[str, dict[str, Any], list[str]]:
    """A lineup entry's source, section on the scenario's arm and notes (module docstring)."""
    section = _fill(c.section, arm.phi)
    derived = section["kind"] in ("pd", "pd_gravity") and ("6", "Kp") not in arm.shared  # K_p = K_v Λ
    taken: list[str] = []
    scaled: list[str] = []
    for path, role, power in _gains(section, _law(section)):
        book = _at(section, path)
        if role in arm.shared:
            value, changed = arm.shared[role], taken
        elif power and not (derived and path == ("Kp",)):
            value, changed = _times(book, arm.scale**power), scaled
        else:
            continue
        if not _same(value, book):
            _put(section, path, value)
            changed.append(".".join(path))
    if derived:
        Kp = _product(section["Kv"], arm.shared.get(("6", "Lam"), _books()["6"].section["Lam"]), arm.model.n)
        if not _same(Kp, section["Kp"]):
            section["Kp"] = Kp
            (taken if {("6", "Kv"), ("6", "Lam")} & arm.shared.keys() else scaled).append("Kp = K_v Λ")
    source = f"{c.reference}; gains: {c.gains}"
    if scaled:
        source += f", scaled by s = {arm.scale:.4g} ({arm.why}): {', '.join(scaled)}"
    if taken:
        source += f"; from the scenario: {', '.join(taken)}"
    holder = next((s for s in (section, section.get("base")) if isinstance(s, dict) and "phi_hat0" in
                   keys("controller", s["kind"])), None)
    return source, section, [] if holder is None else _estimate(arm, holder)


def _entry(base: Scenario, name: str, label: str, source: str, section: dict[str, Any], notes: list[str],
           reference: bool = False) -> Entry:
    """`base` with controller `section`; the repetitive law on the scenario's step (module docstring)."""
    data = copy.deepcopy(base.data)
    data.pop("study", None)
    data["controller"] = section
    rounded = False
    if section.get("kind") == "repetitive":
        period = section.get("period", getattr(base.setup.trajectory, "period", None))
        if period is None:
            raise ConfigError("trajectory", "the repetitive law needs a periodic desired trajectory (7.2.30)")
        integrator = base.setup.integrator
        if isinstance(integrator, SolveIVP):
            sim = data["simulation"]
            for key in ("rtol", "atol"):
                sim.pop(key, None)
            sim["method"] = "rk4"
            notes.append(f"RK4 at dt = {integrator.dt:.4g} s (a delay line needs the fixed step)")
        h, step = (integrator.control_period, "Ts") if isinstance(integrator, Sampled) else (integrator.dt, "dt")
        steps = period / h
        rounded = abs(steps - round(steps)) > 1e-6 * steps
        if rounded:
            miss = round(steps) * h - period
            notes.append(f"delay line N = round(T/{step}) = {round(steps)} steps: N·{step} = T {'+−'[miss < 0]} "
                         f"{abs(miss):.3g} s (Table 7.2.2's delay to within {step}/2)")
            data["controller"]["rounded_delay"] = True
    return Entry(name, label, source, Scenario(f"{base.name} [{name}]", data, setup(data)), "; ".join(notes), reference)


def lineup(base: Scenario, names: list[str] | None = None) -> tuple[list[Entry], dict[str, str]]:
    """The comparison's entries on `base`'s arm, trajectory, disturbance, initial state and step, and the lineup names
    that do not apply (with why, one line each). `names` defaults to all of :func:`contenders`; the scenario's own
    controller is the reference, in place of the lineup entry of the same kinds or as "scenario"; the other laws' gains
    and initial estimate follow the scenario (module docstring)."""
    own = base.data["controller"]
    every = contenders(_space(own))  # the laws of the scenario's law's space: joint angles, or the hand (docs/task-space.md)
    match = next((n for n, c in every.items() if _kinds(c.section) == _kinds(own)), None)
    known = list(every) + ([] if match else ["scenario"])
    for name in names or ():
        if name not in known:
            raise ConfigError("--controllers", f"unknown controller {name!r}; choose from {', '.join(known)}")
    arm = _Arm.of(base)
    entries, skipped = [], {}
    for name in dict.fromkeys(known if names is None else names):
        try:
            if name in (match, "scenario"):
                c = every.get(name)
                label = c.label if c else f"the scenario's {own.get('kind')}"
                source = f"{c.reference + '; ' if c else ''}gains: the scenario's (the reference, run as it is given)"
                entries.append(_entry(base, name, label, source, copy.deepcopy(own), [], reference=True))
            else:
                entries.append(_entry(base, name, every[name].label, *_contender(arm, every[name])))
        except ConfigError as exc:
            if names is not None:
                raise ConfigError("--controllers", f"{name} does not apply here: {brief(exc)}") from None
            skipped[name] = brief(exc)
    return entries, skipped


def _row(entry: Entry, progress: bool) -> Row:
    """Run `entry`; its metrics, µs/step None for a run that stopped before t_final (not ok, or its log ends more
    than a logging interval early)."""
    res = entry.scenario.run(progress)
    m = metrics(res)
    s = entry.scenario.setup
    h = s.integrator.control_period if isinstance(s.integrator, Sampled) else s.integrator.dt
    finished = res.ok and float(res.t[-1]) > s.t_final - s.log_every * h * (1 + 1e-9)
    steps = max(Grid.of(s.integrator, s.t_final).n, 1)
    e_norm = np.linalg.norm(res.e, axis=-1)
    summary = {
        "controller": entry.name, "label": entry.label, "source": entry.source, "reference": entry.reference,
        "status": res.status, "rms_error_norm": m["rms_error_norm"], "final_error": float(e_norm[-1]),
        "max_error": float(e_norm.max()), "peak_torque": float(np.max(m["max_abs_torque"])),
        "control_energy": m["control_energy"], "final_phi_error": m.get("final_phi_error"),
        "convergence_time": convergence_time(res.t, res.e),
        "us_per_step": 1e6 * res.wall_time / steps if finished else None,
        "settings": ", ".join(flat(entry.scenario.data["controller"])), "note": entry.note,
    }
    return Row(entry, res, summary)


def compare(base: Scenario, names: list[str] | None = None, progress: bool = False) -> tuple[list[Row], dict[str, str]]:
    """Run every entry of :func:`lineup`; returns the rows and the skipped names with why."""
    entries, skipped = lineup(base, names)
    return run_entries(entries, progress), skipped


def run_entries(entries: list[Entry], progress: bool = False) -> list[Row]:
    """Each entry run as it stands, in order: the rows of a comparison."""
    rows = []
    for entry in entries:
        rows.append(_row(entry, progress))
        if progress:
            print(f"{entry.name}: {rows[-1].result.status}, {rows[-1].result.wall_time:.1f} s", flush=True)
    return rows


def variants(base: Scenario, settings: list[list[str]], load: Any) -> list[Entry]:
    """The scenario as written, then one entry per variant: its overrides (`SECTION.KEY=VALUE`, as --set takes them)
    applied by `load(overrides)` on top of the scenario's own — natural against Euclidean against no adaptation, one
    law at two control periods — each row named by what it changes."""
    entries = [Entry("as written", "as written", "the scenario as written", base, reference=True)]
    for assignments in settings:
        text = "; ".join(assignments)
        entries.append(Entry(text, text, f"the scenario with {text}", load(assignments)))
    return entries


def tunable(scenario: Scenario) -> list[str]:
    """The gains a fair comparison tunes in the scenario's controller: those its law lists in `tuned`, its servo's,
    update law's and base's by theirs, that tuning accepts (`robotadapt.studies.gain_space.locate` refuses those a law
    derives other constants from that it cannot recompute from a traced gain)."""
    from .gain_space import locate

    def fields(section: Any, prefix: str, registry: str) -> list[str]:
        tuned = getattr(_law(section, registry), "tuned", ())
        out = [f"{prefix}.{k}" for k in section if k in tuned]
        return out + [f for k in NESTED if isinstance(section.get(k), dict)
                      for f in fields(section[k], f"{prefix}.{k}", NESTED[k])]

    found = []
    for name in fields(scenario.data["controller"], "controller", "controller"):
        try:
            locate(scenario, name)
        except ConfigError:
            continue
        found.append(name)
    return found


def _over_budget(summary: dict[str, Any]) -> str:
    """Why a tuned law stays over the budget, measured: its peak after the runs it had, and the gain that moves the peak
    most (∂ln max|τ|/∂ln gain at the answer); empty within the budget."""
    if summary["feasible"]:
        return ""
    name, value = max(summary["peak_elasticity"].items(), key=lambda kv: abs(kv[1]))
    return (f"over the budget after {summary['differentiated_runs']} runs: max |τ| {summary['max_abs_torque']:.4g}; the "
            f"peak moves most with {name} (∂ln max|τ|/∂ln gain = {value:.2g})")


def fair(base: Scenario, names: list[str] | None, objective: str, max_torque: float, max_runs: int,
         progress: bool = False, workers: int | None = None) -> tuple[list[Row], dict[str, str]]:
    """The fair comparison: every entry of :func:`lineup` with its own gains tuned (`tunable`) to the same `objective`
    under the same torque budget (:func:`robotadapt.studies.tune.tune`, at most `max_runs` runs each), then run as
    :func:`compare` runs it. A law that cannot be differentiated keeps the lineup's gains, and its row says why; each row
    holds `tuned_gains`, `within_budget`, `tune_runs` and `tune_converged` (the search ended by its own test, not by
    `max_runs`). The laws are tuned on `workers` processes at once (default: every core; their compilation is most of
    the time), then run here one after the other, so that each row's µs/step is measured alone."""
    from .gain_space import locate, parse_objective
    from .tune import tuned_scenario

    goal = parse_objective(objective)
    entries, skipped = lineup(base, names)
    rows = []
    tunings = _tunings([e.scenario for e in entries], (objective, max_torque, max_runs), workers)
    for entry, (fields, found) in zip(entries, tunings, strict=True):
        if isinstance(found, ConfigError):
            note = "; ".join(filter(None, (entry.note, f"lineup gains: not tuned ({brief(found)})")))
            row = _row(replace(entry, note=note), progress)
            row.metrics.update(tuned_gains=None, tune_runs=0, tune_converged=None)
        else:
            summary, theta = found
            tuned = tuned_scenario(entry.scenario, [locate(entry.scenario, f) for f in fields], theta)
            row = _row(replace(entry, scenario=tuned, source=f"{entry.source}; tuned: {', '.join(fields)}",
                               note="; ".join(filter(None, (entry.note, _over_budget(summary))))), progress)
            row.metrics.update(tuned_gains=summary["gains"], tune_runs=summary["runs"],
                               tune_differentiated_runs=summary["differentiated_runs"],
                               tune_converged=summary["search_converged"])
        row.metrics["within_budget"] = row.result.ok and row.metrics["peak_torque"] <= max_torque
        row.metrics["objective"] = goal.of_metrics(metrics(row.result))
        rows.append(row)
        if progress:
            print(f"{entry.name}: {row.result.status}, RMS ‖e‖ {row.metrics['rms_error_norm']:.4g}, peak |τ| "
                  f"{row.metrics['peak_torque']:.4g}, " + (f"{row.metrics['tune_differentiated_runs']} differentiated "
                  f"runs (--tune-runs) + {row.metrics['tune_runs'] - row.metrics['tune_differentiated_runs']} forward"
                  if row.metrics.get("tune_differentiated_runs") is not None else "lineup gains")
                  + (", converged" if row.metrics["tune_converged"] else ""), flush=True)
    return rows, skipped


Tuning = tuple[list[str], ConfigError | tuple[dict[str, Any], np.ndarray]]


def _tunings(scenarios: list[Scenario], budget: tuple[str, float, int], workers: int | None) -> list[Tuning]:
    """:func:`_tuning` of every scenario under `budget` (objective, max torque, max runs), on `workers` spawned processes
    (default: every core, at most one a scenario; 1: here)."""
    from ..cores import usable_cores
    from .sweep import worker_init

    workers = min(usable_cores() if workers is None else workers, len(scenarios))
    if workers <= 1:
        return [_tuning(s, *budget) for s in scenarios]
    import multiprocessing

    # spawned, not forked (a fork of a process whose JAX threads run can deadlock); each worker's XLA on one thread
    with multiprocessing.get_context("spawn").Pool(workers, initializer=worker_init) as pool:
        return pool.map(_tuning_sent, [(s.name, s.data, *budget) for s in scenarios], 1)


def _tuning_sent(job: tuple[Any, ...]) -> Tuning:
    """:func:`_tuning` in a worker, its scenario built again from the data sent (name, data, then the budget)."""
    name, data, *budget = job
    return _tuning(Scenario(name, data, setup(copy.deepcopy(data))), *budget)


def _tuning(scenario: Scenario, objective: str, max_torque: float, max_runs: int) -> Tuning:
    """One law of :func:`fair` tuned: (the tuned fields, (tune.json's summary, θ)), or the ConfigError why not."""
    from .tune import closed_loop, tune

    fields: list[str] = []
    try:
        loop = closed_loop(scenario)
        period = getattr(loop.controller, "period", None)  # a learning law's (its delay line's)
        if loop.controller.has("delay_line") and period is not None and scenario.setup.t_final <= period:
            raise ConfigError("simulation.t_final", f"{scenario.setup.t_final:g} s is within one period T = "
                              f"{period:.4g} s: the law learns nothing (û_d(t − T) = 0 throughout)")
        fields = tunable(scenario)
        if not fields:
            raise ConfigError("controller", "no gain of this law can be tuned (a law lists them in its `tuned`)")
        tuned = tune(scenario, fields, objective, max_torque, max_runs=max_runs)
    except ConfigError as exc:
        return fields, exc
    return fields, (tuned.summary(), np.asarray(tuned.theta))
