"""The summary figure of a sweep: one metric against every swept key, one panel per key (imported only to draw it)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..files import atomic_write  # noqa: E402
from ..studies.sweep import scalar  # noqa: E402


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _panels(rows: list[dict[str, Any]], keys: list[str]) -> list[tuple[str, np.ndarray, list[str] | None]]:
    """(label, x, tick labels) per panel: numbers as they are; lists of numbers one panel per entry (`plant.phi[2]`);
    anything else (strings, tables) as categories in first-seen order."""
    out: list[tuple[str, np.ndarray, list[str] | None]] = []
    for key in keys:
        values: list[Any] = [row.get(key) for row in rows]
        if all(map(_number, values)):
            out.append((key, np.asarray(values, dtype=float), None))
        elif all(isinstance(v, list) and all(map(_number, v)) and len(v) == len(values[0]) for v in values):
            out += [(f"{key}[{j + 1}]", np.array([v[j] for v in values], dtype=float), None)
                    for j in range(len(values[0]))]
        else:
            labels = list(dict.fromkeys(str(v) for v in values))
            out.append((key, np.array([labels.index(str(v)) for v in values], dtype=float), labels))
    return out


def summary_figure(rows: list[dict[str, Any]], keys: list[str], metric: str, path: Path, title: str = "") -> Path:
    """`metric` of every run against each swept key: finished runs as dots (log scale when positive), along the top
    grey triangles for finished runs where the metric is undefined (None: e.g. no convergence time) and red crosses for
    runs that did not finish; for a key with few values, the median over its runs as a line."""
    panels = _panels(rows, keys)
    fig, axes = plt.subplots(1, len(panels), figsize=(4.5 * len(panels), 3.8), squeeze=False)
    y = np.array([scalar(row.get(metric)) for row in rows])
    finished = np.array([row.get("status") == "ok" for row in rows])
    ok, undefined = finished & np.isfinite(y), finished & ~np.isfinite(y)
    top = np.nanmax(y[ok]) if ok.any() else 1.0
    for ax, (key, x, labels) in zip(axes[0], panels, strict=True):
        ax.plot(x[ok], y[ok], ".", alpha=min(1.0, max(0.15, 30 / max(ok.sum(), 1))), color="C0", label="ok")
        if undefined.any():
            ax.plot(x[undefined], np.full(undefined.sum(), top), "^", color="0.5",
                    label=f"{metric} undefined ({undefined.sum()})")
        if (~finished).any():
            ax.plot(x[~finished], np.full((~finished).sum(), top), "x", color="C3",
                    label=f"not finished ({(~finished).sum()})")
        distinct = np.unique(x[ok])
        if 1 < distinct.size <= 20:
            ax.plot(distinct, [np.median(y[ok][x[ok] == v]) for v in distinct], "-", color="C1", label="median")
        if labels is not None:
            ax.set_xticks(range(len(labels)), labels, rotation=20, fontsize="small")
        if ok.any() and np.all(y[ok] > 0) and top / np.min(y[ok]) > 100:
            ax.set_yscale("log")
        ax.set_xlabel(key)
        ax.set_ylabel(f"{metric} (max over joints)" if rows and isinstance(rows[0].get(metric), list) else metric)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    fig.suptitle(f"{title}: {len(rows)} runs".strip(": "))
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110), binary=True)
    plt.close(fig)
    return path
