"""Pieces several commands share: scenario arguments, figure arguments and the run summary."""

from __future__ import annotations

import argparse
import textwrap
from typing import Any

from ..report.output import DEFAULT_DPI, FORMATS, FigureFormat
from ..validation import ConfigError


def add_scenario(parser: argparse.ArgumentParser,
                 what: str = "a packaged scenario name (see `robotadapt list`) or a TOML file") -> None:
    """The scenario positional (`what` it is for) and `--set`."""
    parser.add_argument("scenario", help=what)
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override any scenario field, e.g. --set controller.Kv=20 (repeatable)")


def add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    """The scenario positional and the `--set`, `--t-final`, `--dt`, `--control-period`, `--backend` overrides."""
    add_scenario(parser)
    parser.add_argument("--t-final", type=float, help="shorthand for --set simulation.t_final=T")
    parser.add_argument("--dt", type=float, help="shorthand for --set simulation.dt=DT")
    parser.add_argument("--control-period", type=float, metavar="T_S",
                        help="shorthand for --set simulation.control_period=T_S: sampled-data control at 1/T_S Hz")
    parser.add_argument("--backend", choices=("auto", "numpy", "jax", "c"),
                        help="shorthand for --set simulation.backend=NAME: 'jax' compiles the loop, 'numpy' steps it "
                             "in Python, 'c' translates the compiled loop to C (the system's compiler; fixed-step and "
                             "sampled runs), 'auto' (the scenario's default) compiles all but short runs (a single "
                             "run to C where a compiler is present; batches, and runs without one, with JAX)")


def overrides(args: argparse.Namespace) -> list[str]:
    """`--set` assignments plus the `--t-final` / `--dt` / `--control-period` / `--backend` shorthands."""
    out = list(args.set)
    for name in ("t_final", "dt", "control_period", "backend"):
        if getattr(args, name, None) is not None:
            out.append(f"simulation.{name}={getattr(args, name)!r}")
    return out


def add_figure_arguments(parser: argparse.ArgumentParser) -> None:
    """`--format` and `--dpi`: how the command writes its figures (read back by :func:`figure_format`)."""
    parser.add_argument("--format", default="png", metavar="{" + ",".join(FORMATS) + "}",
                        help="file format of the figures (default png); pdf and svg are vector graphics, for papers")
    parser.add_argument("--dpi", default=DEFAULT_DPI, metavar="N",
                        help=f"resolution of the figures in dots per inch (default {DEFAULT_DPI}); in pdf and svg it "
                             "sets only the rasterised parts")


def figure_format(args: argparse.Namespace) -> FigureFormat:
    """The figures' format and dpi asked on the command line; a bad value is a ConfigError naming its option (checked
    before any run, so a typo costs no simulation)."""
    try:
        dpi = int(args.dpi)
    except ValueError:
        raise ConfigError("--dpi", f"expected a positive whole number of dots per inch, got {args.dpi!r}") from None
    return FigureFormat(args.format, dpi)


def fmt(values: list[float]) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in values) + "]"


#: above this many parameters the summary gives the parameter error instead of every estimate
MAX_SUMMARY_PARAMETERS = 6
#: the summary's lines wrap at this many characters
SUMMARY_WIDTH = 100


def summary(name: str, m: dict[str, Any], model: Any = None) -> str:
    """The run's summary, a line per quantity, every number with its unit, lines wrapped at `SUMMARY_WIDTH`: status and
    final time; final |e|, RMS e and max |τ| per joint (rad or m, N·m or N by the joint types of the controller's
    `model`; "rad or m" without it); the final estimate (its error ‖φ̃‖ for many parameters; for a model with
    unidentifiable directions, the base-parameter error ‖K φ̃‖/‖K φ‖ and how many directions the dynamics cannot see);
    where the estimate left the physically consistent set; the warnings of :func:`health_warnings`."""
    from ..analysis.metrics import health_warnings
    from ..report.figures import EFFORT, POSITION, joint_types, parameter_units

    joints = joint_types(model) if model is not None else None
    task = m.get("error_space") == "task"  # the hand's error x_d − x, in metres (docs/task-space.md)
    errors = "P" * len(m["rms_error"]) if task else joints
    lines = [f"final |e| = {_with_units(m['final_abs_error'], POSITION, errors)}" + (" (hand)" if task else ""),
             f"RMS e     = {_with_units(m['rms_error'], POSITION, errors)}",
             f"max |τ|   = {_with_units(m['max_abs_torque'], EFFORT, joints)}",
             _estimate(m, parameter_units(model, m["param_names"])), *_kinematics(m), *_left(m),
             *(f"warning: {w}" for w in health_warnings(m))]
    indent = name[: len(name) - len(name.lstrip())] + "  "  # a study's variant, "  Kv = 20", indents its lines
    head = f"{name}: {m['status']}; t = {m['t_end']:.4g} s"
    return "\n".join([_wrap(head, ""), *(_wrap(line, indent) for line in lines)])


def _wrap(line: str, indent: str) -> str:
    """`line` after `indent`, wrapped at `SUMMARY_WIDTH` with a hanging indent, never inside a number (1e-05)."""
    return textwrap.fill(line, SUMMARY_WIDTH, initial_indent=indent, subsequent_indent=indent + "    ",
                         break_on_hyphens=False, break_long_words=False)


def _with_units(values: list[float], units: dict[str, str], joints: str | None) -> str:
    """`[0.01, 0.02] rad` (the unit of each joint type in `units`), or a unit each for mixed joint types."""
    kinds = joints if joints is not None and len(joints) == len(values) else "?" * len(values)
    if len(set(kinds)) == 1:
        return f"{fmt(values)} {units[kinds[0]]}"
    return "[" + ", ".join(f"{v:.4g} {units[kind]}" for v, kind in zip(values, kinds, strict=True)) + "]"


def _kinematics(m: dict[str, Any]) -> list[str]:
    """The kinematic estimate of the adaptive Jacobian, with its truth (metres)."""
    if "final_theta_hat" not in m:
        return []
    return ["final " + ", ".join(f"{name} = {value:.4g} m (true {truth:.4g})" for name, value, truth in
                                 zip(m["kinematic_names"], m["final_theta_hat"], m["theta_true"], strict=True))]


def _left(m: dict[str, Any]) -> list[str]:
    """Where an arm's link estimates left the physically consistent set (docs/natural.md), when they did."""
    if m.get("left_consistent_set_t") is None or not any(p.startswith("link") for p in m.get("consistency_parts", ())):
        return []
    return [f"the estimate left the physically consistent set at t = {m['left_consistent_set_t']:.4g} s "
            f"({m['left_consistent_set_part']}; smallest pseudo-inertia eigenvalue "
            f"{m['min_pseudo_inertia_eigenvalue']:.3g})"]


def _estimate(m: dict[str, Any], units: list[str | None]) -> str:
    """The final estimate, each with its unit; its error, or the base parameters', when there are many."""
    names = m["param_names"]
    if "unidentifiable_directions" in m:  # an n-DOF arm: what the dynamics can see, the base parameters
        hidden = f"{m['unidentifiable_directions']} of {len(names)} directions unidentifiable"
        if m.get("final_base_phi_error_relative") is not None:
            return (f"final ‖K(φ − φ̂)‖/‖Kφ‖ = {m['final_base_phi_error_relative']:.3g} over "
                    f"{m['base_parameters']} base parameters, {hidden}")
        return f"{m['base_parameters']} base parameters estimated, {hidden}"
    if not names:  # a law without a parameter estimate (the repetitive law learns the feedforward instead)
        return "no parameter estimate"
    if len(names) <= MAX_SUMMARY_PARAMETERS:
        return "final " + ", ".join(f"{name} = {value:.4g}" + (f" {unit}" if unit else "")
                                    for name, value, unit in zip(names, m["final_phi_hat"], units, strict=True))
    if "final_phi_error" in m:
        unit = units[0] if len(set(units)) == 1 and units[0] else "(mixed units)"
        return f"final ‖φ − φ̂‖ = {m['final_phi_error']:.4g} {unit} over {len(names)} parameters"
    return f"{len(names)} parameters estimated"
