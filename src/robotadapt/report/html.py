"""Reports a user looks at: the comparison of controllers on one scenario (report.html, figures embedded), the gallery
of the book's examples (index.html over the figures `robotadapt run` writes), and the α(t0) figure of the persistency of
excitation analysis (spec §5).

The comparison answers the book's open question (the comparison of the laws "remains to be investigated"): every
controller of chapters 6–7 on the same arm, desired trajectory, disturbance, initial state and step, each with the gains
the book (or a packaged scenario) gives it on the two-link arm (:data:`robotadapt.studies.compare.LINEUP`).
"""

from __future__ import annotations

import base64
import html
import io
import json
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..analysis.excitation import Excitation  # noqa: E402
from ..analysis.metrics import metrics  # noqa: E402
from ..files import atomic_write, writable_dir  # noqa: E402
from ..studies.compare import Row, flat, number_text  # noqa: E402
from ..studies.scenarios import Scenario, book_scenarios, load  # noqa: E402
from .figures import save_figures  # noqa: E402
from .files import save_result  # noqa: E402

_STYLE = """body{font-family:system-ui,sans-serif;margin:2em;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #ccc;padding:4px 8px;text-align:right;vertical-align:top}
th{background:#f0f0f0}td.l,th.l{text-align:left}img{max-width:100%}code{font-size:90%}.bad{color:#b00}
section{border-top:1px solid #ccc;margin-top:2em}.figs{display:flex;flex-wrap:wrap;gap:8px}.figs img{width:32%}"""


def _page(title: str, body: str) -> str:
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head>\n<body>\n<h1>{html.escape(title)}</h1>\n{body}\n</body></html>\n")


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
        save_figures(res, save_result(res, out / name, scenario.text), title=name)  # what `robotadapt run` writes
        wall = time.perf_counter() - wall
        entries.append(GalleryEntry(name, scenario.description, str(scenario.data.get("notes", "")),
                                    {k: scenario.data[k] for k in ("robot", "plant", "trajectory", "controller",
                                                                    "simulation")},
                                    metrics(res), scenario.setup.t_final, t_scenario, wall))
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
        settings = "".join(f"<tr><th class=\"l\">{k}</th><td class=\"l\">{html.escape(', '.join(flat(v)))}</td></tr>"
                           for k, v in e.settings.items())
        metrics = "".join(f"<tr><th class=\"l\">{html.escape(k)}</th><td class=\"l\">{html.escape(number_text(v))}</td></tr>"
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
    setting = "".join(f"<li>{k}: <code>{html.escape(', '.join(flat(base.data[k])))}</code></li>"
                      for k in ("robot", "plant", "trajectory", "simulation"))
    skip = "".join(f"<li>{html.escape(k)}: {html.escape(v)}</li>" for k, v in skipped.items())
    images = "".join(f'<h3>{title}</h3><img alt="{title}" src="{_data_uri(figures[name])}">'
                     for name, (_, title) in OVERLAYS.items())
    body_html = f"""<p>Scenario <b>{html.escape(base.name)}</b>: {html.escape(base.description)}</p>
<p>Every controller runs on the same arm ({type(s.plant.model).__name__}, φ = {number_text(s.plant.phi.tolist())}), desired
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
