"""Book-style figures of a run: tracking error, parameter estimates against the truth, torques (one file each), and
the overlays of a one-at-a-time study.

Axes carry units: rad or m per joint type (revolute or prismatic), N·m or N for the control input, and per parameter
the unit its name implies (kg for masses, kg·m for first moments, kg·m² for inertias, N·m·s/rad or N·s/m for viscous
friction, N·m or N for Coulomb friction). The joint types come from the model (:func:`joint_types`); without a model
the axes say "rad or m". Symbols are matplotlib mathtext ($e_1$, $\\hat\\varphi$). Each `*_figure` function returns the
matplotlib Figure (to inspect or save elsewhere: `fig.savefig`; in a notebook, display it), made without pyplot, so
that drawing leaves the user's backend and pyplot figures alone (:func:`~robotadapt.report.output.new_figure`); the
functions without the suffix write it (PNG unless their `output`, a :class:`~robotadapt.report.output.FigureFormat`,
says otherwise) and close it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import matplotlib.ticker
import numpy as np

from ..files import writable_dir
from ..studies.compare import number_text
from .forked import spread
from .output import DEFAULT_DPI, PNG, FigureFormat, new_figure, save_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..sim.result import SimulationResult

#: line styles that stay apart when curves coincide or the page is printed in grey
DASHES = ("-", "--", "-.", ":")
MARKERS = ("o", "s", "^", "v", "D", "x")
#: units by joint type: "R" revolute, "P" prismatic, "?" not known
POSITION = {"R": "rad", "P": "m", "?": "rad or m"}
EFFORT = {"R": "N·m", "P": "N", "?": "N·m or N"}
EFFORT_NAME = {"R": "torque", "P": "force", "?": "torque or force"}
JOINT_NAME = {"R": "revolute joints", "P": "prismatic joints", "?": "joints"}
#: above this many parameters one line each is unreadable: the figure shows the relative error instead
MAX_PARAMETER_LINES = 8


# ---------------------------------------------------------------------------------------------------------------------
# what a model says about units


def _pin_kind(shortname: str) -> str | None:
    """'R' or 'P' from a Pinocchio joint model's short name (JointModelRZ, JointModelPrismaticUnaligned, ...)."""
    kind = shortname.removeprefix("JointModel")[:1]
    return kind if kind in ("R", "P") else None


def joint_types(model: Any) -> str | None:
    """'R' (revolute) or 'P' (prismatic) per joint, e.g. ``"RP"`` for the polar arm; None when the model does not say.

    Read from `model.joint_types` when the model has it, else from what each kind of model holds: the `joints` string
    of the DH arms, the joint models of a Pinocchio arm, the standard model under base parameters, the textbook arms.
    """
    from ..robots.one_link import OneLinkArm
    from ..robots.polar import PolarArm
    from ..robots.two_link import TwoLinkArm

    for attr in ("joint_types", "joints"):
        value = getattr(model, attr, None)
        if isinstance(value, str) and value and set(value) <= {"R", "P"}:
            return value
    pin_model = getattr(model, "pin_model", None)
    if pin_model is not None:
        kinds = [_pin_kind(pin_model.joints[j].shortname()) for j in range(1, pin_model.njoints)]
        return "".join(k for k in kinds if k) if all(kinds) else None
    basis = getattr(model, "basis", None)
    if basis is not None and hasattr(basis, "model"):
        return joint_types(basis.model)
    textbook: tuple[tuple[type, str], ...] = ((OneLinkArm, "R"), (TwoLinkArm, "RR"), (PolarArm, "RP"))
    return next((joints for cls, joints in textbook if isinstance(model, cls)), None)


#: parameter name (without the joint number) → unit for a revolute joint, for a prismatic one
_UNITS = {"m": ("kg", "kg"), "mx": ("kg·m", "kg·m"), "my": ("kg·m", "kg·m"), "mz": ("kg·m", "kg·m"),
          **{f"I{a}": ("kg·m²", "kg·m²") for a in ("xx", "xy", "yy", "xz", "yz", "zz")},
          "Ia": ("kg·m²", "kg"), "fv": ("N·m·s/rad", "N·s/m"), "fc": ("N·m", "N"), "fs": ("N·m", "N"),
          "off": ("N·m", "N")}
#: the one-link arm's parameters (its `m` is the joint's inertia)
_ONE_LINK = {"m": "kg·m²", "b": "N·m·s/rad", "k": "N·m/rad"}


def parameter_unit(name: str, joints: str | None = None) -> str | None:
    """The SI unit a parameter's name implies (`m2` kg, `mx1` kg·m, `Izz3` kg·m², `Ia1`, `fv1`, `fc1` by the type of
    the joint its number names); None for names that imply none (base-parameter combinations)."""
    match = re.fullmatch(r"([A-Za-z]+?)(\d*)", name)
    if match is None or match.group(1) not in _UNITS:
        return None
    revolute, prismatic = _UNITS[match.group(1)]
    if revolute == prismatic:
        return revolute
    index = int(match.group(2) or 0) - 1
    kind = joints[index] if joints is not None and 0 <= index < len(joints) else "?"
    return {"R": revolute, "P": prismatic}.get(kind, f"{revolute} or {prismatic}")


def parameter_units(model: Any, names: Sequence[str]) -> list[str | None]:
    """The unit of each parameter: `model.param_units` when the model has it, else derived from the names."""
    from ..robots.one_link import OneLinkArm

    units = getattr(model, "param_units", None)
    if units is not None and len(units) == len(names):
        return list(units)
    if isinstance(model, OneLinkArm):
        return [_ONE_LINK.get(name) for name in names]
    joints = joint_types(model) if model is not None else None
    return [parameter_unit(name, joints) for name in names]


def tex_name(name: str, hat: bool = False) -> str:
    """A parameter name in mathtext: `m2` → $m_{2}$, `fv1` → $f_{v1}$, `Izz3` → $I_{zz3}$ (with `hat`, $\\hat{m}_{2}$);
    names that are not a symbol and subscript (base-parameter combinations) as they are."""
    match = re.fullmatch(r"([A-Za-z])([A-Za-z]*\d*)", name)
    if match is None:
        return ("estimate of " if hat else "") + name
    base = rf"\hat{{{match.group(1)}}}" if hat else match.group(1)
    return f"${base}_{{{match.group(2)}}}$" if match.group(2) else f"${base}$"


def joint_groups(n: int, joints: str | None) -> list[tuple[str, list[int]]]:
    """(joint type, joint indices) per panel: revolute joints, then prismatic ones; one group "?" when not known."""
    if joints is None or len(joints) != n:
        return [("?", list(range(n)))]
    return [(kind, [i for i in range(n) if joints[i] == kind]) for kind in "RP" if kind in joints]


def norm_unit(table: dict[str, str], joints: str | None) -> str:
    """The unit of a norm over all joints: one unit when every joint has the same type, else both."""
    kinds = set(joints) if joints else {"?"}
    return table[kinds.pop()] if len(kinds) == 1 else f"{table['R']} and {table['P']} mixed"


def style(i: int) -> dict[str, Any]:
    """The i-th line's colour (qualitative tab10), dash and hollow marker: (colour, dash) pairs are unique for i < 20,
    neighbours differ in all three, and the markers of curves that coincide sit at different places."""
    return {"color": matplotlib.colormaps["tab10"](i % 10), "linestyle": DASHES[i % len(DASHES)],
            "marker": MARKERS[i % len(MARKERS)], "markevery": (0.023 * (i % 5), 0.12), "markersize": 4.5,
            "markerfacecolor": "none"}


def positive(y: np.ndarray) -> np.ndarray:
    """`y` with values ≤ 0 left out (NaN): a log axis then starts at the first nonzero value (e(0) = 0 is no datum)."""
    y = np.asarray(y, dtype=float)
    return np.where(y > 0, y, np.nan)


# ---------------------------------------------------------------------------------------------------------------------
# the figures of one run


def panels(k: int, height: float = 2.6) -> tuple[Figure, list[Any]]:
    """k stacked panels sharing time, laid out at the dpi they are written at (matplotlib parses each mathtext label
    once per dpi: laid out at another, every label is parsed twice, a third of a fresh `robotadapt run`'s figure
    time)."""
    fig = new_figure(figsize=(7, 1.4 + height * k), dpi=DEFAULT_DPI)
    axes = fig.subplots(k, 1, sharex=True, squeeze=False)
    return fig, list(axes[:, 0])


def finish(fig: Figure, axes: list[Any], title: str) -> Figure:
    fig.suptitle(title)
    axes[-1].set_xlabel("time $t$ (s)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        legend(ax)
    fig.tight_layout()
    return fig


def legend(ax: Any) -> None:
    """The axes' legend, if it has labelled lines, outside the axes on the right: never over the data."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0)


def titled(title: str, what: str) -> str:
    return f"{title} — {what}" if title else what[:1].upper() + what[1:]


def _joint_panels(values: np.ndarray, t: np.ndarray, symbol: str, ylabel: Callable[[str], str], title: str,
                  model: Any) -> Figure:
    """One signal per joint, `values` `(T, n)` labelled `symbol`_i: a panel per joint type, `ylabel(kind)` on each."""
    groups = joint_groups(values.shape[-1], joint_types(model) if model is not None else None)
    fig, axes = panels(len(groups))
    for ax, (kind, joints) in zip(axes, groups, strict=True):
        for i in joints:
            ax.plot(t, values[:, i], label=f"${symbol}_{{{i + 1}}}$", **style(i))
        ax.set_ylabel(ylabel(kind))
        if len(groups) > 1:
            ax.set_title(JOINT_NAME[kind].removesuffix("s" if len(joints) == 1 else ""), fontsize="medium")
    return finish(fig, axes, title)


def tracking_error_figure(res: SimulationResult, title: str = "", model: Any = None) -> Figure:
    """e_i(t) = q_d,i − q_i for every joint, per joint type (rad for revolute, m for prismatic joints): e on a linear
    axis, then |e| on a log axis, where a convergence to round-off (1e-10 and below) shows instead of a flat zero. A
    task-space law's run: the hand's e = x_d − x, per coordinate x, y (, z), in metres."""
    task = res.space == "task"
    m = res.e.shape[-1]
    groups = [("P", list(range(m)))] if task else joint_groups(m, joint_types(model) if model is not None else None)
    fig, axes = panels(2 * len(groups), height=2.0)
    for k, (kind, joints) in enumerate(groups):
        linear, log = axes[2 * k], axes[2 * k + 1]
        for i in joints:
            linear.plot(res.t, res.e[:, i], label=f"$e_{'xyz'[i]}$" if task else f"$e_{{{i + 1}}}$", **style(i))
            magnitude = positive(np.abs(res.e[:, i]))
            if np.isfinite(magnitude).any():  # a joint whose error is exactly 0 throughout has no log line
                log.semilogy(res.t, magnitude, **style(i))
        log.set_yscale("log")
        linear.set_ylabel(f"tracking error $e_i$ ({POSITION[kind]})")
        log.set_ylabel(f"$|e_i|$ ({POSITION[kind]}), log scale")
        if len(groups) > 1:
            linear.set_title(JOINT_NAME[kind].removesuffix("s" if len(joints) == 1 else ""), fontsize="medium")
    return finish(fig, axes, titled(title, "hand error $e = x_d - x$" if task else "tracking error $e = q_d - q$"))


def torques_figure(res: SimulationResult, title: str = "", model: Any = None) -> Figure:
    """Controller output τ_i(t): torques (N·m) at revolute joints, forces (N) at prismatic ones, a panel each; the
    actuator's limit ±τ_max,i, where the plant has one, dotted in each joint's colour."""
    fig = _joint_panels(res.tau, res.t, "\\tau", lambda kind: f"{EFFORT_NAME[kind]} $\\tau_i$ ({EFFORT[kind]})",
                        titled(title, "control input $\\tau$"), model)
    limit = res.info.get("plant", {}).get("actuator", {}).get("torque_limit")
    if limit is not None:
        limits = np.broadcast_to(np.asarray(limit, dtype=float), (res.tau.shape[-1],))
        groups = joint_groups(res.tau.shape[-1], joint_types(model) if model is not None else None)
        for ax, (_, joints) in zip(fig.axes, groups, strict=True):
            for i in joints:
                for sign in (1.0, -1.0):
                    ax.axhline(sign * limits[i], linestyle=":", linewidth=1.0, color=style(i)["color"],
                               label="actuator limit $\\pm\\tau_{max}$" if (i, sign) == (joints[0], 1.0) else None)
            legend(ax)
        fig.tight_layout()
    return fig


def _many_parameters(res: SimulationResult, ax: Any) -> None:
    """‖φ̃(t)‖ / ‖φ(t)‖ when the truth is known, else ‖φ̂(t)‖: one line for an n-DOF arm's tens of parameters."""
    p = len(res.param_names)
    if res.phi_true is not None and res.phi_err is not None:
        rel = np.linalg.norm(res.phi_err, axis=-1) / np.maximum(np.linalg.norm(res.phi_true, axis=-1), 1e-300)
        ax.semilogy(res.t, positive(rel), label=f"{p} parameters")
        ax.set_ylabel(r"$\Vert\varphi - \hat{\varphi}\Vert \,/\, \Vert\varphi\Vert$ (dimensionless)")
    else:
        ax.plot(res.t, np.linalg.norm(res.phi_hat, axis=-1), label=f"{p} parameters")
        ax.set_ylabel(r"$\Vert\hat{\varphi}\Vert$ (mixed units)")


def _base_parameters_figure(res: SimulationResult, title: str, basis: Any) -> Figure:
    """What the dynamics see of the estimate: K φ̂(t) against K φ for up to `MAX_PARAMETER_LINES` base parameters, else
    ‖K(φ − φ̂(t))‖ / ‖K φ‖ (‖K φ̂(t)‖ when the truth is unknown); the title counts the unidentifiable directions."""
    b, p = basis.count, basis.K.shape[1]
    fig, axes = panels(1)
    ax, truth, est = axes[0], res.phi_true, basis.base(res.phi_hat)
    if b <= MAX_PARAMETER_LINES:
        for i, name in enumerate(basis.names):
            ax.plot(res.t, est[:, i], label=f"{name} (estimate)", color=style(i)["color"])
            if truth is not None:
                ax.plot(res.t, basis.base(truth)[:, i], color=style(i)["color"], linestyle="--", marker="o",
                        markevery=0.1, markersize=4, markerfacecolor="none", label=f"{name} true")
        ax.set_ylabel(r"$K\hat{\varphi}$" + (r", $K\varphi$" if truth is not None else "") + " (mixed units)")
        what = r"base parameters $K\hat{\varphi}$" + (r" (solid), $K\varphi$ (dashed)" if truth is not None else "")
    elif truth is not None:
        rel = np.linalg.norm(basis.base(truth - res.phi_hat), axis=-1) / np.maximum(
            np.linalg.norm(basis.base(truth), axis=-1), 1e-300)
        ax.semilogy(res.t, positive(rel), label=f"{b} base parameters")
        ax.set_ylabel(r"$\Vert K(\varphi - \hat{\varphi})\Vert \,/\, \Vert K\varphi\Vert$")
        what = "base-parameter error"
    else:
        ax.plot(res.t, np.linalg.norm(est, axis=-1), label=f"{b} base parameters")
        ax.set_ylabel(r"$\Vert K\hat{\varphi}\Vert$ (mixed units)")
        what = "base-parameter estimates"
    return finish(fig, axes, titled(title, f"{what}; {p - b} of {p} directions unidentifiable"))


def parameters_figure(res: SimulationResult, title: str = "", model: Any = None) -> Figure:
    """φ̂(t) solid, the true φ(t) dashed with markers in the same colour when known (both stay visible where they
    coincide); one panel per unit. For more than `MAX_PARAMETER_LINES` parameters (n-DOF arms) the relative error
    ‖φ̃(t)‖ / ‖φ(t)‖ when the truth is known, else ‖φ̂(t)‖. When `model` (the controller's) has unidentifiable directions
    (fewer base than standard parameters), the base parameters K φ̂ instead: the figure shows what the dynamics see."""
    from ..analysis.metrics import base_of

    names, truth = res.param_names, res.phi_true
    basis = base_of(model) if model is not None else None
    if basis is not None and basis.K.shape[1] == len(names):
        return _base_parameters_figure(res, title, basis)
    if not names or len(names) > MAX_PARAMETER_LINES:
        fig, axes = panels(1)
        if names:
            _many_parameters(res, axes[0])
        else:
            axes[0].text(0.5, 0.5, "this controller estimates no parameters", ha="center", va="center",
                         transform=axes[0].transAxes)
        return finish(fig, axes, titled(title, "parameter error" if truth is not None else "parameter estimates"))
    units = parameter_units(model, names)
    groups = list(dict.fromkeys(units))
    fig, axes = panels(len(groups), height=2.4)
    for ax, unit in zip(axes, groups, strict=True):
        for i, name in enumerate(names):
            if units[i] != unit:
                continue
            ax.plot(res.t, res.phi_hat[:, i], label=tex_name(name, hat=True), color=style(i)["color"])
            if truth is not None:
                ax.plot(res.t, truth[:, i], color=style(i)["color"], linestyle="--", marker="o", markevery=0.1,
                        markersize=4, markerfacecolor="none", label=f"{tex_name(name)} true")
        ax.set_ylabel(r"$\hat{\varphi}_i$" + (r", $\varphi_i$" if truth is not None else "")
                      + (f" ({unit})" if unit else ""))
    what = r"estimates $\hat{\varphi}$ (solid), true $\varphi$ (dashed)" if truth is not None else \
        r"estimates $\hat{\varphi}$"
    return finish(fig, axes, titled(title, f"parameter {what}"))


# the hand of a task-space law's run (docs/task-space.md)

VIEWS = {2: ((0, 1),), 3: ((0, 1), (0, 2), (1, 2))}  # the planes drawn: x–y; or the top, front and side views


def path_figure(res: SimulationResult, title: str = "") -> Figure:
    """The hand's path x(t) = x_d − e (solid) over the desired x_d(t) (dashed), in the x–y plane of a planar arm or in
    three views (x–y from above, x–z from the front, y–z from the side) in space, equal scales, metres; the start
    marked."""
    xd = res.q_des
    x = xd - res.e
    views = VIEWS[xd.shape[-1]]
    fig = new_figure(figsize=(4.2 * len(views), 4.6))
    axes = fig.subplots(1, len(views), squeeze=False)[0]
    for ax, (a, b) in zip(axes, views, strict=True):
        ax.plot(x[:, a], x[:, b], label="hand $x$", **{**style(0), "marker": None})
        ax.plot(xd[:, a], xd[:, b], label="desired $x_d$", **{**style(1), "marker": None})  # on top: seen where equal
        ax.plot(x[:1, a], x[:1, b], "o", color=style(0)["color"], label="start")
        ax.set_xlabel(f"${'xyz'[a]}$ (m)")
        ax.set_ylabel(f"${'xyz'[b]}$ (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
    legend(axes[-1])
    fig.suptitle(titled(title, "hand path"))
    fig.tight_layout()
    return fig


def kinematics_figure(res: SimulationResult, title: str = "") -> Figure:
    """θ̂_k(t), the kinematic parameters the adaptive Jacobian estimates (solid), and their truths (dashed), metres."""
    theta, truth = res.monitors["theta_hat"], res.monitors["theta_true"]
    names = [n[len("theta_hat["):-1] for n in res.state_names if n.startswith("theta_hat[")]
    fig, axes = panels(1)
    ax = axes[0]
    for i, name in enumerate(names):
        line = style(i)
        ax.plot(res.t, theta[:, i], label=f"$\\hat\\theta$ {name}", **line)
        ax.plot(res.t, truth[:, i], linestyle="--", color=line["color"], linewidth=1.0)
    ax.set_ylabel(r"kinematic estimate $\hat\theta_k$ (m)")
    return finish(fig, axes, titled(title, r"kinematic estimates $\hat\theta_k$ (solid), true (dashed)"))


#: the figures of one run, by file stem (`save_figures`, the gallery)
RUN_FIGURES = ("tracking_error", "parameters", "torques")


def save_figures(res: SimulationResult, directory: str | os.PathLike[str], title: str = "",
                 model: Any = None, output: FigureFormat = PNG, cores: int = 1) -> list[Path]:
    """Write `tracking_error.png`, `parameters.png` and `torques.png` (the suffix `output`'s format) into `directory`,
    and for a task-space law's run `path.png` (and `kinematics.png` for the adaptive Jacobian's θ̂_k); `model` (the
    controller's) gives the units (joint types, parameter units), else the axes say "rad or m". `cores` > 1: drawn by
    that many processes at once where forking is safe (:mod:`robotadapt.report.forked`; `robotadapt run` does)."""
    directory = writable_dir(directory)
    drawn: list[tuple[str, Callable[[], Figure]]] = [  # the heaviest first: this process draws it
        ("tracking_error", lambda: tracking_error_figure(res, title, model)),
        ("parameters", lambda: parameters_figure(res, title, model)),
        ("torques", lambda: torques_figure(res, title, model))]
    if res.space == "task":  # the hand's path, and the kinematic estimate of a law that has one
        drawn.append(("path", lambda: path_figure(res, title)))
        if "theta_hat" in res.monitors:
            drawn.append(("kinematics", lambda: kinematics_figure(res, title)))
    return spread([partial(_save, figure, directory / output.name(stem), output) for stem, figure in drawn], cores)


def _save(figure: Callable[[], Figure], path: Path, output: FigureFormat) -> Path:
    return save_figure(figure(), path, output)


# ---------------------------------------------------------------------------------------------------------------------
# one-at-a-time studies


def study_figure(key: str, runs: list[Any], title: str = "", model: Any = None) -> Figure:
    """Overlay of a one-at-a-time study: ‖e(t)‖ and ‖φ̃(t)‖ (or ‖φ̂(t)‖ when the truth is unknown), one line per
    value; log axes that start at the first nonzero value."""
    joints = joint_types(model) if model is not None else None
    fig = new_figure(figsize=(7, 6))
    ax_e, ax_p = fig.subplots(2, 1, sharex=True)
    known = bool(runs) and runs[0].result.phi is not None
    for i, run in enumerate(runs):
        res = run.result
        line = study_style(runs, i)
        label = f"{key.rsplit('.', 1)[-1]} = {number_text(run.value)}"  # the full key is in the title
        ax_e.semilogy(res.t, positive(np.linalg.norm(res.e, axis=-1)), label=label, **line)
        err = res.phi_err if res.phi_err is not None else res.phi_hat
        if err.shape[-1]:
            ax_p.semilogy(res.t, positive(np.linalg.norm(err, axis=-1)), label=label, **line)
    ax_e.set_ylabel(f"$\\Vert e(t)\\Vert$ ({norm_unit(POSITION, joints)})")
    ax_p.set_ylabel(r"$\Vert\varphi - \hat{\varphi}(t)\Vert$" if known else r"$\Vert\hat{\varphi}(t)\Vert$")
    ax_e.set_title("tracking error", fontsize="medium")
    ax_p.set_title("parameter error" if known else "parameter estimate", fontsize="medium")
    return finish(fig, [ax_e, ax_p], titled(title, f"effect of {key}"))


def study_style(runs: list[Any], i: int) -> dict[str, Any]:
    """Run i's line: for a study over numbers, an ordered colour scale (viridis, by the value's rank: neighbours in
    value are neighbours in colour), the dashes and markers of :func:`style`; else :func:`style`."""
    values = [run.value for run in runs]
    line = style(i)
    if len(values) > 1 and all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        rank = int(np.argsort(np.argsort(values, kind="stable"))[i])
        line["color"] = matplotlib.colormaps["viridis"](0.9 * rank / (len(values) - 1))
    return line


def study(key: str, runs: list[Any], path: Path, title: str = "", model: Any = None,
          output: FigureFormat = PNG) -> Path:
    """Write :func:`study_figure` to `path` in `output`'s format."""
    return save_figure(study_figure(key, runs, title, model), path, output)


# ---------------------------------------------------------------------------------------------------------------------
# a value per round of a repeated trajectory


def rounds_figure(values: dict[str, Sequence[float]], title: str, ylabel: str, xlabel: str = "round") -> Figure:
    """A value per round (one repetition of a periodic trajectory: its RMS tracking error, say) for each method, rounds
    numbered from 1 on a whole-number axis, the values on a log axis; the title wraps to stay inside the figure."""
    fig = new_figure(figsize=(6, 3.8), dpi=DEFAULT_DPI, layout="constrained")
    ax = fig.subplots()
    for i, (label, ys) in enumerate(values.items()):
        ax.semilogy(np.arange(1, len(ys) + 1), ys, label=label, color=style(i)["color"],
                    linestyle=DASHES[i % len(DASHES)], marker=MARKERS[i % len(MARKERS)])
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True, min_n_ticks=1))
    ax.set(xlabel=xlabel, ylabel=ylabel)
    ax.set_title(title, wrap=True)
    ax.grid(True, which="both", alpha=0.3)
    if values:
        ax.legend()
    return fig
