"""The figures of a task-space law's run (docs/task-space.md): the hand's path against the desired one, and the
adaptive Jacobian's kinematic estimates against their truths."""

from __future__ import annotations

from matplotlib.figure import Figure

from ..sim.result import SimulationResult
from .figures import finish, legend, panels, style, titled
from .output import new_figure

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


