"""`robotadapt` command line: parse, call the library, write files. Bad input exits 2 with one line, no traceback."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .validation import ConfigError

EXIT_BAD_INPUT = 2
EXIT_DIVERGED = 1


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="robotadapt", description="Adaptive control of rigid robot manipulators.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    sub.add_parser("list", help="the packaged scenarios, one line each")
    run = sub.add_parser("run", help="simulate a scenario; write result.npz, metrics.json and figures")
    run.add_argument("scenario", help="a packaged scenario name (see `robotadapt list`) or a TOML file")
    run.add_argument("--out", type=Path, help="output folder (default: results/NAME)")
    run.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                     help="override any scenario field, e.g. --set controller.Kv=20 (repeatable)")
    run.add_argument("--t-final", type=float, help="shorthand for --set simulation.t_final=T")
    run.add_argument("--dt", type=float, help="shorthand for --set simulation.dt=DT")
    run.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    gains = sub.add_parser("gains", help="estimate ζ1…ζ4 of (7.2.9) and check the gain conditions of §7.2")
    gains.add_argument("scenario", help="a dcal or repetitive scenario (name or TOML file)")
    gains.add_argument("--radius", type=float, default=1.0, help="radius of the sampled error ball (default 1)")
    gains.add_argument("--samples", type=int, default=4000, help="number of sampled (t, e, r) points")
    gains.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    gains.add_argument("--json", action="store_true", help="print one JSON object")
    return p


def _list() -> int:
    from .scenarios import available

    items = available()
    width = max(map(len, items)) if items else 0
    for name, description in items.items():
        print(f"{name:<{width}}  {description}")
    return 0


def _fmt(values: list[float]) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in values) + "]"


def _summary(name: str, m: dict) -> None:
    print(f"{name}: {m['status']}; t = {m['t_end']:.4g} s, final |e| = {_fmt(m['final_abs_error'])}, "
          f"RMS e = {_fmt(m['rms_error'])}, final {', '.join(m['param_names'])} = {_fmt(m['final_phi_hat'])}")


def _study(scenario, out: Path, no_plots: bool) -> None:  # type: ignore[no-untyped-def]
    """Run the scenario's [study] variants; write study.json and one overlay figure per varied key."""
    import json

    from .result import atomic_write
    from .study import run_study, summary

    runs = run_study(scenario, progress=True)
    for group in runs.values():
        for run in group:
            _summary(f"  {run.key} = {run.value}", run.result.metrics())
    atomic_write(out / "study.json", lambda f: json.dump(summary(runs), f, indent=2))
    if not no_plots:
        from .plotting import study

        for key, group in runs.items():
            study(key, group, out / f"study_{key.replace('.', '_')}.png", scenario.name)


def _gains(args: argparse.Namespace) -> int:
    import json

    from .gains import gain_report
    from .scenarios import load
    from .validation import as_scalar

    radius = as_scalar(args.radius, "--radius", positive=True)
    if args.samples < 10:
        raise ConfigError("--samples", f"need at least 10 samples, got {args.samples}")
    s = load(args.scenario, args.set).setup
    report = gain_report(s.controller, s.plant.phi, s.trajectory, s.t_final, radius, args.samples)
    if args.json:
        print(json.dumps(report.as_dict()))
        return 0
    z = report.zeta
    print(f"ζ1..ζ4 (estimated over ‖e‖, ‖r‖ ≤ {radius:g}, {report.samples} samples) = "
          f"{z[0]:.4g}, {z[1]:.4g}, {z[2]:.4g}, {z[3]:.4g}")
    for eq, c in report.conditions.items():
        print(f"({eq}) {c['condition']}: {c['gain']:.4g} > {c['bound']:.4g}  {'holds' if c['holds'] else 'FAILS'}")
    print("all gain conditions hold" if report.all_hold else "some gain conditions fail (for the sampled ball)")
    return 0


def _run(args: argparse.Namespace) -> int:
    from .scenarios import load

    overrides = list(args.set)
    if args.t_final is not None:
        overrides.append(f"simulation.t_final={args.t_final!r}")
    if args.dt is not None:
        overrides.append(f"simulation.dt={args.dt!r}")
    scenario = load(args.scenario, overrides)
    out = args.out if args.out is not None else Path("results") / scenario.name
    result = scenario.run(progress=True)
    result.save(out, scenario.text)
    if not args.no_plots:
        result.plot(out, title=scenario.name)
    _summary(scenario.name, result.metrics())
    if scenario.study:
        _study(scenario, out, args.no_plots)
    print(f"wrote {out}/")
    return 0 if result.ok else EXIT_DIVERGED


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "list":
            return _list()
        if args.command == "gains":
            return _gains(args)
        return _run(args)
    except ConfigError as exc:
        print(f"robotadapt: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("robotadapt: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a reader that stopped early (e.g. `| head`)
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
