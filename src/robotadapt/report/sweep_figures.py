"""The summary figure of a sweep: one metric against every swept key, one panel per key (imported only to draw it).

Every run is a dot coloured by its grid point (the `--grid` values), in every panel, so that a random key's panel shows
which grid value each run had. A parameter vector's entries get a panel each, labelled by the model's parameter name
($m_2$ (kg), not `plant.phi[2]`); a log-spaced grid (Γ = 1, 10, 100) gets a log axis; the median over the runs of one
value is drawn only through values with at least `MEDIAN_MIN_RUNS` runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import matplotlib
import numpy as np

from ..studies.compare import number_text
from ..studies.sweep import scalar
from .figures import parameter_unit, tex_name
from .output import PNG, FigureFormat, new_figure, save_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: least runs at one value of a key for its median to mean something
MEDIAN_MIN_RUNS = 3
#: at most this many distinct values make a key a grid axis (when the caller does not say which keys are)
MAX_GRID_VALUES = 10
#: the book's letters of the controllers' gains, for axis labels
GAIN_SYMBOLS = {"Gamma": r"\Gamma", "Lam": r"\Lambda", "Kv": "K_v", "Kp": "K_p", "Ka": "K_a", "kd": "k_d", "ka": "k_a",
                "kL": "k_L", "K_I": "K_I", "F_p": "F_p", "P0": "P_0", "phi0": r"\varphi_0", "a": "a"}
#: vector keys whose entries are the model's parameters: key → (which names, what the values are)
PARAMETER_KEYS = {"plant.phi": "true", "controller.phi_hat0": "initial estimate"}


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


class Panel(NamedTuple):
    """One panel: the x label, the x values (one per row), tick labels for categories (else None)."""

    label: str
    x: np.ndarray
    ticks: list[str] | None


def parameter_names(rows: list[dict[str, Any]], key: str) -> list[str] | None:
    """The model's parameter names of a parameter-vector key, from the rows' metrics: the controller's `param_names`
    (for `plant.phi` the plant's own model's when it differs); None when not known."""
    for row in rows:
        if key == "plant.phi" and isinstance(row.get("plant"), dict) and "model" in row["plant"]:
            return list(row["plant"]["model"].get("param_names", [])) or None
        if isinstance(row.get("param_names"), list):
            return list(row["param_names"])
    return None


def _key_label(key: str) -> str:
    """`controller.Gamma` → `controller.Gamma ($\\Gamma$)`; other keys as they are."""
    symbol = GAIN_SYMBOLS.get(key.rsplit(".", 1)[-1])
    return f"{key} (${symbol}$)" if symbol and key.startswith("controller.") else key


def panels(rows: list[dict[str, Any]], keys: list[str]) -> list[Panel]:
    """One panel per key: numbers as they are; lists of numbers one panel per entry, labelled by the parameter's name
    when the key is a parameter vector (`plant.phi`: $m_2$ (kg)), else `key[j]` (1-based); anything else (strings,
    tables) as categories in first-seen order."""
    out: list[Panel] = []
    for key in keys:
        values: list[Any] = [row.get(key) for row in rows]
        if all(map(_number, values)):
            out.append(Panel(_key_label(key), np.asarray(values, dtype=float), None))
        elif all(isinstance(v, list) and all(map(_number, v)) and len(v) == len(values[0]) for v in values):
            names = parameter_names(rows, key) if key in PARAMETER_KEYS else None
            for j in range(len(values[0])):
                if names is not None and len(names) == len(values[0]):
                    unit = parameter_unit(names[j])
                    name = tex_name(names[j], hat=key == "controller.phi_hat0")
                    label = f"{PARAMETER_KEYS[key]} {name}" + (f" ({unit})" if unit else "") + f"  [{key}]"
                else:
                    label = f"{key}[{j + 1}]"
                out.append(Panel(label, np.array([v[j] for v in values], dtype=float), None))
        else:
            labels = list(dict.fromkeys(str(v) for v in values))
            out.append(Panel(key, np.array([labels.index(str(v)) for v in values], dtype=float), labels))
    return out


def log_spaced(x: np.ndarray) -> bool:
    """Whether a grid's values are log-spaced: positive, at least three distinct values in a geometric progression
    (ratios within 10 %) that is not also arithmetic, or two values a factor 100 or more apart."""
    v = np.unique(x[np.isfinite(x)])
    if v.size < 2 or v.size > 4 * MAX_GRID_VALUES or v[0] <= 0:
        return False
    if v.size == 2:
        return bool(v[1] / v[0] >= 100)
    steps, ratios = np.diff(v), np.diff(np.log(v))
    geometric = np.ptp(ratios) <= 0.1 * np.mean(ratios)
    arithmetic = np.ptp(steps) <= 0.1 * np.mean(steps)
    return bool(geometric and not arithmetic)


def grid_keys(rows: list[dict[str, Any]], keys: list[str]) -> list[str]:
    """The keys that look like grid axes: few distinct values, each shared by several runs."""
    out = []
    for key in keys:
        distinct = {str(row.get(key)) for row in rows}
        if 1 < len(distinct) <= MAX_GRID_VALUES and len(distinct) < len(rows):
            out.append(key)
    return out


def _classes(rows: list[dict[str, Any]], grid: list[str]) -> tuple[np.ndarray, list[str]]:
    """Each row's colour class (its grid point; by the first grid key when there are too many points) and the
    legend text of each class."""
    used = grid if len({tuple(str(r.get(k)) for k in grid) for r in rows}) <= MAX_GRID_VALUES else grid[:1]
    points = [tuple(str(row.get(k)) for k in used) for row in rows]
    order = list(dict.fromkeys(points))
    texts = [", ".join(f"{k.rsplit('.', 1)[-1]} = {number_text(rows[points.index(p)].get(k))}" for k in used)
             for p in order]
    return np.array([order.index(p) for p in points]), texts


def _median(ax: Any, x: np.ndarray, y: np.ndarray) -> None:
    """The median of y at each x value that has at least `MEDIAN_MIN_RUNS` runs (not through single samples)."""
    distinct, counts = np.unique(x, return_counts=True)
    if distinct.size > 2 * MAX_GRID_VALUES:
        return
    at = distinct[counts >= MEDIAN_MIN_RUNS]
    if at.size:
        ax.plot(at, [np.median(y[x == v]) for v in at], linestyle="-" if at.size > 1 else "none", marker="D",
                color="k", markersize=5, linewidth=1.2, label=f"median (values with ≥ {MEDIAN_MIN_RUNS} runs)")


def summary_plot(rows: list[dict[str, Any]], keys: list[str], metric: str, title: str = "",
                 grid: Sequence[str] | None = None) -> Figure:
    """The figure of :func:`summary_figure`, returned open; `grid` the grid keys (default: the keys with at most
    `MAX_GRID_VALUES` distinct values shared by several runs), whose values colour the dots."""
    shown = panels(rows, keys)
    fig = new_figure(figsize=(4.6 * len(shown), 4.0))
    axes = fig.subplots(1, len(shown), squeeze=False)
    y = np.array([scalar(row.get(metric)) for row in rows])
    finished = np.array([row.get("status") == "ok" for row in rows])
    ok, undefined = finished & np.isfinite(y), finished & ~np.isfinite(y)
    top = np.nanmax(y[ok]) if ok.any() else 1.0
    grid = grid_keys(rows, keys) if grid is None else list(grid)
    classes, texts = _classes(rows, grid) if grid else (np.zeros(len(rows), dtype=int), ["ok"])
    alpha = min(1.0, max(0.25, 30 / max(ok.sum(), 1)))
    per_joint = bool(rows) and isinstance(rows[0].get(metric), list)
    for ax, panel in zip(axes[0], shown, strict=True):
        x = panel.x
        for c, text in enumerate(texts):
            sel = ok & (classes == c)
            if sel.any():
                ax.plot(x[sel], y[sel], "o", markersize=4, alpha=alpha, color=matplotlib.colormaps["tab10"](c % 10),
                        label=text)
        if undefined.any():
            ax.plot(x[undefined], np.full(undefined.sum(), top), "^", color="0.5",
                    label=f"{metric} undefined ({undefined.sum()})")
        if (~finished).any():
            ax.plot(x[~finished], np.full((~finished).sum(), top), "x", color="C3",
                    label=f"not finished ({(~finished).sum()})")
        _median(ax, x[ok], y[ok])
        if panel.ticks is not None:
            ax.set_xticks(range(len(panel.ticks)), panel.ticks, rotation=20, fontsize="small")
        elif log_spaced(x):
            ax.set_xscale("log")
        if ok.any() and np.all(y[ok] > 0) and top / np.min(y[ok]) > 100:
            ax.set_yscale("log")
        ax.set_xlabel(panel.label)
        ax.set_ylabel(f"{metric} (max over joints)" if per_joint else metric)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="x-small")
    fig.suptitle(f"{title}: {len(rows)} runs".strip(": ") + (f", coloured by {', '.join(grid)}" if grid else ""))
    fig.tight_layout()
    return fig


def summary_figure(rows: list[dict[str, Any]], keys: list[str], metric: str, path: Path, title: str = "",
                   grid: Sequence[str] | None = None, output: FigureFormat = PNG) -> Path:
    """`metric` of every run against each swept key: finished runs as dots coloured by grid point (log scale when
    positive and spread over more than two decades), along the top grey triangles for finished runs where the metric
    is undefined (None: e.g. no convergence time) and red crosses for runs that did not finish; where a value of a key
    has at least `MEDIAN_MIN_RUNS` runs, the median over them; written to `path` in `output`'s format."""
    return save_figure(summary_plot(rows, keys, metric, title, grid), path, output)
