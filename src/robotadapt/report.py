"""Reports a user looks at: the comparison of controllers on one scenario (report.html, figures embedded), the gallery
of the book's examples (index.html over the figures `robotadapt run` writes), and the α(t0) figure of the persistency of
excitation analysis (spec §5).

The comparison answers the book's open question (the comparison of the laws "remains to be investigated"): every
controller of chapters 6–7 on the same arm, desired trajectory, disturbance, initial state and step, each with the gains
the book (or a packaged scenario) gives it on the two-link arm, `LINEUP` below.
"""

from __future__ import annotations

import base64
import copy
import html
import io
import json
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .excitation import Excitation  # noqa: E402
from .monitors import convergence_time  # noqa: E402
from .result import SimulationResult, atomic_write, writable_dir  # noqa: E402
from .scenarios import Scenario, available, load  # noqa: E402
from .scenarios.build import setup  # noqa: E402
from .simulation import RK4  # noqa: E402
from .validation import ConfigError  # noqa: E402


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
        "Example 6.2.2; box [0.1, 10] of spec §2.3; φ̂(0) = 1.1 φ",
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
_STYLE = """body{font-family:system-ui,sans-serif;margin:2em;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #ccc;padding:4px 8px;text-align:right;vertical-align:top}
th{background:#f0f0f0}td.l,th.l{text-align:left}img{max-width:100%}code{font-size:90%}.bad{color:#b00}
section{border-top:1px solid #ccc;margin-top:2em}.figs{display:flex;flex-wrap:wrap;gap:8px}.figs img{width:32%}"""


def _page(title: str, body: str) -> str:
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head>\n<body>\n<h1>{html.escape(title)}</h1>\n{body}\n</body></html>\n")


def _num(v: Any) -> str:
    """A number or list of numbers to 4 significant digits, text as is, None as —."""
    if v is None:
        return "—"
    if isinstance(v, bool | str):
        return str(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_num(x) for x in v) + "]"
    return f"{v:.4g}"


def _flat(section: Any, prefix: str = "") -> list[str]:
    """`key = value` items of a (nested) scenario table, nested keys dotted."""
    if not isinstance(section, dict):
        return [f"{prefix} = {_num(section)}"]
    return [item for k, v in section.items() for item in _flat(v, f"{prefix}.{k}" if prefix else k)]


def _png(fig: Any) -> bytes:
    """A figure as PNG bytes, closing it."""
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


# ---------------------------------------------------------------------------------------------------------------------
# persistency of excitation


def _log_with_zero(ax: Any, t: np.ndarray, y: np.ndarray, floor: float, label: str) -> None:
    """Plot y ≥ 0 on a log axis; zeros (round-off) are drawn at `floor`, which then becomes the bottom of the axis."""
    zero = bool(np.any(y <= floor))
    ax.semilogy(t, np.maximum(y, floor), label=label + (" (0 drawn at the bottom)" if zero else ""))
    if zero:
        ax.set_ylim(bottom=floor / 2)


def excitation_figure(exc: Excitation, path: Path, title: str = "") -> Path:
    """α(t0), β(t0) of the windowed Gram matrix (6.5.2) with the PE threshold, and the extreme eigenvalues of the
    growing integral ∫_0^t Y_dᵀ Y_d (6.6.18); log scale, zero drawn at the bottom of the axis."""
    floor = 1e-12 * max(exc.beta_max, 1e-300)
    fig, (ax_w, ax_c) = plt.subplots(2, 1, figsize=(7, 6.5))
    ax_w.semilogy(exc.t0, exc.beta, label="β(t0) = λ_max")
    _log_with_zero(ax_w, exc.t0, exc.alpha, floor, "α(t0) = λ_min")
    ax_w.axhline(exc.rtol * exc.beta_max, color="k", linestyle="--", label=f"PE threshold {exc.rtol:g}·max β")
    verdict = "persistently exciting" if exc.persistently_exciting else "NOT persistently exciting"
    ax_w.set_title(f"{title}: {verdict} (ρ = {exc.window:.4g} s)".lstrip(": "))
    ax_w.set_xlabel("window start t0 (s)")
    ax_w.set_ylabel("eigenvalues of ∫ Y_dᵀY_d over [t0, t0+ρ]")
    ax_c.semilogy(exc.t_cum, exc.lambda_max_cum, label="λ_max")
    _log_with_zero(ax_c, exc.t_cum, exc.lambda_min_cum, floor, "λ_min")
    grows = "grows" if exc.integral_grows else "levels off"
    ax_c.set_title(f"(6.6.18): λ_min ∫_0^t Y_dᵀY_d {grows} (∝ t^{exc.growth_exponent:.2f} over the second half)")
    ax_c.set_xlabel("t (s)")
    for ax in (ax_w, ax_c):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110), binary=True)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------------------------------
# gallery of the book's examples and problems


@dataclass(frozen=True, eq=False)
class GalleryEntry:
    """One book scenario as run for the gallery: `t_final` the simulated time, `t_scenario` the scenario's own."""

    name: str
    description: str
    notes: str
    settings: dict[str, Any]
    metrics: dict[str, Any]
    t_final: float
    t_scenario: float
    wall_time: float


def book_scenarios() -> list[str]:
    """The packaged scenarios named example-* and problem-*, in order."""
    return [name for name in available() if name.startswith(("example-", "problem-"))]


def run_gallery(out: Path, t_final_cap: float | None = None, progress: bool = False) -> list[GalleryEntry]:
    """Run every book scenario (capped at `t_final_cap` seconds of simulated time if given), write into out/NAME/ what
    `robotadapt run` writes (result.npz, metrics.json, scenario.toml and the three figures), and index.html into `out`."""
    out = writable_dir(out)
    entries = []
    for name in book_scenarios():
        scenario = load(name)
        t_scenario = scenario.setup.t_final
        if t_final_cap is not None and t_final_cap < t_scenario:
            scenario = load(name, [f"simulation.t_final={t_final_cap!r}"])
        wall = time.perf_counter()
        res = scenario.run(progress)
        res.plot(res.save(out / name, scenario.text), title=name)  # what `robotadapt run` writes
        wall = time.perf_counter() - wall
        entries.append(GalleryEntry(name, scenario.description, str(scenario.data.get("notes", "")),
                                    {k: scenario.data[k] for k in ("robot", "plant", "trajectory", "controller",
                                                                    "simulation")},
                                    res.metrics(), scenario.setup.t_final, t_scenario, wall))
        if progress:
            print(f"{name}: {res.status}, {wall:.1f} s", flush=True)
    atomic_write(out / "index.html", lambda f: f.write(gallery_html(entries)))
    return entries


def gallery_html(entries: list[GalleryEntry]) -> str:
    """The gallery page: per example its description, notes, settings, metrics and the three figures."""
    total = sum(e.wall_time for e in entries)
    capped = [e.name for e in entries if e.t_final < e.t_scenario]
    parts = [f"<p>{len(entries)} scenarios of the book's chapter 6 and §7.2 (examples and problems), generated by "
             f"<code>robotadapt figures</code> in {total:.0f} s."
             + (f" <b>Capped</b> simulated time for {len(capped)} of them (marked below)." if capped else "")
             + "</p>", "<ul>"]
    parts += [f'<li><a href="#{e.name}">{e.name}</a>: {html.escape(e.description)}</li>' for e in entries]
    parts.append("</ul>")
    for e in entries:
        cap = (f'<p class="bad">Simulated {e.t_final:g} s of the scenario\'s {e.t_scenario:g} s '
               "(capped with --t-final).</p>" if e.t_final < e.t_scenario else "")
        settings = "".join(f"<tr><th class=\"l\">{k}</th><td class=\"l\">{html.escape(', '.join(_flat(v)))}</td></tr>"
                           for k, v in e.settings.items())
        metrics = "".join(f"<tr><th class=\"l\">{html.escape(k)}</th><td class=\"l\">{html.escape(_num(v))}</td></tr>"
                          for k, v in e.metrics.items())
        figs = "".join(f'<img src="{e.name}/{f}.png" alt="{e.name} {f.replace("_", " ")}">'
                       for f in ("tracking_error", "parameters", "torques"))
        parts.append(f'<section id="{e.name}" data-scenario="{e.name}"><h2>{e.name}</h2>'
                     f"<p>{html.escape(e.description)}</p><p><small>{html.escape(e.notes)}</small></p>{cap}"
                     f'<div class="figs">{figs}</div><h3>Settings</h3><table>{settings}</table>'
                     f"<h3>Metrics</h3><table>{metrics}</table><p>run time {e.wall_time:.1f} s</p></section>")
    return _page("robotadapt: the book's examples and problems", "\n".join(parts))


# ---------------------------------------------------------------------------------------------------------------------
# comparison of controllers


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
    """A controller section's kind and the kinds of its servo, law and base: what identifies a lineup entry."""
    if not isinstance(section, dict):
        return (section,)
    return (section.get("kind"),) + tuple(_kinds(section[k]) for k in ("servo", "law", "base") if k in section)


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
    m = res.metrics()
    steps = max(round(float(res.t[-1]) / entry.scenario.setup.integrator.dt), 1)
    e_norm = np.linalg.norm(res.e, axis=-1)
    summary = {
        "controller": entry.name, "label": entry.label, "source": entry.source, "status": res.status,
        "rms_error": float(np.sqrt(np.mean(e_norm**2))), "final_error": float(e_norm[-1]),
        "max_error": float(e_norm.max()), "peak_torque": float(np.max(m["max_abs_torque"])),
        "control_energy": m["control_energy"], "final_phi_error": m.get("final_phi_error"),
        "convergence_time": convergence_time(res.t, res.e), "us_per_step": 1e6 * res.wall_time / steps,
        "settings": ", ".join(_flat(entry.scenario.data["controller"])), "note": entry.note,
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


COLUMNS = (("label", "controller", "{}"), ("status", "status", "{}"), ("rms_error", "RMS ‖e‖", "{:.3g}"),
           ("final_error", "final ‖e‖", "{:.3g}"), ("peak_torque", "peak |τ|", "{:.3g}"),
           ("control_energy", "energy ∫τᵀτ", "{:.4g}"), ("final_phi_error", "final ‖φ̃‖", "{:.3g}"),
           ("convergence_time", "t_conv (s)", "{:.3g}"), ("us_per_step", "µs/step", "{:.1f}"))


def _cell(value: Any, fmt: str) -> str:
    return "—" if value is None else fmt.format(value)


def table_text(rows: list[Row]) -> str:
    """The comparison table as aligned text (what `robotadapt compare` prints)."""
    cells = [[title for _, title, _ in COLUMNS]]
    cells += [[_cell(r.metrics[k], fmt) if k != "status" else r.metrics[k].split(":")[0] for k, _, fmt in COLUMNS]
              for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(line, widths,
                                                                                                    strict=True)))
                     for line in cells)


def _write_bytes(data: bytes, f: Any) -> None:
    f.write(data)


def _overlay(rows: list[Row], signal: str) -> bytes:
    """One figure, one line per controller: ‖e(t)‖, ‖φ̃(t)‖ (log scale over 12 decades) or ‖τ(t)‖ (over 4)."""
    fig, ax = plt.subplots(figsize=(10, 4.5))
    colors = [plt.get_cmap("tab20")(i) for i in range(20)]
    top = 0.0
    for i, row in enumerate(rows):
        res = row.result
        y = {"e": res.e, "phi": res.phi_err, "tau": res.tau}[signal]
        if y is None or y.shape[-1] == 0:
            continue
        norm = np.linalg.norm(y, axis=-1)
        top = max(top, float(np.max(norm, initial=0.0, where=np.isfinite(norm))))
        ax.semilogy(res.t, norm, color=colors[(2 * i) % 20 + (2 * i) // 20], linestyle=("-", "--", ":")[i % 3],
                    label=row.entry.label)
    if top > 0:
        ax.set_ylim((1e-4 if signal == "tau" else 1e-12) * top, 3 * top)
    ax.set_xlabel("t (s)")
    ax.set_ylabel({"e": "‖e(t)‖ (rad or m)", "phi": "‖φ − φ̂(t)‖", "tau": "‖τ(t)‖ (N·m or N)"}[signal])
    ax.grid(True, alpha=0.3)
    ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize="small")
    return _png(fig)


OVERLAYS = {"errors": ("e", "Tracking error ‖e(t)‖"),
            "parameter_errors": ("phi", "Parameter error ‖φ − φ̂(t)‖ (controllers with an estimate of the true φ)"),
            "torques": ("tau", "Torque ‖τ(t)‖")}


def comparison_html(base: Scenario, rows: list[Row], skipped: dict[str, str], figures: dict[str, bytes]) -> str:
    """The self-contained report: setting, table (one row per controller), definitions, the `OVERLAYS` figures
    (PNG bytes by name) embedded."""
    s = base.setup
    head = "".join(f'<th{" class=l" if k == "label" else ""}>{html.escape(t)}</th>' for k, t, _ in COLUMNS)
    body = "".join(
        f'<tr data-controller="{r.entry.name}"><td class="l">{html.escape(r.entry.label)}</td>'
        f'<td class="l{"" if r.result.ok else " bad"}">{html.escape(r.metrics["status"])}</td>'
        + "".join(f"<td>{_cell(r.metrics[k], fmt)}</td>" for k, _, fmt in COLUMNS[2:]) + "</tr>" for r in rows)
    gains = "".join(f"<tr><td class=\"l\">{html.escape(r.entry.label)}</td><td class=\"l\">{html.escape(r.entry.source)}"
                    f"</td><td class=\"l\"><code>{html.escape(r.metrics['settings'])}</code>"
                    f"{'<br>' + html.escape(r.entry.note) if r.entry.note else ''}</td></tr>" for r in rows)
    setting = "".join(f"<li>{k}: <code>{html.escape(', '.join(_flat(base.data[k])))}</code></li>"
                      for k in ("robot", "plant", "trajectory", "simulation"))
    skip = "".join(f"<li>{html.escape(k)}: {html.escape(v)}</li>" for k, v in skipped.items())
    images = "".join(f'<h3>{title}</h3><img alt="{title}" src="{_data_uri(figures[name])}">'
                     for name, (_, title) in OVERLAYS.items())
    body_html = f"""<p>Scenario <b>{html.escape(base.name)}</b>: {html.escape(base.description)}</p>
<p>Every controller runs on the same arm ({type(s.plant.model).__name__}, φ = {_num(s.plant.phi.tolist())}), desired
trajectory, disturbance, initial state and integrator, {s.t_final:g} s:</p><ul>{setting}</ul>
<table id="comparison"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>
<p><small>RMS ‖e‖: root mean square of ‖e(t)‖ over the run; final ‖e‖ at the last instant; peak |τ|: largest joint
torque; energy ∫τᵀτ dt; final ‖φ̃‖ = ‖φ − φ̂‖ at the end (the constant model error for fixed-estimate laws, ‖φ‖ for PD,
which uses no model; — for the repetitive law, which learns a signal, not φ); t_conv: the last time
‖e(t)‖ exceeds 1 % of its maximum (— if it still does at the end); µs/step: wall time of the whole simulation (controller,
plant and RK4 stages) divided by the number of steps, on this machine.</small></p>
{"<p>Not applicable here:</p><ul>" + skip + "</ul>" if skip else ""}
{images}
<h2>Gains</h2><p>The book's gains for each law on the two-link arm (or the scenario's own, for the law it uses); they are
not tuned to a common bandwidth, so the table compares the laws as the book ran them.</p>
<table><thead><tr><th class="l">controller</th><th class="l">source</th><th class="l">settings</th></tr></thead>
<tbody>{gains}</tbody></table>"""
    return _page(f"robotadapt: controllers compared on {base.name}", body_html)


def write_comparison(base: Scenario, rows: list[Row], skipped: dict[str, str], out: Path) -> Path:
    """Write report.html (self-contained), comparison.json and the overlaid figures errors.png, parameter_errors.png,
    torques.png into `out`; returns the report's path."""
    out = writable_dir(out)
    figures = {name: _overlay(rows, signal) for name, (signal, _) in OVERLAYS.items()}
    for name, png in figures.items():
        atomic_write(out / f"{name}.png", partial(_write_bytes, png), binary=True)
    atomic_write(out / "comparison.json", lambda f: json.dump(
        {"scenario": base.name, "rows": [r.metrics for r in rows], "skipped": skipped}, f, indent=2))
    atomic_write(out / "report.html", lambda f: f.write(comparison_html(base, rows, skipped, figures)))
    return out / "report.html"
