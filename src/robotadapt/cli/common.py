"""Pieces several commands share: scenario arguments and the one-line run summary."""

from __future__ import annotations

import argparse
from typing import Any


def add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    """The scenario positional and the `--set`, `--t-final`, `--dt` overrides."""
    parser.add_argument("scenario", help="a packaged scenario name (see `robotadapt list`) or a TOML file")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override any scenario field, e.g. --set controller.Kv=20 (repeatable)")
    parser.add_argument("--t-final", type=float, help="shorthand for --set simulation.t_final=T")
    parser.add_argument("--dt", type=float, help="shorthand for --set simulation.dt=DT")


def overrides(args: argparse.Namespace) -> list[str]:
    """`--set` assignments plus the `--t-final` / `--dt` shorthands."""
    out = list(args.set)
    if getattr(args, "t_final", None) is not None:
        out.append(f"simulation.t_final={args.t_final!r}")
    if getattr(args, "dt", None) is not None:
        out.append(f"simulation.dt={args.dt!r}")
    return out


def fmt(values: list[float]) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in values) + "]"


def summary(name: str, m: dict[str, Any]) -> str:
    """One line: status, final and RMS error, final estimate."""
    return (f"{name}: {m['status']}; t = {m['t_end']:.4g} s, final |e| = {fmt(m['final_abs_error'])}, "
            f"RMS e = {fmt(m['rms_error'])}, final {', '.join(m['param_names'])} = {fmt(m['final_phi_hat'])}")
