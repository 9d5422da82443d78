"""Book-style figures of a run: tracking error, parameter estimates against the truth, torques (one PNG each)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ..files import atomic_write, writable_dir  # noqa: E402

if TYPE_CHECKING:
    from ..sim.result import SimulationResult


def _finish(fig: Any, ax: Any, title: str, path: Path) -> Path:
    ax.set_title(title)
    ax.set_xlabel("t (s)")
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110), binary=True)
    plt.close(fig)
    return path


def tracking_error(res: SimulationResult, path: Path, title: str = "") -> Path:
    """e_i(t) = q_des,i − q_i for every joint."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for i in range(res.e.shape[-1]):
        ax.plot(res.t, res.e[:, i], label=f"e{i + 1}")
    ax.set_ylabel("tracking error (rad or m)")
    return _finish(fig, ax, f"{title} — tracking error".strip(" —"), path)


#: above this many parameters one line each is unreadable: the figure shows the relative error instead
MAX_PARAMETER_LINES = 8


def parameters(res: SimulationResult, path: Path, title: str = "") -> Path:
    """φ̂(t), solid, with the true φ(t) dashed in the same colour when known; for more than `MAX_PARAMETER_LINES`
    parameters (n-DOF arms) the relative error ‖φ̃(t)‖ / ‖φ(t)‖ when the truth is known, else ‖φ̂(t)‖."""
    import numpy as np

    fig, ax = plt.subplots(figsize=(7, 4))
    truth = res.phi_true
    if not res.param_names:
        ax.text(0.5, 0.5, "this controller estimates no parameters", ha="center", va="center", transform=ax.transAxes)
    elif len(res.param_names) > MAX_PARAMETER_LINES:
        if truth is not None and res.phi_err is not None:
            rel = np.linalg.norm(res.phi_err, axis=-1) / np.maximum(np.linalg.norm(truth, axis=-1), 1e-300)
            ax.semilogy(res.t, rel + 1e-16, label=f"‖φ − φ̂‖ / ‖φ‖ ({len(res.param_names)} parameters)")
            ax.set_ylabel("relative parameter error")
        else:
            ax.plot(res.t, np.linalg.norm(res.phi_hat, axis=-1), label=f"‖φ̂‖ ({len(res.param_names)} parameters)")
            ax.set_ylabel("‖φ̂‖")
        return _finish(fig, ax, f"{title} — parameter estimates".strip(" —"), path)
    for i, name in enumerate(res.param_names):
        (line,) = ax.plot(res.t, res.phi_hat[:, i], label=f"{name} estimate")
        if truth is not None:
            ax.plot(res.t, truth[:, i], color=line.get_color(), linestyle="--", label=f"{name} true")
    ax.set_ylabel("parameter")
    return _finish(fig, ax, f"{title} — parameter estimates".strip(" —"), path)


def torques(res: SimulationResult, path: Path, title: str = "") -> Path:
    """Controller output τ_i(t)."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for i in range(res.tau.shape[-1]):
        ax.plot(res.t, res.tau[:, i], label=f"tau{i + 1}")
    ax.set_ylabel("torque (N·m) or force (N)")
    return _finish(fig, ax, f"{title} — control input".strip(" —"), path)


def save_figures(res: SimulationResult, directory: str | os.PathLike[str], title: str = "") -> list[Path]:
    """Write `tracking_error.png`, `parameters.png` and `torques.png` into `directory`."""
    directory = writable_dir(directory)
    return [tracking_error(res, directory / "tracking_error.png", title),
            parameters(res, directory / "parameters.png", title),
            torques(res, directory / "torques.png", title)]


def study(key: str, runs: list[Any], path: Path, title: str = "") -> Path:
    """Overlay of a one-at-a-time study: ‖e(t)‖ and ‖φ̃(t)‖ (or ‖φ̂(t)‖ when the truth is unknown), one line per value."""
    import numpy as np

    fig, (ax_e, ax_p) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for run in runs:
        res = run.result
        ax_e.semilogy(res.t, np.linalg.norm(res.e, axis=-1) + 1e-16, label=f"{key} = {run.value}")
        err = res.phi_err if res.phi_err is not None else res.phi_hat
        ax_p.semilogy(res.t, np.linalg.norm(err, axis=-1) + 1e-16, label=f"{key} = {run.value}")
    ax_e.set_ylabel("‖e‖")
    ax_e.grid(True, alpha=0.3)
    ax_e.legend(loc="best", fontsize="small")
    ax_p.set_ylabel("‖φ − φ̂‖" if runs and runs[0].result.phi is not None else "‖φ̂‖")
    ax_e.set_title(f"{title} — effect of {key}".strip(" —"))
    return _finish(fig, ax_p, "", path)
