"""`robotadapt pe`: is the scenario's desired trajectory persistently exciting for its model?
(docs/laws.md#persistency-of-excitation, (6.5.2))"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .common import add_figure_arguments, add_scenario_arguments, figure_format, fmt, overrides


def add_parser(sub: argparse._SubParsersAction) -> None:
    pe = sub.add_parser("pe", help="persistency of excitation of the desired trajectory: α, β over windows of ρ (6.5.2)")
    add_scenario_arguments(pe)
    pe.add_argument("--window", type=float, metavar="RHO",
                    help="window length ρ in s (default: the trajectory's period, else a quarter of the horizon)")
    pe.add_argument("--json", action="store_true", help="print one JSON object instead of the text verdict")
    pe.add_argument("--out", type=Path, help="folder for pe.json and the figure pe.png (default: results/NAME)")
    pe.add_argument("--no-plots", action="store_true", help="skip the figure pe.png")
    add_figure_arguments(pe)


def main(args: argparse.Namespace) -> int:
    """Exit 0 whatever the verdict; the horizon is the scenario's t_final (--t-final to change it)."""
    from ..analysis.excitation import excitation
    from ..files import atomic_write, writable_dir
    from ..studies.scenarios import load

    output = figure_format(args)
    scenario = load(args.scenario, overrides(args))
    s = scenario.setup
    exc = excitation(s.controller.model, s.trajectory, s.t_final, args.window)
    out = writable_dir(args.out if args.out is not None else Path("results") / scenario.name)
    verdict = exc.as_dict()
    atomic_write(out / "pe.json", lambda f: json.dump({**verdict, "series": exc.series()}, f, indent=2))
    if not args.no_plots:
        from ..report.html import excitation_figure

        excitation_figure(exc, out / output.name("pe"), scenario.name, output)
    if args.json:
        print(json.dumps(verdict))
        return 0
    what = f"the {len(exc.param_names)} base parameters " if exc.unidentifiable else ""
    direction = ", ".join(f"{k} = {v:.4g}" for k, v in exc.weakest_direction.items())
    print(f"{scenario.name}: {'' if exc.persistently_exciting else 'NOT '}persistently exciting (6.5.2) for "
          f"{what}({', '.join(exc.param_names)}), windows of ρ = {exc.window:.6g} s ({exc.window_source}), "
          f"t0 from 0 to {exc.t0[-1]:.4g} s")
    print(f"  α = min λ_min = {exc.alpha_min:.6g}, β = max λ_max = {exc.beta_max:.6g}; "
          f"PE iff α ≥ {exc.rtol:g}·β = {exc.rtol * exc.beta_max:.3g}")
    rank = f"rank {exc.rank} of {len(exc.param_names)}"
    if exc.unidentifiable:
        rank += (f" identifiable ({exc.unidentifiable} of {exc.standard_parameters} standard directions unidentifiable "
                 "by construction)")
    print(f"  weakest window t0 = {exc.t0_worst:.4g} s: eigenvalues {fmt(exc.eigenvalues.tolist())}, {rank}; "
          f"least excited direction {direction}")
    print(f"  infinite-integral test (6.6.18): λ_min ∫_0^t Y_dᵀY_d = {exc.lambda_min_cum[-1]:.4g} at t = "
          f"{exc.t_cum[-1]:.4g} s, ∝ t^{exc.growth_exponent:.2f} over the second half: "
          f"{'grows without bound' if exc.integral_grows else 'levels off'}")
    print(f"wrote {out}/")
    return 0
