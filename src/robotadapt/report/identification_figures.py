"""The figures of identification (docs/identification.md): `robotadapt excite`'s trajectory against its limits and its
regressor's singular values, and `robotadapt identify`'s held-out torque and validation log's torque against each
estimate's prediction."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ..analysis.identification import Identification, Prediction
from ..robots.base import RobotModel
from ..robots.identifiability import base_parameters
from ..studies.excite import Excitation, stacked_regressor
from ..trajectories import Trajectory
from .output import PNG, FigureFormat, new_figure, save_figure

STYLES = {"consistent": "-", "wls": "--", "ols": ":", "prior": "-.", "nominal": (0, (1, 3))}


def prediction_plot(prediction: Prediction, title: str = "") -> Figure:
    """One panel per joint: the measured torque of one log (after its own filtering) and its prediction by each
    estimate and the prior, with RMS errors in the legend."""
    n = prediction.tau.shape[1]
    cols = 2 if n > 3 else 1
    rows = -(-n // cols)
    fig = new_figure(figsize=(7 * cols, 1.9 * rows + 0.8))
    axes = fig.subplots(rows, cols, sharex=True, squeeze=False)
    rms = prediction.rms
    for i, ax in enumerate(axes.flat):
        if i >= n:
            ax.set_visible(False)
            continue
        ax.plot(prediction.t, prediction.tau[:, i], color="k", linewidth=1.6, label="measured")
        for name, tau in prediction.predicted.items():
            ax.plot(prediction.t, tau[:, i], linestyle=STYLES.get(name, "-"), linewidth=1.0,
                    label=f"{name} (RMS {rms[name][i]:.3g})")
        ax.set_ylabel(f"$\\tau_{{{i + 1}}}$")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="x-small")
    for ax in axes[-1]:
        ax.set_xlabel("time $t$ (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def holdout_plot(result: Identification, title: str = "") -> Figure:
    """:func:`prediction_plot` of the held-out part of the log."""
    return prediction_plot(result.holdout, f"{title}: held-out torque (N·m or N) and its prediction".lstrip(": "))


def validation_plot(result: Identification, title: str = "") -> Figure:
    """:func:`prediction_plot` of the validation log (`--validate`)."""
    if result.validation is None:
        raise ValueError("the identification has no validation log")
    return prediction_plot(result.validation, f"{title}: torque of the validation log {result.validation.source} "
                           "(N·m or N) and its prediction".lstrip(": "))


def holdout_figure(result: Identification, path: Path, title: str = "", output: FigureFormat = PNG) -> Path:
    """:func:`holdout_plot` written to `path` in `output`'s format."""
    return save_figure(holdout_plot(result, title), path, output)


def validation_figure(result: Identification, path: Path, title: str = "", output: FigureFormat = PNG) -> Path:
    """:func:`validation_plot` written to `path` in `output`'s format."""
    return save_figure(validation_plot(result, title), path, output)


def excitation_plot(model: RobotModel, result: Excitation, old: Trajectory, compared: dict[str, Any],
                    title: str = "") -> Figure:
    """Over one period on the check's fine grid: each joint's position, velocity, acceleration and torque (at the
    nominal φ) as a share of its bound (±1 dashed; the bounds in their units in each panel's title; a kind without
    bounds is drawn in its own units: rad, rad/s, rad/s², N·m at revolute joints, m, m/s, m/s², N at prismatic ones),
    and the singular values of the stacked base regressor W of `model` on the optimised trajectory against the
    scenario's own (`old`, on the grid of `compared`, :func:`~robotadapt.studies.excite.before`'s record). The legends
    sit outside the axes, right of them."""
    from .figures import EFFORT, POSITION, joint_types, legend

    fine, limits = result.fine, result.limits
    types = set(joint_types(model) or "?")
    joints = types.pop() if len(types) == 1 else "?"  # "R", "P", or "?" for mixed or unknown joints
    tables = {"position": POSITION, "velocity": {"R": "rad/s", "P": "m/s", "?": "rad/s or m/s"},
              "acceleration": {"R": "rad/s²", "P": "m/s²", "?": "rad/s² or m/s²"}, "torque": EFFORT}
    units = {kind: table[joints] for kind, table in tables.items()}

    def spread(bound: Any, unit: str) -> str:
        lo, hi = float(np.min(bound)), float(np.max(bound))
        return f"{lo:.3g} {unit}" if np.isclose(lo, hi) else f"{lo:.3g}–{hi:.3g} {unit}"

    mid, half = 0.5 * (limits.upper + limits.lower), 0.5 * (limits.upper - limits.lower)
    rows = [("position", (fine.q - mid) / half, "$(q - q_{mid})$ / half range",
             f"position: share of the half range {spread(half, units['position'])} about the middle")]
    for kind, value, symbol in (("velocity", fine.dq, r"\dot q"), ("acceleration", fine.ddq, r"\ddot q"),
                                ("torque", fine.tau, r"\tau")):
        if value is None:
            continue
        bound = limits.bound(kind)
        if np.all(np.isfinite(bound)):
            rows.append((kind, value / bound, f"${symbol} / {symbol}_{{max}}$",
                         f"{kind}: share of the bound {spread(bound, units[kind])}"))
        else:
            rows.append((kind, value, f"${symbol}$ ({units[kind]})", f"{kind} (no bound)"))
    fig = new_figure(figsize=(9.5, 1.9 * len(rows) + 2.6))
    axes = fig.subplots(len(rows) + 1, 1)
    for ax, (kind, value, label, heading) in zip(axes, rows, strict=False):
        for i in range(value.shape[1]):
            ax.plot(fine.t, value[:, i], linewidth=1.0, label=f"joint {i + 1}")
        if kind == "position" or np.all(np.isfinite(limits.bound(kind))):
            for y in (-1.0, 1.0):
                ax.axhline(y, color="k", linestyle="--", linewidth=0.8)
            heading += f"; largest share {fine.ratio[kind]:.3g}"
        ax.set_ylabel(label)
        ax.set_title(heading, fontsize="small")
        ax.grid(True, alpha=0.3)
    legend(axes[0])
    axes[len(rows) - 1].set_xlabel("time $t$ (s), one period")
    independent = np.array(base_parameters(model).independent)
    new_ref = result.trajectory()(result.design.grid(result.samples))
    old_ref = old(compared["horizon"] * np.arange(compared["samples"]) / compared["samples"])
    ax = axes[-1]
    for name, ref, style in (("optimised", new_ref, "o-"), ("scenario's own", old_ref, "s--")):
        W = stacked_regressor(model, independent, ref.q_des, ref.dq_des, ref.ddq_des)
        sv = np.linalg.svd(W / np.sqrt(len(ref.q_des)), compute_uv=False)
        ax.semilogy(np.arange(1, sv.size + 1), sv, style, markersize=3, label=f"{name}:\ncond W = {sv[0] / sv[-1]:.4g}")
    ax.set_xlabel("index of the singular value")
    ax.set_ylabel(r"$\sigma_k(W)/\sqrt{N}$ (SI units)")
    ax.grid(True, which="both", alpha=0.3)
    legend(ax)
    fig.suptitle(f"{title}: exciting trajectory ({result.objective} objective)".lstrip(": "))
    fig.tight_layout()
    return fig


def excitation_figure(model: RobotModel, result: Excitation, old: Trajectory, compared: dict[str, Any], path: Path,
                      title: str = "", output: FigureFormat = PNG) -> Path:
    """:func:`excitation_plot` written to `path` in `output`'s format."""
    return save_figure(excitation_plot(model, result, old, compared, title), path, output)
