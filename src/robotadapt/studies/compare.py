"""The comparison of every law of chapters 6–7 on one scenario's arm, trajectory and disturbance (`robotadapt compare`):
the lineup with each law's book gains, and one row of metrics per law (tables only; :mod:`robotadapt.report.html`
draws and writes the report)."""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from ..analysis.metrics import metrics
from ..analysis.monitors import convergence_time
from ..sim.integrators import RK4
from ..sim.result import SimulationResult
from ..validation import ConfigError
from .scenarios import Scenario
from .scenarios.build import canonical_kind, setup


@dataclass(frozen=True, eq=False)
class OfTruth:
    """A lineup value derived from the true φ: `factor`·φ, or `factor`·‖φ‖ with `norm`."""

    factor: float
    norm: bool = False

    def value(self, phi: np.ndarray) -> Any:
        return self.factor * float(np.linalg.norm(phi)) if self.norm else (self.factor * phi).tolist()


class Contender(NamedTuple):
    label: str
    reference: str  # the book's equations
    gains: str  # where the gains come from
    section: dict[str, Any]  # the scenario's [controller] table


NOMINAL = OfTruth(1.1)  # fixed estimates φ̂ = 1.1 φ (Example 6.2.1's (0.85, 2.2) for (0.8, 2.3) are +6 %, −4 %)
SIGMA_BOUND = OfTruth(1.25, norm=True)  # φ0 = 1.25 ‖φ‖ > ‖φ‖ (6.7.15); sigma-modification.toml's 3 is 1.23 ‖φ‖
_SL = {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}  # Example 6.3.1 [BT]
_PID = {"kind": "pid", "Lam": 2.5, "Psi": 1.0}  # Problem 6.4-1 [P]
# The comparison's controllers with the gains the packaged two-link scenarios give them. A scenario whose own controller
# has the same kinds (controller, servo, law, base) replaces that entry's gains with its own.
LINEUP: dict[str, Contender] = {
    "slotine_li": Contender("Slotine–Li", "Table 6.3.1", "Example 6.3.1", {"kind": "slotine_li", **_SL}),
    "computed_torque": Contender("computed torque, fixed φ̂", "(6.2.2)", "Example 6.2.1's K_p, K_v; φ̂ = 1.1 φ",
                                 {"kind": "computed_torque", "Kp": 4.0, "Kv": 4.0, "phi_hat0": NOMINAL}),
    "pd": Contender("PD", "baseline", "K_p = K_v Λ, K_v of Example 6.3.1", {"kind": "pd", "Kp": 25.0, "Kv": 10.0}),
    "pd_gravity": Contender("PD + gravity, fixed φ̂", "(6.3.5)", "K_p = K_v Λ, K_v of Example 6.3.1; φ̂ = 1.1 φ",
                            {"kind": "pd_gravity", "Kp": 25.0, "Kv": 10.0, "phi_hat0": NOMINAL}),
    "adaptive_computed_torque": Contender(
        "adaptive computed torque + projection", "Table 6.2.1",
        "Example 6.2.2; box [0.1, 10] (docs: laws.md#adaptive-computed-torque); φ̂(0) = 1.1 φ",
        {"kind": "adaptive_computed_torque", "Kp": 125.0, "Kv": 50.0, "Gamma": 500.0, "phi_hat0": NOMINAL,
         "phi_min": 0.1, "phi_max": 10.0}),
    "passivity": Contender("passivity: PID servo + gradient", "Table 6.4.1, Examples 6.4.1, 6.4.3", "Problem 6.4-1",
                           {"kind": "passivity", "Kv": 10.0, "servo": _PID, "law": {"kind": "gradient", "Gamma": 20.0}}),
    "passivity_pi": Contender("passivity: PID servo + Landau PI", "(6.4.20)–(6.4.21)", "Problem 6.4-2",
                              {"kind": "passivity", "Kv": 10.0, "servo": _PID,
                               "law": {"kind": "landau_pi", "K_I": 20.0, "F_p": 2.0}}),
    "sigma": Contender("switching σ-modification", "(6.7.13)–(6.7.14)", "Example 6.3.1; φ0 = 1.25 ‖φ‖",
                       {"kind": "passivity", "Kv": 10.0, "servo": {"kind": "pd", "Lam": 2.5},
                        "law": {"kind": "sigma", "Gamma": 20.0, "phi0": SIGMA_BOUND}}),
    "composite": Contender("composite (least squares)", "Table 6.6.1",
                           "Λ, K_v of Example 6.3.1; a = 1, P(0) = 10 I of Example 6.6.3",
                           {"kind": "composite", "Lam": 2.5, "Kv": 10.0, "a": 1.0, "P0": 10.0}),
    "sign_robust": Contender("Slotine–Li + k_d sgn(r)", "(6.7.6)", "Example 6.7.2 (k_d = 2.2)",
                             {"kind": "sign_robust", "kd": 2.2, "boundary_layer": 0.0,
                              "base": {"kind": "slotine_li", **_SL}}),
    "dcal": Contender("DCAL", "Table 7.2.1", "Example 7.2.1",
                      {"kind": "dcal", "Kv": 50.0, "Kp": 50.0, "Ka": 50.0, "Gamma": 20.0, "precompute": True}),
    "repetitive": Contender("repetitive (learning)", "Table 7.2.2", "Example 7.2.2; T = the trajectory's period",
                            {"kind": "repetitive", "Kv": 50.0, "Kp": 50.0, "Ka": 50.0, "kL": 50.0}),
}


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


@dataclass(frozen=True, eq=False)
class Entry:
    """One controller of a comparison: its scenario (the common setting with this controller), label, source, and
    what was changed for it (`note`, e.g. the step of the repetitive law)."""

    name: str
    label: str
    source: str
    scenario: Scenario
    note: str = ""


@dataclass(frozen=True, eq=False)
class Row:
    entry: Entry
    result: SimulationResult
    metrics: dict[str, Any]


def _kinds(section: Any) -> tuple[Any, ...]:
    """A controller section's kind and the kinds of its servo, law and base (aliases by their registry name): what
    identifies a lineup entry."""
    if not isinstance(section, dict):
        return (section,)
    return ((canonical_kind("controller", section.get("kind")),)
            + tuple(_kinds(section[k]) for k in ("servo", "law", "base") if k in section))


def _fill(section: Any, phi: np.ndarray) -> Any:
    """A copy of a lineup section with every :class:`OfTruth` value evaluated at the true φ."""
    if isinstance(section, dict):
        return {k: _fill(v, phi) for k, v in section.items()}
    return section.value(phi) if isinstance(section, OfTruth) else copy.deepcopy(section)


def _entry(base: Scenario, name: str, label: str, source: str, section: dict[str, Any]) -> Entry:
    """`base` with controller `section`; for the repetitive law a step dividing the period and the fixed-step method."""
    data = copy.deepcopy(base.data)
    data.pop("study", None)
    data["controller"] = section
    note = ""
    if section.get("kind") == "repetitive":
        period = getattr(base.setup.trajectory, "period", None)
        if period is None:
            raise ConfigError("trajectory", "the repetitive law needs a periodic desired trajectory (7.2.30)")
        integrator = base.setup.integrator
        steps = period / integrator.dt
        if abs(steps - round(steps)) > 1e-6 * steps or not isinstance(integrator, RK4):
            dt = period / np.ceil(steps - 1e-6)
            sim = data["simulation"]
            for key in ("rtol", "atol"):
                sim.pop(key, None)
            sim.update(dt=dt, method="rk4")
            note = f"dt = T/{round(period / dt)} = {dt:.4g} s, RK4 (the step must divide the period)"
    return Entry(name, label, source, Scenario(f"{base.name} [{name}]", data, setup(data)), note)


def lineup(base: Scenario, names: list[str] | None = None) -> tuple[list[Entry], dict[str, str]]:
    """The comparison's entries on `base`'s arm, trajectory, disturbance, initial state and step, and the lineup names
    that do not apply (with why). `names` defaults to all of `LINEUP`; the lineup entry of the same kinds as the
    scenario's own controller takes the scenario's gains, and a scenario controller that matches none joins as
    "scenario"."""
    own = base.data["controller"]
    match = next((n for n, c in LINEUP.items() if _kinds(c.section) == _kinds(own)), None)
    known = list(LINEUP) + ([] if match else ["scenario"])
    for name in names or ():
        if name not in known:
            raise ConfigError("--controllers", f"unknown controller {name!r}; choose from {', '.join(known)}")
    phi = base.setup.plant.phi
    entries, skipped = [], {}
    for name in dict.fromkeys(known if names is None else names):
        if name == "scenario":
            label, source, section = f"the scenario's {own.get('kind')}", "the scenario's controller", own
        else:
            c = LINEUP[name]
            section = own if name == match else _fill(c.section, phi)
            label, source = c.label, f"{c.reference}; gains: {'the scenario' if name == match else c.gains}"
        try:
            entries.append(_entry(base, name, label, source, copy.deepcopy(section)))
        except ConfigError as exc:
            if names is not None:
                raise ConfigError("--controllers", f"{name} does not apply here: {exc}") from None
            skipped[name] = str(exc)
    return entries, skipped


def _row(entry: Entry, progress: bool) -> Row:
    res = entry.scenario.run(progress)
    m = metrics(res)
    steps = max(round(float(res.t[-1]) / entry.scenario.setup.integrator.dt), 1)
    e_norm = np.linalg.norm(res.e, axis=-1)
    summary = {
        "controller": entry.name, "label": entry.label, "source": entry.source, "status": res.status,
        "rms_error_norm": m["rms_error_norm"], "final_error": float(e_norm[-1]),
        "max_error": float(e_norm.max()), "peak_torque": float(np.max(m["max_abs_torque"])),
        "control_energy": m["control_energy"], "final_phi_error": m.get("final_phi_error"),
        "convergence_time": convergence_time(res.t, res.e), "us_per_step": 1e6 * res.wall_time / steps,
        "settings": ", ".join(flat(entry.scenario.data["controller"])), "note": entry.note,
    }
    return Row(entry, res, summary)


def compare(base: Scenario, names: list[str] | None = None, progress: bool = False) -> tuple[list[Row], dict[str, str]]:
    """Run every entry of :func:`lineup`; returns the rows and the skipped names with why."""
    entries, skipped = lineup(base, names)
    rows = []
    for entry in entries:
        rows.append(_row(entry, progress))
        if progress:
            print(f"{entry.name}: {rows[-1].result.status}, {rows[-1].result.wall_time:.1f} s", flush=True)
    return rows, skipped


#: the gains a fair comparison tunes, where a law has them (the book's letters; `robotadapt.studies.tune.locate`
#: refuses those a law derives other constants from, e.g. adaptive computed torque's K_p, K_v)
TUNED_GAINS = ("Lam", "Kv", "Kp", "Ka", "Gamma", "P0", "K_I", "F_p", "Psi", "kL")


def tunable(scenario: Scenario) -> list[str]:
    """The fields of `TUNED_GAINS` in the scenario's controller (its servo, law and base too) that tuning accepts."""
    from .gain_space import locate

    def fields(section: Any, prefix: str) -> list[str]:
        out = [f"{prefix}.{k}" for k in section if k in TUNED_GAINS]
        return out + [f for k in ("servo", "law", "base") if isinstance(section.get(k), dict)
                      for f in fields(section[k], f"{prefix}.{k}")]

    found = []
    for name in fields(scenario.data["controller"], "controller"):
        try:
            locate(scenario, name)
        except ConfigError:
            continue
        found.append(name)
    return found


def fair(base: Scenario, names: list[str] | None, objective: str, max_torque: float, max_runs: int,
         progress: bool = False) -> tuple[list[Row], dict[str, str]]:
    """The fair comparison: every entry of :func:`lineup` with its own gains tuned (`tunable`) to the same `objective`
    under the same torque budget (:func:`robotadapt.studies.tune.tune`, at most `max_runs` runs each), then run as
    :func:`compare` runs it. A law that cannot be differentiated keeps the book's gains, and its row says why; each row
    holds `tuned_gains`, `within_budget` and `tune_runs`."""
    from .tune import closed_loop, tune

    entries, skipped = lineup(base, names)
    rows = []
    for entry in entries:
        try:
            closed_loop(entry.scenario)
            fields = tunable(entry.scenario)
            if not fields:
                raise ConfigError("controller", "no gain of this law can be tuned")
            tuned = tune(entry.scenario, fields, objective, max_torque, max_runs=max_runs)
        except ConfigError as exc:
            row = _row(replace(entry, note=f"book gains: not tuned ({exc.reason})"), progress)
            row.metrics.update(tuned_gains=None, tune_runs=0)
        else:
            gains = tuned.summary()["gains"]
            row = _row(replace(entry, scenario=tuned.scenario, source=f"{entry.source}; tuned: {', '.join(fields)}"),
                       progress)
            row.metrics.update(tuned_gains=gains, tune_runs=tuned.summary()["runs"])
        row.metrics["within_budget"] = row.result.ok and row.metrics["peak_torque"] <= max_torque
        rows.append(row)
        if progress:
            print(f"{entry.name}: {row.result.status}, RMS ‖e‖ {row.metrics['rms_error_norm']:.4g}, peak |τ| "
                  f"{row.metrics['peak_torque']:.4g}, {row.metrics['tune_runs']} tuning runs", flush=True)
    return rows, skipped
