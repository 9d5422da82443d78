"""The figure of a tuning (`robotadapt tune`, docs/tuning.md), a 2 × 2 grid: the objective and the peak torque against
the iteration, the tracking error ‖e(t)‖ and the peak joint torque max_i |τ_i(t)| before and after, and, when a surface
was computed, the objective over a grid of two gains with the optimiser's path on it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib.colors
import matplotlib.ticker
import numpy as np

from ..studies.tune import Surface, Tuned
from .figures import EFFORT, POSITION, joint_types, norm_unit
from .output import DEFAULT_DPI, PNG, FigureFormat, new_figure, save_figure
from .sweep_figures import GAIN_SYMBOLS

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def gain_label(field: str) -> str:
    """`controller.Kv` → $K_v$ (the book's letter), else the field itself."""
    last = field.rsplit(".", 1)[-1]
    return f"${GAIN_SYMBOLS[last]}$" if last in GAIN_SYMBOLS else field


def plural(count: int, noun: str) -> str:
    """`count` and `noun`, in the plural unless one: "1 iteration", "3 iterations"."""
    return f"{count} {noun}" + ("" if count == 1 else "s")


def tuning_figure(tuned: Tuned) -> Figure:
    """Objective and peak torque per iteration (across the top, or beside the objective surface over two gains with
    the path when the tuning computed one); ‖e(t)‖ and max_i |τ_i(t)| before and after (the nominal plant) below: a
    2 × 2 grid, with units from the controller's model (rad or m, N·m or N by joint type)."""
    surface = tuned.surface
    joints = joint_types(tuned.scenario.setup.controller.model)
    position, effort = norm_unit(POSITION, joints), norm_unit(EFFORT, joints)
    fig = new_figure(figsize=(11, 8), dpi=DEFAULT_DPI, layout="constrained")
    axes = fig.subplot_mosaic([["iterations", "surface" if surface is not None else "iterations"], ["e", "tau"]])
    its = tuned.search.iterations
    ax = axes["iterations"]
    ax.semilogy([it.objective for it in its], "o-", color="C0", label=tuned.objective.text)
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True, min_n_ticks=1))
    ax.set_xlim(-0.5, max(len(its) - 0.5, 0.5))  # one iteration: a unit-wide axis, not ±0.05 around it
    ax.set_xlabel("iteration")
    ax.set_ylabel(f"objective: {tuned.objective.text}", color="C0")
    ax.set_title(f"{plural(len(its), 'iteration')}, {plural(tuned.search.runs, 'differentiated run')}, "
                 f"{tuned.wall_time:.3g} s")
    if tuned.max_torque is not None:
        twin = ax.twinx()
        twin.plot([it.max_abs_torque for it in its], "s--", color="C3", ms=3)
        twin.axhline(tuned.max_torque, color="C3", lw=0.8, ls=":")
        twin.set_ylabel(f"peak |τ| ({effort}), budget dotted", color="C3")
    for label, score, style in (("before", tuned.before, "--"), ("after", tuned.after, "-")):
        res = score.result
        axes["e"].semilogy(res.t, np.linalg.norm(res.e, axis=-1), style, label=f"{label}: {score.objective:.4g}")
        axes["tau"].plot(res.t, np.max(np.abs(res.tau), axis=-1), style,
                         label=f"{label}: peak {score.max_abs_torque:.4g} {effort}")
    top = max(float(np.max(np.linalg.norm(s.result.e, axis=-1))) for s in (tuned.before, tuned.after))
    axes["e"].set(xlabel="time t (s)", ylabel=f"‖e(t)‖ ({position})", title="tracking error (nominal plant)",
                  ylim=(1e-8 * top, 2 * top))
    axes["tau"].set(xlabel="time t (s)", ylabel=f"max_i |τ_i(t)| ({effort})", title="peak joint torque")
    if tuned.max_torque is not None:
        axes["tau"].axhline(tuned.max_torque, color="k", lw=0.8, ls=":", label=f"budget {tuned.max_torque:g} {effort}")
    axes["e"].legend(fontsize=8)
    axes["tau"].legend(fontsize=8)
    if surface is not None:
        _surface(axes["surface"], tuned, surface)
    fig.suptitle(f"robotadapt tune {tuned.scenario.name}: {tuned.objective.text}"
                 + ("" if tuned.max_torque is None else f", max |τ| ≤ {tuned.max_torque:g} {effort}")
                 + ("" if tuned.feasible else " (budget NOT met)"))
    return fig


def tune_figure(tuned: Tuned, path: Path, output: FigureFormat = PNG) -> Path:
    """Write :func:`tuning_figure` to `path` in `output`'s format."""
    return save_figure(tuning_figure(tuned), path, output)


def _surface(ax: Any, tuned: Tuned, surface: Surface) -> None:
    """The objective over the grid (log colours), the budget's contour with the region over it hatched, and the
    optimiser's path (white dots, the answer a star)."""
    X, Y = np.meshgrid(surface.x, surface.y, indexing="ij")
    Z = np.where(np.isfinite(surface.objective), surface.objective, np.nan)
    low, high = float(np.nanmin(Z)), float(np.nanmax(Z))
    log = high > low > 0
    cs = ax.contourf(X, Y, Z, levels=np.geomspace(low, high, 20) if log else 20,
                     norm=matplotlib.colors.LogNorm(low, high) if log else None, cmap="viridis")
    bar = ax.figure.colorbar(cs, ax=ax, label=tuned.objective.text, format="%.3g")
    bar.ax.minorticks_off()
    if tuned.max_torque is not None:
        ax.contour(X, Y, surface.max_abs_torque, levels=[tuned.max_torque], colors="r", linewidths=1.2)
        ax.contourf(X, Y, surface.max_abs_torque, levels=[tuned.max_torque, np.inf], colors="none", hatches=["//"])
    path = np.exp(np.array([[it.theta[surface.i], it.theta[surface.j]] for it in tuned.search.iterations]))
    if path.size:
        ax.plot(path[:, 0], path[:, 1], "w.-", lw=1, ms=7, zorder=3, clip_on=False)
        ax.plot(*np.exp([tuned.theta[surface.i], tuned.theta[surface.j]]), "*", color="w", mec="k", ms=14, zorder=4,
                clip_on=False)
    ax.set(xscale="log", yscale="log", xlabel=gain_label(surface.x_field), ylabel=gain_label(surface.y_field),
           title="objective surface (other gains as tuned)\nred: budget; hatched: over it")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
