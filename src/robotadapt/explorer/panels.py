"""The page's figures, drawn by Bokeh from :mod:`.curves`' panels: one figure per panel, time axes linked (zoom one,
all follow), a hover readout, legends that hide a curve on a click, and a pinned run drawn faintly beneath.

The y axes are held: fitted to the curves when the figures are made (a view's first run, a new law, a pin) and kept as
the gains move, so that a smaller error looks smaller; :meth:`Figures.fit` fits them again (the page's "fit axes").
Held axes also redraw sooner: a range that a new run changes makes Bokeh measure and lay out every axis again."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from bokeh.models import ColumnDataSource, HoverTool, Range1d
from bokeh.models.annotations import Span, Title
from bokeh.palettes import Category10_10
from bokeh.plotting import figure

from .curves import Curves, Panel

#: the share of the curves' span left free above and below (of their decades on a log axis), as Bokeh's own ranges
PADDING = 0.05

#: (title, axis labels, tick labels, legend) font sizes: a lecture hall's, and the screen's
FONTS = {True: ("22px", "20px", "17px", "17px"), False: ("14px", "13px", "11px", "11px")}
TOOLS = "pan,wheel_zoom,box_zoom,reset,save"


def end(curves: Curves) -> float:
    """The last instant of the curves (1 s for none)."""
    t = curves.data.get("t")
    return float(t[-1]) if t is not None and len(t) else 1.0


def y_bounds(values: Iterable[np.ndarray], log: bool) -> tuple[float, float]:
    """A y range showing the finite values (positive ones on a `log` axis) of `values`, `PADDING` to spare."""
    kept = [v[np.isfinite(v) & (v > 0 if log else True)] for v in map(np.asarray, values)]
    kept = [v for v in kept if v.size]
    if not kept:
        return (0.1, 10.0) if log else (-1.0, 1.0)
    low, high = min(float(v.min()) for v in kept), max(float(v.max()) for v in kept)
    if log:
        low, high = np.log10(low), np.log10(high)
    span = high - low if high > low else 1.0 if log else max(abs(high), 1.0)
    low, high = low - PADDING * span, high + PADDING * span
    return (10.0 ** low, 10.0 ** high) if log else (low, high)


def _columns(panel: Panel | None, curves: Curves | None) -> list[np.ndarray]:
    """The data of `panel`'s curves in `curves` (none without either)."""
    if panel is None or curves is None:
        return []
    return [curves.data[s.column] for s in panel.series]


def color(i: int) -> str:
    return Category10_10[i % len(Category10_10)]


class Figures:
    """A figure per panel of `curves`, those of `pinned` (a pinned run's) drawn faintly beneath the panels of the same
    name and axis; `large`: a lecture hall's fonts. :meth:`update` takes new data for the same panels."""

    def __init__(self, curves: Curves, pinned: Curves | None, large: bool, height: int = 260) -> None:
        self.panels = curves.panels
        self.source = ColumnDataSource(curves.data, name="curves")
        self.figures: list[Any] = []
        before = {p.name: p for p in pinned.panels} if pinned is not None else {}
        faint = ColumnDataSource(pinned.data if pinned is not None else {})
        self.pinned = pinned
        #: the pinned run's panel drawn beneath each panel (None: none)
        self.beneath = [old if old is not None and old.log == p.log else None
                        for p, old in ((p, before.get(p.name)) for p in curves.panels)]
        self.y_ranges = [Range1d() for _ in curves.panels]
        # one time axis, set (not computed from the data): zoom one figure, all follow
        self.x_range = Range1d(start=0.0, end=end(curves), reset_start=0.0, reset_end=end(curves))
        title, axis, ticks, legend = FONTS[large]
        for panel, old, y_range in zip(curves.panels, self.beneath, self.y_ranges, strict=True):
            fig = figure(title=Title(text=panel.title, text_font_size=title), x_axis_label="time t (s)",
                         y_axis_type="log" if panel.log else "linear",
                         y_axis_label=panel.ylabel, tools=TOOLS, active_scroll="wheel_zoom", height=height,
                         sizing_mode="stretch_width", name=f"figure-{panel.name}", x_range=self.x_range,
                         y_range=y_range)
            if old is not None:
                for s in old.series:
                    fig.line("t", s.column, source=faint, color=color(s.color), alpha=0.3, line_width=3,
                             line_dash="dashed" if s.truth else "solid", legend_label="pinned run")
            lines: list[Any] = [fig.line("t", s.column, source=self.source, color=color(s.color), line_width=2,
                                         name=s.label, line_dash="dashed" if s.truth else "solid", legend_label=s.label)
                                for s in panel.series]
            for value, i in panel.limits:
                fig.add_layout(Span(location=value, dimension="width", line_color=color(i), line_dash="dotted",
                                    line_width=2))
            fig.add_tools(HoverTool(renderers=lines, tooltips=[("", "$name"), ("t", "@t{0.000} s"), ("value", "$y")]))
            for ax in (*fig.xaxis, *fig.yaxis):
                ax.axis_label_text_font_size, ax.major_label_text_font_size = axis, ticks
            if fig.legend:
                fig.legend.update(click_policy="hide", location="top_right", background_fill_alpha=0.6,
                                  label_text_font_size=legend, visible=panel.legend)
            self.figures.append(fig)

        self.fit(curves)

    def fit(self, curves: Curves) -> None:
        """Each y axis (and its reset) fitted to `curves` and the pinned run's curves beneath."""
        for panel, old, y_range in zip(curves.panels, self.beneath, self.y_ranges, strict=True):
            low, high = y_bounds(_columns(panel, curves) + _columns(old, self.pinned), panel.log)
            y_range.update(start=low, end=high, reset_start=low, reset_end=high)

    def fits(self, curves: Curves) -> bool:
        """Whether these figures draw `curves` (the same panels)."""
        return self.panels == curves.panels

    def update(self, curves: Curves) -> None:
        """New data for curves that fit, the y axes held (the time axis reset when the run's length changed)."""
        if self.x_range.reset_end != end(curves):
            self.x_range.update(start=0.0, end=end(curves), reset_start=0.0, reset_end=end(curves))
        self.source.data = curves.data
