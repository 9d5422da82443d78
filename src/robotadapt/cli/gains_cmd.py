"""`robotadapt gains`: estimate ζ1…ζ4 of (7.2.9) and check the gain conditions of §7.2."""

from __future__ import annotations

import argparse
import json

from ..validation import ConfigError


def add_parser(sub: argparse._SubParsersAction) -> None:
    gains = sub.add_parser("gains", help="estimate ζ1…ζ4 of (7.2.9) and check the gain conditions of §7.2")
    gains.add_argument("scenario", help="a dcal or repetitive scenario (name or TOML file)")
    gains.add_argument("--radius", type=float, default=1.0, help="radius of the sampled error ball (default 1)")
    gains.add_argument("--samples", type=int, default=4000, help="number of sampled (t, e, r) points")
    gains.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    gains.add_argument("--json", action="store_true", help="print one JSON object")


def main(args: argparse.Namespace) -> int:
    """Exit 0 whenever the conditions could be evaluated, whatever the verdict (certified or not)."""
    from ..analysis.gains import gain_report
    from ..studies.scenarios import load
    from ..validation import as_scalar

    radius = as_scalar(args.radius, "--radius", positive=True)
    if args.samples < 10:
        raise ConfigError("--samples", f"need at least 10 samples, got {args.samples}")
    s = load(args.scenario, args.set).setup
    report = gain_report(s.controller, s.plant.phi, s.trajectory, s.t_final, radius, args.samples)
    if args.json:
        print(json.dumps(report.as_dict()))
        return 0
    z = report.zeta
    which = "certifying" if report.certified else "least-sum"
    print(f"ζ1..ζ4 ({which}; (7.2.9) at {report.samples} samples with ‖e‖, ‖r‖ ≤ {radius:g}) = "
          f"{z[0]:.4g}, {z[1]:.4g}, {z[2]:.4g}, {z[3]:.4g}")
    for eq, c in report.conditions.items():
        print(f"({eq}) {c['condition']}: {c['gain']:.4g} > {c['bound']:.4g}  {'holds' if c['holds'] else 'missed'}")
    if report.certified:
        print(f"certified for the sampled ball: every gain exceeds its bound by ≥ {100 * report.margin:.3g}%")
    else:
        hint = f" (it would with every gain × more than {1 - report.margin:.4g})" if report.margin < 0 else ""
        print(f"not certified for the sampled ball: no ζ bounding (7.2.9) at every sample meets all conditions{hint}")
    return 0
