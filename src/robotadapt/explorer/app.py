"""The explorer's page, one Bokeh document per browser tab: the scenario and its law, a field (and a slider on a log
scale) per gain with its unit, the settings, the run's figures, metrics and health warnings, a pinned run beneath.

Every change re-runs the loop (:class:`~robotadapt.explorer.runner.Runner`: the newest change wins) and writes the view
into the page's URL (`history.replaceState`); a bad value gets the ConfigError's line beside its field. The page marks
each outcome it shows in `window.robotadaptDrawn` (`{run, t}`: the run's ticket and `performance.now()` just after the
animation frame that painted its figures, or showed its refusal), which the browser tests and the benchmark read."""

from __future__ import annotations

import html
import logging
import math
import re
import time
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, replace
from functools import cached_property, partial
from typing import Any

import numpy as np
from bokeh.document import Document
from bokeh.layouts import column, row
from bokeh.models import ColumnDataSource, CustomJS, CustomJSTickFormatter
from bokeh.models.widgets import (
    Button,
    CheckboxButtonGroup,
    DataTable,
    Div,
    Select,
    Slider,
    TableColumn,
    TextInput,
    Toggle,
)
from jinja2 import Template

from ..studies.scenarios.loader import parse_value
from ..validation import ConfigError
from .catalogue import Catalogue, Control, Run, one_line
from .curves import Curves, curves, metric_rows
from .panels import Figures
from .runner import Outcome, Runner
from .view import FIGURES, View, key_of

log = logging.getLogger(__name__)

WIDTH = 360  # of the column of controls, px
#: metrics.json's entries the table shows first, and those the headline over the figures repeats
FIRST = ("status", "rms_error", "rms_error_norm", "final_abs_error", "max_abs_torque", "control_energy",
         "final_phi_hat", "final_phi_error")
HEADLINE = ("status", "rms_error", "max_abs_torque", "final_phi_error")
#: the page's URL and its redraw mark, from the state source's data (a source, not a widget: no layout to redo); the
#: figures paint in the first animation frame after their data came (Bokeh throttles painting to frames), so the mark
#: is set just after that frame, and the server told (`painted`): it sends the run's texts then, not before
STATE_JS = """
const url = state.data.url[0], run = state.data.run[0];
if (url !== window.location.search) { history.replaceState(history.state, '', url); }
if (run !== window.robotadaptRun) {
  window.robotadaptRun = run;
  requestAnimationFrame(() => setTimeout(() => {
    window.robotadaptDrawn = {run: run, t: performance.now()};
    painted.data = {run: [run]};
  }, 0));
}"""
DOWNLOAD_JS = "window.location.assign('download' + window.location.search)"
SLIDER_FORMAT = "return (10 ** tick).toPrecision(3)"
ERROR_STYLE: dict[str, str | None] = {"color": "#b00020", "font-weight": "bold"}
#: the places of the figures shown, then of the metrics table, each a root of its own: a figure whose axes change lays out
#: itself, not the page (Bokeh lays out a root and everything in it at once)
SLOTS = len(FIGURES) + 1
#: two changes to BokehJS's paint that draw the same (bokeh/bokeh#15286): at every paint each renderer rewrites its
#: position stylesheet, then each of its visuals reads its `--bk-*` CSS variables, so the browser works out the page's
#: styles again for every renderer. The page sets no such variable (nor does Bokeh), so the visuals take their values
#: from the models, and a stylesheet is rewritten only when its text changes: five figures paint in about 35 ms instead
#: of 60 at a redraw (Chromium traces of Example 6.3.1). Without these BokehJS internals the page draws the same, slower.
#: Bokeh's own functions are kept in `window.robotadaptPaint` (the browser tests paint with them too).
PAINT_JS = """(() => {
  try {
    const visual = Bokeh.require("core/visuals/visual").VisualProperties.prototype;
    const sheet = Bokeh.require("core/dom").InlineStyleSheet.prototype, update = sheet._update;
    window.robotadaptPaint = {visual: visual, sheet: sheet, css: visual._get_css_value, update: update};
    visual._get_css_value = () => "";
    sheet._update = function (css) { if (this.el.textContent !== css) { update.call(this, css); } };
  } catch (e) { console.warn("robotadapt explorer: BokehJS paints as it is", e); }
})();"""
TEMPLATE = Template("""{% extends base %}
{% block postamble %}<script>""" + PAINT_JS + """</script><style>
  .ra-page { display: grid; grid-template-columns: max-content minmax(0, 1fr); gap: 16px; padding: 8px; }
  .ra-grid { display: grid; grid-template-columns: repeat(2, minmax(0, 1fr)); gap: 8px; }
</style>{% endblock %}
{% block contents %}<div class="ra-page">
  <div>{{ embed(roots.controls) }}</div>
  <div>{{ embed(roots.head) }}<div class="ra-grid">{% for i in range(slots) %}<div>{{ embed(roots["slot" ~ i]) }}</div>
  {% endfor %}</div>{{ embed(roots.tail) }}</div>
</div>{{ embed(roots.state) }}{% endblock %}""")


@dataclass(frozen=True, eq=False)
class Shown:
    """What a page shows of a view: its controls, the laws to choose from (name → label, the scenario's own first),
    the laws that do not apply and why, where the law and its gains come from; its run (None: it did not build, `error`
    says why) and curves; the run's metrics rows when first asked for."""

    view: View
    controls: list[Control]
    laws: dict[str, str]
    skipped: dict[str, str]
    source: str
    run: Run | None = None
    error: ConfigError | None = None
    curves: Curves | None = None

    @cached_property
    def rows(self) -> dict[str, str]:
        return metric_rows(self.run.metrics) if self.run is not None else {}


def prepare(catalogue: Catalogue, view: View) -> Shown:
    """Everything the page shows of `view`, on the worker thread: a ConfigError of its settings (no lineup, no controls)
    is raised, one of its law's gains is the Shown's `error`."""
    entries, skipped = catalogue.lineup(view)
    entry = catalogue.entry(view)
    controls = catalogue.controls(view)
    laws = {name: e.label + (" (the scenario's)" if e.reference else "") for name, e in entries.items()}
    source = f"{entry.scenario.description} — law: {entry.label}; {entry.source}" + (f"; {entry.note}" if entry.note else "")
    try:
        run = catalogue.run(view)
    except ConfigError as exc:
        return Shown(view, controls, laws, skipped, source, error=exc)
    return Shown(view, controls, laws, skipped, source, run, None, curves(run))


def css_class(key: str) -> str:
    """A field's CSS class: `controller.Kv` → `ra-controller-Kv`."""
    return "ra-" + re.sub(r"\W+", "-", key)


@dataclass(eq=False)
class Field:
    """A control's widgets: its text field, its error line and its slider (None: a value without one)."""

    control: Control
    text: TextInput
    error: Div
    slider: Slider | None

    def position(self, text: str) -> float | None:
        """The slider's position (log10 of the value, or of the factor of the lineup's list) for `text`; None when it
        has none."""
        try:
            value = np.asarray(parse_value(text), dtype=float)
            default = np.asarray(self.control.default, dtype=float)
        except (TypeError, ValueError):
            return None
        ratio = value / default if value.shape == default.shape else np.array(np.nan)
        factor = float(value) if self.control.scalar else float(ratio.flat[0]) if np.allclose(ratio, ratio.flat[0]) \
            else math.nan
        return math.log10(factor) if factor > 0 and math.isfinite(factor) else None

    def value(self, position: float) -> str:
        """The TOML text of the gain at slider `position`, to three significant digits (of the factor of a list)."""
        factor = float(f"{10 ** position:.3g}")
        if self.control.scalar:
            return f"{factor:g}"
        return one_line((np.asarray(self.control.default, dtype=float) * factor).round(12).tolist())


class Page:
    """One tab's document: widgets, figures and the runs behind them (module docstring)."""

    def __init__(self, doc: Document, catalogue: Catalogue, executor: Executor, view: View) -> None:
        self.doc, self.catalogue = doc, catalogue
        self.runner = Runner(executor, self._done)
        self.closed = False
        self.view, refused = view.checked()
        self.fields: dict[str, Field] = {}
        self.figures: Figures | None = None
        self.current: Shown | None = None
        self.pinned: Shown | None = None
        self.seconds: float | None = None  # the last run's, for the progress of the next
        self.reference: str | None = None  # the lineup's name of the scenario's own controller

        self.scenario = Select(title="scenario", options=list[str | None](catalogue.names), value=self.view.scenario,
                               width=WIDTH, css_classes=["ra-scenario"])
        self.scenario.on_change("value", self._scenario)
        self.law = Select(title="law (the book's gains, scaled to this arm)", options=[],
                          width=WIDTH, name="law", css_classes=["ra-law"])
        self.law.on_change("value", self._law)
        self.skipped = Div(width=WIDTH, styles={"color": "#555"})
        self.gains = column(Div(text="<b>gains</b>"), width=WIDTH)
        self.settings = column(Div(text="<b>settings</b>"), width=WIDTH)
        self.others = Div(width=WIDTH)
        self.notice = "<br>".join(html.escape(str(exc)) for exc in refused)  # the URL's refused assignments, shown
        self.message = Div(width=WIDTH, styles=ERROR_STYLE, name="message", text=self.notice)  # until the next change
        self.status = Div(sizing_mode="stretch_width", name="status")
        self.source = Div(sizing_mode="stretch_width", styles={"color": "#444"})
        self.warnings = Div(sizing_mode="stretch_width", name="warnings", styles={"color": "#a05000"})
        self.table = ColumnDataSource({"metric": [], "value": [], "pinned": []}, name="metrics")
        self.metrics = DataTable(source=self.table, index_position=None, sizing_mode="stretch_width", height=260,
                          columns=[TableColumn(field="metric", title="metric (metrics.json)"),
                                   TableColumn(field="value", title="this run"),
                                   TableColumn(field="pinned", title="pinned run")])
        # a table whose rows stay the same redraws only when its view says so (Bokeh 3 redraws on a change of indices)
        self.table.js_on_change("data", CustomJS(args={"table": self.metrics}, code="table.view.change.emit()"))
        self.state = ColumnDataSource({"url": [self.view.query()], "run": [0]}, name="state")
        self.painted = ColumnDataSource({"run": [0]}, name="painted")  # the run whose figures the browser painted last
        self.painted.on_change("data", self._painted)
        self.unsent: tuple[Shown, Outcome] | None = None  # the texts of the run drawn last, until it is painted
        state = CustomJS(args={"state": self.state, "painted": self.painted}, code=STATE_JS)
        self.state.js_on_change("data", state)
        doc.js_on_event("document_ready", state)  # a run that ended before the page connected
        pin = Button(label="pin this run", width=170, name="pin", css_classes=["ra-pin"])
        pin.on_click(self._pin)
        unpin = Button(label="unpin", width=170)
        unpin.on_click(self._unpin)
        download = Button(label="download run (.zip)", width=170, name="download")
        download.js_on_click(CustomJS(code=DOWNLOAD_JS))
        reset = Button(label="the lineup's gains", width=170)
        reset.on_click(self._reset)
        fit = Button(label="fit axes", width=170, name="fit")
        fit.on_click(self._fit)
        self.large = Toggle(label="lecture fonts", active=self.view.large, width=170)
        self.large.on_change("active", self._fonts)
        # the figures shown: a hidden one is out of the document, so the browser does not paint it (its curves still come)
        self.shown = CheckboxButtonGroup(labels=list(FIGURES.values()), width=WIDTH, name="figures",
                                         active=[i for i, n in enumerate(FIGURES) if n not in self.view.hidden])
        self.shown.on_change("active", self._shown)
        self.slots = [column(Div(text="the first run is on its way…" if i == 0 else ""), sizing_mode="stretch_width",
                             name=f"slot{i}") for i in range(SLOTS)]
        self.roots = [column(Div(text="<b>robotadapt explorer</b>", styles={"font-size": "150%"}), self.scenario,
                             self.law, self.skipped, self.gains, self.settings, self.others,
                             Div(text="<b>figures shown</b>"), self.shown, row(pin, unpin),
                             row(download, self.large), row(reset, fit), self.message, width=WIDTH + 20, name="controls"),
                      column(self.source, self.status, sizing_mode="stretch_width", name="head"), *self.slots,
                      column(self.warnings, sizing_mode="stretch_width", name="tail")]
        self._style()
        for root in [*self.roots, self.state]:
            doc.add_root(root)
        doc.template = TEMPLATE
        doc.template_variables["slots"] = SLOTS
        doc.title = "robotadapt explorer"
        doc.add_periodic_callback(self._progress, 250)
        doc.on_session_destroyed(self._close)
        self.submit(self.view)

    # ---------------------------------------------------------------------------------------------------------------
    # changes

    def submit(self, view: View) -> None:
        """Show `view`: its URL now, its run when it ends (unless a newer change came first)."""
        self.notice = "" if view != self.view else self.notice
        self.view = view
        self._url()
        self.runner.submit(partial(prepare, self.catalogue, view))

    def _url(self) -> None:
        """The page's URL: the view's (the run mark kept)."""
        self.state.data = {"url": [self.view.query()], "run": self.state.data["run"]}

    def _scenario(self, attr: str, old: Any, new: str) -> None:
        if new != self.view.scenario:
            self.submit(View(new, large=self.view.large, hidden=self.view.hidden))

    def _law(self, attr: str, old: Any, new: str) -> None:
        law = None if new == self.reference else new
        if law != self.view.law:
            settings, _ = self.view.split()
            self.submit(replace(self.view, law=law, sets=tuple(settings)))

    def _typed(self, key: str, attr: str, old: Any, new: str) -> None:
        entry = self.fields[key]
        given = None if not new.strip() or parse_value(new.strip()) == entry.control.default else new
        position = entry.position(new)
        if entry.slider is not None and position is not None and abs(position - entry.slider.value) > entry.slider.step:
            entry.slider.update(start=min(entry.slider.start, position), end=max(entry.slider.end, position),
                                value=position)
        view = self.view.with_set(key, given)
        if view != self.view:
            self.submit(view)

    def _slid(self, key: str, attr: str, old: Any, new: float) -> None:
        entry = self.fields[key]
        entry.text.value = entry.value(new)  # the field's callback runs it

    def _reset(self) -> None:
        settings, _ = self.view.split()
        self.submit(replace(self.view, sets=tuple(settings)))

    def _fonts(self, attr: str, old: Any, new: bool) -> None:
        self.view = replace(self.view, large=new)
        self._url()
        self._style()
        self._draw()

    def _shown(self, attr: str, old: Any, new: list[int]) -> None:
        self.view = replace(self.view, hidden=tuple(n for i, n in enumerate(FIGURES) if i not in new))
        self._url()
        self._place()

    def _fit(self) -> None:
        if self.figures is not None and self.current is not None and self.current.curves is not None:
            self.figures.fit(self.current.curves)

    def _pin(self) -> None:
        self.pinned = self.current
        self._draw()
        self._table()

    def _unpin(self) -> None:
        self.pinned = None
        self._draw()
        self._table()

    # ---------------------------------------------------------------------------------------------------------------
    # results

    def _done(self, outcome: Outcome) -> None:
        """On the worker thread: hand the outcome to the document's thread."""
        if not self.closed:
            self.doc.add_next_tick_callback(partial(self._show, outcome))

    def _close(self, context: Any) -> None:
        self.closed = True

    def _show(self, outcome: Outcome) -> None:
        """The outcome on the page, its changes sent together: the figures' data (or the refusal) and the mark. The
        metrics and the headline follow once the browser painted the figures (:meth:`_painted`): they would otherwise
        be laid out before the figures are painted."""
        self.seconds = outcome.seconds
        if outcome.ticket != self.runner.latest:  # a change came after it ended: its own run is on the way
            return
        self.doc.hold("combine")
        try:
            shown = self._outcome(outcome)
            if shown is not None:
                self.unsent = (shown, outcome)
            self.state.data = {"url": self.state.data["url"], "run": [outcome.ticket]}
        finally:
            self.doc.unhold()

    def _painted(self, attr: str, old: Any, new: dict[str, list[int]]) -> None:
        """The browser painted a run's figures: its texts, if it is the run drawn last."""
        if self.unsent is not None and new["run"] == [self.unsent[1].ticket]:
            (shown, outcome), self.unsent = self.unsent, None
            self._texts(shown, outcome)

    def _outcome(self, outcome: Outcome) -> Shown | None:
        """The run's figures, or its refusal (None: the figures keep the run drawn last, whose texts are put up first
        if the browser has not yet said it painted it)."""
        shown: Shown | None = outcome.value
        if shown is None or shown.error is not None or shown.run is None:
            if self.unsent is not None:
                self._texts(*self.unsent)
                self.unsent = None
            if shown is not None:
                self._controls(shown)
            self._error(shown.error if shown is not None else outcome.error, outcome.ticket)
            return None
        self._controls(shown)
        self.current = shown
        if self.figures is not None and shown.curves is not None and self.figures.fits(shown.curves):
            self.figures.update(shown.curves)
        else:
            self._draw()
        return shown

    def _texts(self, shown: Shown, outcome: Outcome) -> None:
        """The metrics table, the headline and the health warnings of a run drawn; the error lines cleared."""
        assert shown.run is not None
        for entry in self.fields.values():
            entry.error.text = ""
        self.message.text = self.notice
        self._table()
        res = shown.run.result
        self.warnings.text = "".join(f"<p>⚠ {html.escape(w)}</p>" for w in shown.run.warnings)
        self.status.text = (" · ".join(f"<b>{k}</b> {html.escape(shown.rows[k])}" for k in HEADLINE if k in shown.rows)
                            + f"<br><small>run {outcome.ticket}: {1e3 * res.wall_time:.0f} ms to simulate {res.t.size} "
                            f"samples, {1e3 * outcome.seconds:.0f} ms in all</small>")

    def _error(self, exc: BaseException | None, ticket: int) -> None:
        """A ConfigError's line beside its field (else under the buttons); any other error as an internal one."""
        for entry in self.fields.values():
            entry.error.text = ""
        self.message.text = self.notice
        if isinstance(exc, ConfigError):
            target = self.fields[exc.field].error if exc.field in self.fields else self.message
            target.text = html.escape(str(exc))
            self.status.text = f"run {ticket}: not run (the value in red)"
        else:
            log.error("explorer: run %d failed", ticket, exc_info=exc)
            self.message.text = html.escape(f"internal error: {type(exc).__name__}: {exc}")
            self.status.text = f"run {ticket}: failed"

    def _controls(self, shown: Shown) -> None:
        """The law's choices and fields for `shown` (rebuilt when the law or scenario changed, else brought up to date)."""
        laws = list[str | tuple[Any, str]](shown.laws.items())
        if self.law.options != laws:
            self.law.options = laws
        self.reference = next(iter(shown.laws))
        law = shown.view.law or self.reference
        if self.law.value != law:
            self.law.value = law
        if self.scenario.value != shown.view.scenario:
            self.scenario.value = shown.view.scenario
        self.skipped.text = "".join(f"<br>not applicable: {html.escape(k)} — {html.escape(v)}"
                                    for k, v in shown.skipped.items()).removeprefix("<br>")
        self.source.text = html.escape(shown.source)
        def layout(controls: list[Control]) -> list[Any]:
            return [(c.key, repr(c.default), c.span) for c in controls]

        if layout([f.control for f in self.fields.values()]) != layout(shown.controls):
            self.fields = {c.key: self._field(c) for c in shown.controls}
            gains = [f for f in self.fields.values() if f.control.key.startswith("controller.")]
            self.gains.children = [Div(text="<b>gains</b>")] + [w for f in gains for w in self._widgets(f)]
            self.settings.children = [Div(text="<b>settings</b>")] + [
                w for f in self.fields.values() if f not in gains for w in self._widgets(f)]
        for c in shown.controls:
            entry = self.fields[c.key]
            entry.control = c
            if entry.text.value != c.text:
                entry.text.value = c.text
        others = [s for s in shown.view.sets if key_of(s) not in self.fields]
        self.others.text = "also set by the URL: " + ", ".join(html.escape(s) for s in others) if others else ""

    def _field(self, c: Control) -> Field:
        title = f"{c.label} ({c.unit})"
        text = TextInput(title="" if c.span else title, value=c.text, width=WIDTH, css_classes=[css_class(c.key)],
                         name=f"field-{c.key}")
        text.on_change("value", partial(self._typed, c.key))
        entry = Field(c, text, Div(width=WIDTH, styles=ERROR_STYLE, name=f"error-{c.key}"), None)
        if c.span is not None:
            low, high = (math.log10(v) for v in c.span)
            at = entry.position(c.text)
            at = (low + high) / 2 if at is None else at
            entry.slider = Slider(start=min(low, at), end=max(high, at), value=at, step=(high - low) / 400,
                                  title=title if c.scalar else f"{title}: × the lineup's",
                                  format=CustomJSTickFormatter(code=SLIDER_FORMAT), width=WIDTH, show_value=False,
                                  css_classes=[css_class(c.key) + "-slider"], name=f"slider-{c.key}")
            entry.slider.on_change("value_throttled", partial(self._slid, c.key))
        return entry

    @staticmethod
    def _widgets(entry: Field) -> list[Any]:
        return [w for w in (entry.slider, entry.text, entry.error) if w is not None]

    def _draw(self) -> None:
        """The figures of the current run (and the pinned one), built anew."""
        if self.current is None or self.current.curves is None:
            return
        self.figures = Figures(self.current.curves, self.pinned.curves if self.pinned is not None else None,
                               self.view.large, height=330 if self.view.large else 260)
        self.metrics.height = self.figures.figures[0].height
        self._place()

    def _place(self) -> None:
        """The figures shown in the first slots, then the metrics table; the other slots empty."""
        if self.figures is None:
            return
        items = [f for f, panel in zip(self.figures.figures, self.figures.panels, strict=True)
                 if panel.name not in self.view.hidden] + [self.metrics]
        for i, slot in enumerate(self.slots):
            slot.children = [items[i]] if i < len(items) else []

    def _table(self) -> None:
        rows = self.current.rows if self.current is not None else {}
        pinned = self.pinned.rows if self.pinned is not None else {}
        names = [k for k in FIRST if k in rows] + [k for k in rows if k not in FIRST]
        self.table.data = {"metric": names, "value": [rows[k] for k in names],
                           "pinned": [pinned.get(k, "") for k in names]}

    def _style(self) -> None:
        """The widgets' font size: a lecture hall's or the screen's."""
        for root in self.roots:
            root.styles = {"--bokeh-font-size": "18px" if self.view.large else "13px"}

    def _progress(self) -> None:
        """While a run is going: for how long, against the last run's time."""
        started = self.runner.started
        if started is None or time.perf_counter() - started < 0.3:
            return
        elapsed = time.perf_counter() - started
        share = min(0.99, elapsed / self.seconds) if self.seconds else 0.5
        self.status.text = (f"running… {elapsed:.1f} s" + (f" (the last run took {self.seconds:.1f} s)" if self.seconds
                                                             else "")
                            + f"<div style='background:#ddd;width:{WIDTH - 20}px;height:6px'><div style='background:"
                            f"#1f77b4;width:{100 * share:.0f}%;height:6px'></div></div>")


def document(catalogue: Catalogue, executor: Executor) -> Callable[[Document], None]:
    """The Bokeh application's function: a page for each new session, its view from the request's URL."""

    def make(doc: Document) -> None:
        request = getattr(doc.session_context, "request", None)
        arguments = request.arguments if request is not None else {}
        Page(doc, catalogue, executor, View.of_query(arguments, catalogue.default))

    return make
