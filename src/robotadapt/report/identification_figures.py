"""The figure of `robotadapt identify`: held-out torque, measured against each estimate's prediction
(docs/identification.md)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from ..analysis.identification import Identification  # noqa: E402
from .output import PNG, FigureFormat, save_figure  # noqa: E402

STYLES = {"consistent": "-", "wls": "--", "ols": ":", "prior": "-."}


def holdout_plot(result: Identification, title: str = "") -> Figure:
    """One panel per joint: the held-out torque and its prediction by each estimate and the prior, with RMS errors."""
    n = result.holdout_tau.shape[1]
    cols = 2 if n > 3 else 1
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(7 * cols, 1.9 * rows + 0.8), sharex=True, squeeze=False)
    rms = result.holdout_rms
    for i, ax in enumerate(axes.flat):
        if i >= n:
            ax.set_visible(False)
            continue
        ax.plot(result.holdout_t, result.holdout_tau[:, i], color="k", linewidth=1.6, label="measured")
        for name, tau in result.holdout_prediction.items():
            ax.plot(result.holdout_t, tau[:, i], STYLES.get(name, "-"), linewidth=1.0,
                    label=f"{name} (RMS {rms[name][i]:.3g})")
        ax.set_ylabel(f"$\\tau_{{{i + 1}}}$")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="x-small")
    for ax in axes[-1]:
        ax.set_xlabel("time $t$ (s)")
    fig.suptitle(f"{title}: held-out torque (N·m or N) and its prediction".lstrip(": "))
    fig.tight_layout()
    return fig


def holdout_figure(result: Identification, path: Path, title: str = "", output: FigureFormat = PNG) -> Path:
    """:func:`holdout_plot` written to `path` in `output`'s format."""
    return save_figure(holdout_plot(result, title), path, output)
