"""`robotadapt run`: simulate a scenario; write result.npz, metrics.json, scenario.toml and the figures."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..plant.mujoco import MujocoPlant
from ..report.output import FigureFormat
from .common import add_figure_arguments, add_scenario_arguments, figure_format, overrides, summary

EXIT_DIVERGED = 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    run = sub.add_parser("run", help="simulate a scenario; write result.npz, metrics.json and figures")
    add_scenario_arguments(run)
    run.add_argument("--out", type=Path, help="output folder (default: results/NAME)")
    run.add_argument("--no-plots", action="store_true", help="skip the figures")
    add_figure_arguments(run)
    run.add_argument("--video", action="store_true", help="also write motion.mp4: the arm and, as a ghost, the desired "
                     "pose, rendered off-screen by MuJoCo (extra [mujoco]; OpenGL: OSMesa on a machine without "
                     "display, or MUJOCO_GL=egl)")


def _study(scenario: Any, out: Path, figures: FigureFormat | None) -> None:
    """Run the scenario's [study] variants; write study.json and one overlay figure per varied key (in the format
    `figures`; None: none)."""
    from ..analysis.metrics import metrics
    from ..files import atomic_write
    from ..studies.study import run_study
    from ..studies.study import summary as study_summary

    runs = run_study(scenario, progress=True)
    model = scenario.setup.controller.model
    for group in runs.values():
        for run in group:
            print(summary(f"  {run.key} = {run.value}", metrics(run.result, model), model))
    atomic_write(out / "study.json", lambda f: json.dump(study_summary(runs), f, indent=2))
    if figures is not None:
        from ..report.figures import study

        for key, group in runs.items():
            study(key, group, out / figures.name(f"study_{key.replace('.', '_')}"), scenario.name,
                  model=scenario.setup.controller.model, output=figures)


def main(args: argparse.Namespace) -> int:
    from ..analysis.metrics import metrics
    from ..report.files import save_result
    from ..studies.scenarios import load

    output = figure_format(args)
    scenario = load(args.scenario, overrides(args))
    out = args.out if args.out is not None else Path("results") / scenario.name
    if args.video:  # no OpenGL backend: say so before the run, not after it
        from ..report.video import check_rendering

        check_rendering()
    result = scenario.run(progress=True)
    model = scenario.setup.controller.model
    save_result(result, out, scenario.text, model=model)
    if not args.no_plots:
        from ..cores import usable_cores
        from ..report.figures import save_figures

        save_figures(result, out, title=scenario.name, model=scenario.setup.controller.model, output=output,
                     cores=usable_cores())
        if isinstance(scenario.setup.plant, MujocoPlant):
            from ..report.mujoco import option_estimates

            option_estimates(result, scenario.setup.plant, model, out / output.name("mujoco_options"), scenario.name,
                             output)
    print(summary(scenario.name, metrics(result, model), model))
    if args.video:
        from ..report.video import save_video
        from ..studies.scenarios.build import mujoco_view

        print(f"wrote {save_video(result, mujoco_view(scenario.data, scenario.setup.plant), out / 'motion.mp4')}")
    if scenario.study:
        _study(scenario, out, None if args.no_plots else output)
    print(f"wrote {out}/")
    return 0 if result.ok else EXIT_DIVERGED
