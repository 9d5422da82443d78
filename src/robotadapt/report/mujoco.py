"""The figure of a run on a MuJoCo plant: the estimates of the columns that are MuJoCo options (rotor inertia Ia_i ↔
armature, viscous fv_i ↔ damping, Coulomb fc_i ↔ frictionloss) against the numbers read back from the compiled
MuJoCo model (`dof_armature`, `dof_damping`, `dof_frictionloss`), not from the scenario.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..plant.mujoco import MujocoPlant, option_columns
from ..robots.base import RobotModel
from ..sim.result import SimulationResult
from .figures import style
from .output import PNG, FigureFormat, new_figure, save_figure

UNITS = {"armature": ("rotor inertia $I_a$", "kg·m²"), "damping": ("viscous friction $f_v$", "N·m·s/rad"),
         "frictionloss": ("dry friction $f_c$", "N·m")}


def option_estimates(result: SimulationResult, plant: MujocoPlant, model: RobotModel, path: Path,
                     title: str = "", output: FigureFormat = PNG) -> Path | None:
    """Write the figure (one panel per option the controller's `model` estimates) to `path` in `output`'s format;
    None when it estimates none of them."""
    mj_model, _, _, vadr = plant.engine
    columns = {name: index for name, index in option_columns(model).items() if np.any(index >= 0)}
    if not columns or result.phi_hat.shape[-1] != model.p:
        return None
    fig = new_figure(figsize=(7, 1.4 + 2.6 * len(columns)))
    axes = fig.subplots(len(columns), 1, sharex=True, squeeze=False)
    for ax, (name, index) in zip(axes[:, 0], columns.items(), strict=True):
        truth = getattr(mj_model, f"dof_{name}")[vadr]
        for joint in np.flatnonzero(index >= 0):
            line = style(int(joint))
            ax.plot(result.t, result.phi_hat[:, index[joint]], label=f"joint {joint + 1}", **line)
            ax.axhline(truth[joint], color=line["color"], linestyle=":", linewidth=1.0)
        meaning, unit = UNITS[name]
        ax.set_ylabel(f"{meaning} ({unit})")
        ax.set_title(f"estimates (lines) and MuJoCo's {name} (dotted)", fontsize="medium")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small", ncol=2)
    axes[-1, 0].set_xlabel("time $t$ (s)")
    fig.suptitle(f"{title} — MuJoCo's joint options" if title else "MuJoCo's joint options")
    fig.tight_layout()
    return save_figure(fig, path, output)

