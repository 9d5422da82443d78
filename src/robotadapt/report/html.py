"""Reports a user looks at: the comparison of controllers on one scenario (report.html, figures embedded), the gallery
of the book's examples (index.html over the figures `robotadapt run` writes), and the α(t0) figure of the persistency of
excitation analysis (§6.5; docs/laws.md#persistency-of-excitation).

The comparison answers the book's open question (the comparison of the laws "remains to be investigated"): every
controller of chapters 6–7 on the same arm, desired trajectory, disturbance, initial state and step, each with the gains
the book (or a packaged scenario) gives it on the two-link arm (:func:`robotadapt.studies.compare.contenders`).
"""

from __future__ import annotations

import base64
import html
import json
import time
import unicodedata
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from ..analysis.excitation import Excitation
from ..analysis.metrics import metrics
from ..files import atomic_write, writable_dir
from ..studies.compare import Row, flat, number_text
from ..studies.scenarios import Scenario, book_scenarios, load
from .figures import EFFORT, POSITION, RUN_FIGURES, joint_types, norm_unit, positive, save_figures, style
from .files import save_result
from .output import PNG, FigureFormat, new_figure, render, save_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

_STYLE = """body{font-family:system-ui,sans-serif;margin:2em;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #ccc;padding:4px 8px;text-align:right;vertical-align:top}
th{background:#f0f0f0}td.l,th.l{text-align:left}img{max-width:100%}code{font-size:90%}.bad{color:#b00}
section{border-top:1px solid #ccc;margin-top:2em}.figs{display:flex;flex-wrap:wrap;gap:8px}.figs img{width:32%}"""


def _page(title: str, body: str) -> str:
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head>\n<body>\n<h1>{html.escape(title)}</h1>\n{body}\n</body></html>\n")


#: the media types of the figure formats a browser shows in an <img> (a pdf it does not)
IMAGE_TYPES = {"png": "image/png", "svg": "image/svg+xml"}


def _data_uri(data: bytes, format: str) -> str:
    return f"data:{IMAGE_TYPES[format]};base64," + base64.b64encode(data).decode("ascii")


# ---------------------------------------------------------------------------------------------------------------------
# persistency of excitation


def _log_with_zero(ax: Any, t: np.ndarray, y: np.ndarray, floor: float, label: str, **kw: Any) -> None:
    """Plot y ≥ 0 on a log axis from its first nonzero value (a sum that starts at 0 is no datum); later zeros (a
    rank-deficient window: round-off) are drawn at `floor`, which then becomes the bottom of the axis."""
    start = int(np.argmax(y > floor)) if np.any(y > floor) else 0
    zero = bool(np.any(y[start:] <= floor))
    ax.semilogy(t[start:], np.maximum(y[start:], floor), label=label + (" (0 drawn at the bottom)" if zero else ""),
                **kw)
    if zero:
        ax.set_ylim(bottom=floor / 2)


def _coincide(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-9, atol=0.0))


#: the smaller eigenvalue's line where it may lie on the larger one: dashed, hollow markers on top
_UNDER = {"linestyle": "-", "linewidth": 3.0, "alpha": 0.5}
_OVER = {"linestyle": "--", "marker": "o", "markevery": 0.08, "markersize": 5, "markerfacecolor": "none"}


def coincidence_note(high: np.ndarray, low: np.ndarray, p: int) -> str:
    """What the legend says where λ_max and λ_min coincide: one parameter has one eigenvalue; with more, the Gram
    matrix (6.5.2) is a multiple of the identity there (Example 6.5.2: sin t over whole periods excites m and b equally)."""
    if not _coincide(high, low):
        return ""
    return " (the curves coincide: one parameter)" if p == 1 else " (the curves coincide: λ_max = λ_min, equal excitation)"


def _pair(ax: Any, t: np.ndarray, high: np.ndarray, low: np.ndarray, floor: float, labels: tuple[str, str],
          p: int) -> None:
    """λ_max and λ_min on a log axis; where they coincide both stay visible: the larger one wide and pale, the smaller
    one dashed with markers, and the legend says why (:func:`coincidence_note`, `p` the parameters analysed)."""
    ax.semilogy(t, positive(high), label=labels[0], color="C0", **_UNDER)
    note = coincidence_note(high, low, p)
    _log_with_zero(ax, t, low, floor, labels[1] + note, color="C1", **_OVER)


def _power_of_ten(x: float) -> str:
    """`x` in mathtext: 1e-06 → 10^{-6}, 2.5e-06 → 2.5·10^{-6}."""
    mantissa, _, exponent = f"{x:.2g}".partition("e")
    if not exponent:
        return f"${mantissa}$"
    factor = "" if mantissa == "1" else mantissa + r" \cdot "
    return f"${factor}10^{{{int(exponent)}}}$"


def excitation_plot(exc: Excitation, title: str = "") -> Figure:
    """The figure of :func:`excitation_figure`, returned open."""
    floor = 1e-12 * max(exc.beta_max, 1e-300)
    fig = new_figure(figsize=(7, 6.5))
    ax_w, ax_c = fig.subplots(2, 1)
    _pair(ax_w, exc.t0, exc.beta, exc.alpha, floor, (r"$\beta(t_0) = \lambda_{\max}$", r"$\alpha(t_0) = \lambda_{\min}$"),
          len(exc.param_names))
    ax_w.axhline(exc.rtol * exc.beta_max, color="k", linestyle=":",
                 label=f"PE threshold {_power_of_ten(exc.rtol)}" + r"$\,\max\,\beta$")
    verdict = "persistently exciting" if exc.persistently_exciting else "NOT persistently exciting"
    ax_w.set_title(f"{title}: {verdict} ($\\rho$ = {exc.window:.4g} s)".lstrip(": "))
    ax_w.set_xlabel("window start $t_0$ (s)")
    ax_w.set_ylabel(r"eigenvalues of $\int_{t_0}^{t_0+\rho} Y_d^T Y_d\,dt$")
    _pair(ax_c, exc.t_cum, exc.lambda_max_cum, exc.lambda_min_cum, floor, (r"$\lambda_{\max}$", r"$\lambda_{\min}$"),
          len(exc.param_names))
    grows = "grows" if exc.integral_grows else "levels off"
    ax_c.set_title(f"(6.6.18): $\\lambda_{{\\min}} \\int_0^t Y_d^T Y_d\\,d\\sigma$ {grows} "
                   f"($\\propto t^{{{exc.growth_exponent:.2f}}}$ over the second half)")
    ax_c.set_xlabel("time $t$ (s)")
    ax_c.set_ylabel(r"eigenvalues of $\int_0^t Y_d^T Y_d\,d\sigma$")
    for ax in (ax_w, ax_c):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    return fig


def excitation_figure(exc: Excitation, path: Path, title: str = "", output: FigureFormat = PNG) -> Path:
    """α(t0), β(t0) of the windowed Gram matrix (6.5.2) with the PE threshold, and the extreme eigenvalues of the
    growing integral ∫_0^t Y_dᵀ Y_d (6.6.18); log scale, zero drawn at the bottom of the axis; written to `path` in
    `output`'s format."""
    return save_figure(excitation_plot(exc, title), path, output)


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


def run_gallery(out: Path, t_final_cap: float | None = None, progress: bool = False,
                output: FigureFormat = PNG) -> list[GalleryEntry]:
    """Run every book scenario (capped at `t_final_cap` seconds of simulated time if given), write into out/NAME/ what
    `robotadapt run` writes (result.npz, metrics.json, scenario.toml and the three figures, in `output`'s format), and
    index.html into `out`."""
    out = writable_dir(out)
    entries = []
    for name in book_scenarios():
        scenario = load(name)
        t_scenario = scenario.setup.t_final
        if t_final_cap is not None and t_final_cap < t_scenario:
            scenario = load(name, [f"simulation.t_final={t_final_cap!r}"])
        wall = time.perf_counter()
        res = scenario.run(progress)
        save_figures(res, save_result(res, out / name, scenario.text), name,  # what `robotadapt run` writes
                     scenario.setup.controller.model, output)
        wall = time.perf_counter() - wall
        entries.append(GalleryEntry(name, scenario.description, str(scenario.data.get("notes", "")),
                                    {k: scenario.data[k] for k in ("robot", "plant", "trajectory", "controller",
                                                                    "simulation")},
                                    metrics(res), scenario.setup.t_final, t_scenario, wall))
        if progress:
            print(f"{name}: {res.status}, {wall:.1f} s", flush=True)
    atomic_write(out / "index.html", lambda f: f.write(gallery_html(entries, output)))
    return entries


def _gallery_figure(path: str, alt: str, format: str) -> str:
    """One figure of the gallery: an image (png, svg), or for a pdf, which a browser does not show in an <img>, a link
    that opens it."""
    if format in IMAGE_TYPES:
        return f'<img src="{path}" alt="{alt}">'
    return f'<a href="{path}">{alt} ({format})</a>'


def gallery_html(entries: list[GalleryEntry], output: FigureFormat = PNG) -> str:
    """The gallery page: per example its description, notes, settings, metrics and the three figures (the files
    written in `output`'s format)."""
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
        if e.metrics.get("status", "ok") != "ok":  # its figures end where it stopped: say so, not empty axes alone
            cap += (f'<p class="bad">This run stopped early, at t = {e.metrics["t_end"]:.4g} s of {e.t_final:g} s: '
                    f"{html.escape(str(e.metrics['status']))}. Its figures end there.</p>")
        settings = "".join(f"<tr><th class=\"l\">{k}</th><td class=\"l\">{html.escape(', '.join(flat(v)))}</td></tr>"
                           for k, v in e.settings.items())
        metrics = "".join(f"<tr><th class=\"l\">{html.escape(k)}</th><td class=\"l\">{html.escape(number_text(v))}</td></tr>"
                          for k, v in e.metrics.items())
        figs = "".join(_gallery_figure(f"{e.name}/{output.name(f)}", f"{e.name} {f.replace('_', ' ')}", output.format)
                       for f in RUN_FIGURES)
        parts.append(f'<section id="{e.name}" data-scenario="{e.name}"><h2>{e.name}</h2>'
                     f"<p>{html.escape(e.description)}</p><p><small>{html.escape(e.notes)}</small></p>{cap}"
                     f'<div class="figs">{figs}</div><h3>Settings</h3><table>{settings}</table>'
                     f"<h3>Metrics</h3><table>{metrics}</table><p>run time {e.wall_time:.1f} s</p></section>")
    return _page("robotadapt: the book's examples and problems", "\n".join(parts))


# ---------------------------------------------------------------------------------------------------------------------
# comparison of controllers


COLUMNS = (("label", "controller", "{}"), ("status", "status", "{}"), ("rms_error_norm", "RMS ‖e‖", "{:.3g}"),
           ("final_error", "final ‖e‖", "{:.3g}"), ("peak_torque", "peak |τ|", "{:.3g}"),
           ("control_energy", "energy ∫τᵀτ", "{:.4g}"), ("final_phi_error", "final ‖φ̃‖", "{:.3g}"),
           ("convergence_time", "t_conv (s)", "{:.3g}"), ("us_per_step", "µs/step", "{:.1f}"))


def _cell(value: Any, fmt: str) -> str:
    return "—" if value is None else fmt.format(value)


def display_width(text: str) -> int:
    """Columns `text` takes in a terminal: combining marks (the hat of φ̂) 0, wide East Asian characters 2."""
    return sum(0 if unicodedata.combining(c) else 2 if unicodedata.east_asian_width(c) in "WF" else 1 for c in text)


def _pad(text: str, width: int, left: bool) -> str:
    fill = " " * max(width - display_width(text), 0)
    return text + fill if left else fill + text


def table_text(rows: list[Row]) -> str:
    """The comparison table as aligned text (what `robotadapt compare` prints), padded by display width."""
    cells = [[title for _, title, _ in COLUMNS]]
    cells += [[_cell(r.metrics[k], fmt) if k != "status" else r.result.status.headline for k, _, fmt in COLUMNS]
              for r in rows]
    widths = [max(display_width(c[i]) for c in cells) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(_pad(c, w, i == 0) for i, (c, w) in enumerate(zip(line, widths, strict=True)))
                     for line in cells)


#: the panels of the comparison figures: lineup names by family; a name in none (the scenario's own law) goes last
FAMILIES = (("fixed estimates, no adaptation", ("computed_torque", "pd", "pd_gravity")),
            ("Slotine–Li and its modifications", ("slotine_li", "sign_robust", "sigma", "composite")),
            ("passivity class (Table 6.4.1)", ("passivity", "passivity_pi")),
            ("computed torque, desired compensation, learning", ("adaptive_computed_torque", "dcal", "repetitive")))
#: drawn in grey in the other panels, as a common reference
def _reference(rows: list[Row]) -> int | None:
    """The row of the scenario's own law (the comparison's reference), drawn in grey behind the others."""
    return next((i for i, r in enumerate(rows) if r.entry.reference), None)


def _drawable(y: np.ndarray | None) -> bool:
    """A signal with a finite positive sample: what a log axis can draw."""
    return y is not None and bool(np.any(np.isfinite(y) & (y > 0)))


def _families(rows: list[Row]) -> list[tuple[str, list[int]]]:
    """(panel title, row indices) of the panels that have rows, in `FAMILIES` order; leftover rows in a last panel."""
    placed = {name for _, names in FAMILIES for name in names}
    panels = [(title, [i for i, r in enumerate(rows) if r.entry.name in names]) for title, names in FAMILIES]
    panels.append(("other", [i for i, r in enumerate(rows) if r.entry.name not in placed]))
    return [(title, idx) for title, idx in panels if idx]


def _signal(row: Row, signal: str) -> np.ndarray | None:
    res = row.result
    y = {"e": res.e, "phi": res.phi_err, "tau": res.tau}[signal]
    return None if y is None or y.shape[-1] == 0 else np.linalg.norm(y, axis=-1)


def overlay_figure(rows: list[Row], signal: str) -> Figure:
    """Small multiples of ‖e(t)‖, ‖φ̃(t)‖ (log scale, from each run's first nonzero value, over at most 12 decades)
    or ‖τ(t)‖ (over 4): one panel per family of laws (`FAMILIES`), every law in its own colour and dash (the same in
    every figure), the reference (the scenario's own law) in grey behind the other panels."""
    panels = _families(rows)
    cols = 2 if len(panels) > 1 else 1
    nrows = -(-len(panels) // cols)
    fig = new_figure(figsize=(6.2 * cols, 1.2 + 3.2 * nrows))
    axes = fig.subplots(nrows, cols, sharex=True, sharey=True, squeeze=False)
    joints = joint_types(rows[0].entry.scenario.setup.controller.model) if rows else None
    norms = [_signal(r, signal) for r in rows]
    ref = _reference(rows)
    ref = ref if ref is not None and _drawable(norms[ref]) else None
    finite = [y[np.isfinite(y) & (y > 0)] for y in norms if y is not None]
    top = max((float(v.max()) for v in finite if v.size), default=0.0)
    low = min((float(v.min()) for v in finite if v.size), default=0.0)
    for ax, (title, idx) in zip(axes.flat, panels, strict=False):
        reference = norms[ref] if ref is not None and ref not in idx else None
        if ref is not None and reference is not None:
            ax.semilogy(rows[ref].result.t, positive(reference), color="0.75", linewidth=1.0,
                        label=f"{rows[ref].entry.label} (reference)")
        for i in idx:
            y = norms[i]
            if y is not None and _drawable(y):
                ax.semilogy(rows[i].result.t, positive(y), label=rows[i].entry.label, linewidth=1.4, **style(i))
        ax.set_title(title, fontsize="medium")
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize="x-small")
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    if top > 0:  # the axes share y
        axes[0, 0].set_ylim(max(low, (1e-4 if signal == "tau" else 1e-12) * top) / 2, 3 * top)
    ylabel = {"e": f"$\\Vert e(t)\\Vert$ ({norm_unit(POSITION, joints)})", "phi": r"$\Vert\varphi - \hat{\varphi}(t)\Vert$",
              "tau": f"$\\Vert\\tau(t)\\Vert$ ({norm_unit(EFFORT, joints)})"}[signal]
    for ax in axes[:, 0]:
        ax.set_ylabel(ylabel)
    for ax in axes[-1, :]:
        ax.set_xlabel("time $t$ (s)")
    fig.suptitle(OVERLAYS[{"e": "errors", "phi": "parameter_errors", "tau": "torques"}[signal]][1])
    fig.tight_layout()
    return fig


def laws_figure(rows: list[Row], max_torque: float | None = None) -> Figure:
    """Small multiples, one panel per law on shared axes, so that twelve laws stay readable: ‖e(t)‖ (log, left) and
    max_i |τ_i(t)| (right, the torque budget dotted when there is one), the reference's ‖e(t)‖ in grey behind the others;
    the title gives RMS ‖e‖ and the peak torque."""
    cols = min(4, max(len(rows), 1))
    nrows = -(-len(rows) // cols)
    fig = new_figure(figsize=(3.6 * cols, 0.8 + 2.4 * nrows))
    axes = fig.subplots(nrows, cols, sharex=True, sharey=True, squeeze=False)
    norms = [np.linalg.norm(r.result.e, axis=-1) for r in rows]
    finite = np.concatenate([y[np.isfinite(y) & (y > 0)] for y in norms] or [np.ones(1)])
    top = float(finite.max()) if finite.size else 1.0
    peak = max([float(np.nanmax(np.abs(r.result.tau))) for r in rows if np.isfinite(r.result.tau).any()] or [1.0])
    ref = _reference(rows)
    ref = ref if ref is not None and _drawable(norms[ref]) else None
    twins = []
    for i, (ax, row) in enumerate(zip(axes.flat, rows, strict=False)):
        if ref is not None and i != ref:
            ax.semilogy(rows[ref].result.t, positive(norms[ref]), color="0.8", linewidth=1.0)
        if _drawable(norms[i]):  # a run that stopped at its first step has nothing to draw
            ax.semilogy(row.result.t, positive(norms[i]), linewidth=1.3, **style(i))
        twin = ax.twinx()
        twin.plot(row.result.t, np.max(np.abs(row.result.tau), axis=-1), color="C3", linewidth=0.8, alpha=0.7)
        if max_torque is not None:
            twin.axhline(max_torque, color="C3", linestyle=":", linewidth=0.8)
        twin.set_ylim(0, 1.1 * max(peak, max_torque or 0.0))
        twins.append(twin)
        over = max_torque is not None and row.metrics["peak_torque"] > max_torque
        ax.set_title(f"{row.entry.label}\nRMS ‖e‖ {row.metrics['rms_error_norm']:.3g}, peak |τ| "
                     f"{row.metrics['peak_torque']:.3g}{' (over)' if over else ''}", fontsize="small",
                     color="C3" if over else "k")
        ax.grid(True, alpha=0.3)
    for k, twin in enumerate(twins):
        if k % cols != cols - 1 and k != len(twins) - 1:
            twin.tick_params(labelright=False)
        else:
            twin.set_ylabel("max |τ_i| (red)", fontsize="small")
    for ax in axes.flat[len(rows):]:
        ax.set_visible(False)
    axes[0, 0].set_ylim(1e-10 * top, 3 * top)
    for ax in axes[:, 0]:
        ax.set_ylabel("‖e(t)‖")
    for ax in axes[-1, :]:
        ax.set_xlabel("time $t$ (s)")
    fig.suptitle("Each law on its own: tracking error (the reference in grey) and peak joint torque"
                 + ("" if max_torque is None else f", budget {max_torque:g} dotted"))
    fig.tight_layout()
    return fig


LAWS_TITLE = "Each law on its own: ‖e(t)‖ and peak torque"
OVERLAYS = {"errors": ("e", "Tracking error ‖e(t)‖"),
            "parameter_errors": ("phi", "Parameter error ‖φ − φ̂(t)‖ (controllers with an estimate of the true φ)"),
            "torques": ("tau", "Control input ‖τ(t)‖")}


def _gains_text(budget: dict[str, Any] | None, rows: list[Row]) -> str:
    """What the gains of the report are: the book's, or tuned to one objective under one torque budget (`budget`)."""
    if budget is None:
        return ("The scenario's own law is the reference, run as it is given; every other law has the book's gains, "
                "scaled to the arm where it is not the book's (each row's settings say how), from the same initial "
                "estimate. They are not tuned to a common bandwidth: <code>--fair</code> tunes them.")
    over = [r.entry.label for r in rows if not r.metrics.get("within_budget")]
    return (f"Fair comparison: every law's own gains tuned by <code>robotadapt tune</code> to minimise "
            f"<code>{html.escape(str(budget['objective']))}</code> under the same torque budget max |τ_i(t)| ≤ "
            f"{budget['max_torque']:g} (docs: tuning.md); a law that cannot be differentiated keeps the book's gains "
            f"(its settings say why)." + (f" Over the budget: {html.escape(', '.join(over))}." if over else
                                         " Every law stays within the budget."))


def comparison_html(base: Scenario, rows: list[Row], skipped: dict[str, str], figures: dict[str, str],
                    budget: dict[str, Any] | None = None) -> str:
    """The self-contained report: setting, table (one row per controller), definitions, the `OVERLAYS` figures and
    "laws" embedded (data URIs by name); with `budget` (objective, max_torque) the gains are the fair comparison's
    tuned ones."""
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
    images = "".join(f'<h3>{title}</h3><img alt="{title}" src="{figures[name]}">'
                     for name, title in [(n, t) for n, (_, t) in OVERLAYS.items()] + [("laws", LAWS_TITLE)])
    body_html = f"""<p>Scenario <b>{html.escape(base.name)}</b>: {html.escape(base.description)}</p>
<p>Every controller runs on the same arm ({type(s.plant.model).__name__}, φ = {number_text(s.plant.phi.tolist())}), desired
trajectory, disturbance, initial state and integrator, {s.t_final:g} s:</p><ul>{setting}</ul>
<table id="comparison"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>
<p><small>RMS ‖e‖: √(mean over the logged samples of ‖e(t)‖²), the metric <code>rms_error_norm</code>; final ‖e‖
at the last instant; peak |τ|: largest joint torque; energy ∫τᵀτ dt; final ‖φ̃‖ = ‖φ − φ̂‖ at the end (the constant
model error for fixed-estimate laws, ‖φ‖ for PD, which uses no model; — for the repetitive law, which learns a signal,
not φ); t_conv: the last time ‖e(t)‖ exceeds 1 % of its maximum (— if it still does at the end); µs/step: wall time of
the whole simulation (controller, plant and RK4 stages) divided by the number of steps, on this machine.</small></p>
{"<p>Not applicable here:</p><ul>" + skip + "</ul>" if skip else ""}
{images}
<h2>Gains</h2><p>{_gains_text(budget, rows)}</p>
<table><thead><tr><th class="l">controller</th><th class="l">source</th><th class="l">settings</th></tr></thead>
<tbody>{gains}</tbody></table>"""
    return _page(f"robotadapt: controllers compared on {base.name}", body_html)


def _write_text(text: str, f: IO[str]) -> None:
    f.write(text)


def write_comparison(base: Scenario, rows: list[Row], skipped: dict[str, str], out: Path,
                     budget: dict[str, Any] | None = None, output: FigureFormat = PNG) -> Path:
    """Write report.html (self-contained), comparison.json, the overlaid figures errors.png, parameter_errors.png,
    torques.png and the small multiples laws.png (the suffix `output`'s format) into `out`; returns the report's path.
    `budget`: the fair comparison's objective and torque budget.

    The report embeds the very files when a browser shows them in an <img> (png, svg: data URIs, so that the ids
    inside one svg cannot clash with another's); for pdf it embeds a PNG drawn at the same dpi."""
    out = writable_dir(out)
    figures = {name: overlay_figure(rows, signal) for name, (signal, _) in OVERLAYS.items()}
    figures["laws"] = laws_figure(rows, None if budget is None else budget["max_torque"])
    shown = output if output.format in IMAGE_TYPES else replace(output, format="png")
    images = {}
    for name, fig in figures.items():
        drawn = None if shown == output else render(fig, shown)
        path = save_figure(fig, out / output.name(name), output)
        images[name] = _data_uri(path.read_bytes() if drawn is None else drawn, shown.format)
    if budget is not None:  # each row's scenario as it ran, tuned: `robotadapt run` reproduces the row
        (out / "tuned").mkdir(exist_ok=True)
        for r in rows:
            text = (f"# robotadapt compare {base.name} --fair: {r.entry.label}, {budget['objective']} "
                    f"{r.metrics['objective']:.12g}, max |tau| {r.metrics['peak_torque']:.6g} (budget "
                    f"{budget['max_torque']:g})\n" + r.entry.scenario.text)
            atomic_write(out / "tuned" / f"{r.entry.name}.toml", partial(_write_text, text))
            r.metrics["scenario_file"] = f"tuned/{r.entry.name}.toml"
    atomic_write(out / "comparison.json", lambda f: json.dump(
        {"scenario": base.name, "fair": budget, "rows": [r.metrics for r in rows], "skipped": skipped}, f, indent=2))
    atomic_write(out / "report.html", lambda f: f.write(comparison_html(base, rows, skipped, images, budget)))
    return out / "report.html"
