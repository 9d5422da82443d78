"""`robotadapt excite SCENARIO --harmonics K --period T`: an optimised exciting trajectory for identification, within
joint position, velocity, acceleration and torque limits (docs/identification.md#excitation)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from ..validation import ConfigError
from .common import add_figure_arguments, add_scenario, figure_format


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("excite", help="optimise a finite Fourier series (Swevers 1997) per joint for identification: "
                       "the smallest condition number of the stacked base regressor within the joint limits")
    add_scenario(p, "the scenario whose controller's model is to be identified (packaged name or TOML)")
    p.add_argument("--harmonics", type=int, default=5, metavar="K", help="harmonics per joint, ≥ 2 (default 5)")
    p.add_argument("--period", type=float, default=10.0, metavar="T", help="period of the series in s (default 10)")
    p.add_argument("--objective", default="cond", choices=("cond", "logdet"),
                   help="minimise the condition number of W (default: what bounds the least-squares error) or maximise "
                   "log det WᵀW (D-optimal)")
    p.add_argument("--samples", type=int, metavar="N", help="instants of the period the objective and limits are "
                   "evaluated at (default 20 per harmonic, at least 4 equations per base parameter)")
    p.add_argument("--starts", type=int, default=3, metavar="S", help="random feasible starts (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random starts (default 0)")
    p.add_argument("--max-iter", metavar="N", help="most SLSQP iterations per start (default 300)")
    p.add_argument("--time-budget", metavar="SECONDS", help="stop the search when this many seconds have passed since "
                   "it began (compilation included) and keep the best feasible point found so far; excite.json's "
                   "`stopped` says so (default: no limit)")
    p.add_argument("--fraction", type=float, default=0.9, metavar="F",
                   help="use this fraction of every limit, a margin for what the model misses (default 0.9)")
    p.add_argument("--position-limit", metavar="SPEC",
                   help="joint position range: X (|q| ≤ X) or LO:HI, one or one per joint, comma-separated (default: "
                   "the URDF's or model's limits)")
    for kind, unit in (("velocity", "rad/s"), ("acceleration", "rad/s²"), ("torque", "N·m")):
        p.add_argument(f"--{kind}-limit", metavar="X", help=f"|{kind}| bound in {unit}, one or one per joint, "
                       "comma-separated (default: the URDF's where it has one, else none)")
    p.add_argument("--out", type=Path, help="folder for excite.json, trajectory.toml, scenario.toml and excite.png "
                   "(default: results/excite-SCENARIO)")
    p.add_argument("--no-plots", action="store_true", help="skip the figure excite.png")
    add_figure_arguments(p)


def limit_spec(text: str | None, n: int, option: str, position: bool = False) -> Any:
    """A limit given on the command line: (n,) bounds, or (n, 2) ranges for `position` (X means −X:X)."""
    if text is None:
        return None
    fields = [f.strip() for f in text.split(",")]
    if len(fields) not in (1, n):
        raise ConfigError(option, f"expected one value or {n} (one per joint), comma-separated, got {len(fields)}")
    try:
        rows = [[float(x) for x in f.split(":")] if position else [float(f)] for f in fields]
    except ValueError:
        raise ConfigError(option, f"expected numbers{' or LO:HI' * position}, got {text!r}") from None
    if position:
        rows = [[-r[0], r[0]] if len(r) == 1 else r for r in rows]
        if any(len(r) != 2 or not r[0] < r[1] for r in rows):
            raise ConfigError(option, f"expected X > 0 or LO:HI with LO < HI per joint, got {text!r}")
    values = np.array(rows * n if len(rows) == 1 else rows, dtype=float)
    if not np.all(np.isfinite(values)) or (not position and np.any(values <= 0)):
        raise ConfigError(option, f"expected finite{'' if position else ' positive'} numbers, got {text!r}")
    return values if position else values[:, 0]


def positive(text: str | None, option: str, kind: type[int] | type[float], expected: str) -> Any:
    """`--max-iter` (a whole number ≥ 1) or `--time-budget` (a positive finite number of seconds) as `kind`, or None
    (not given: the library's default); `expected` words the value in the one-line refusal."""
    if text is None:
        return None
    try:
        value = kind(text)
    except ValueError:
        value = 0
    if not 0 < value < float("inf"):
        raise ConfigError(option, f"expected {expected}; got {text!r}")
    return value


def main(args: argparse.Namespace) -> int:
    from ..files import atomic_write, writable_dir
    from ..studies.excite import Design, before, excite, resolve_limits
    from ..studies.scenarios import load

    output = figure_format(args)
    iterations = positive(args.max_iter, "--max-iter", int, "a whole number of iterations ≥ 1, e.g. --max-iter 100")
    budget = positive(args.time_budget, "--time-budget", float, "a positive number of seconds, e.g. --time-budget 60")
    scenario = load(args.scenario, list(args.set))
    s = scenario.setup
    model = s.controller.model
    n = model.n
    given = {"position": limit_spec(args.position_limit, n, "--position-limit", position=True),
             **{kind: limit_spec(getattr(args, f"{kind}_limit"), n, f"--{kind}-limit")
                for kind in ("velocity", "acceleration", "torque")}}
    limits = resolve_limits(model, given, args.fraction,
                            "urdf" if scenario.data["robot"].get("kind") in ("urdf", "example_robot") else "model")
    design = Design(n, args.harmonics, args.period)
    result = excite(model, design, limits, args.objective, args.samples, args.starts, np.random.default_rng(args.seed),
                    time_budget=budget, progress=True, **({} if iterations is None else {"max_iter": iterations}))
    old = before(model, s.trajectory, s.t_final, design, result.samples, limits)
    a, b, offset = design.coefficients(result.x)
    table = {"kind": "fourier", "period": design.period, "a": a.tolist(), "b": b.tolist(), "offset": offset.tolist()}
    data = {k: v for k, v in scenario.data.items() if k != "study"}
    q0 = result.trajectory()(0.0).q_des
    data = {**data, "trajectory": table, "plant": {**data["plant"], "q0": q0.tolist(), "dq0": 0.0},
            "description": f"{scenario.description} — driven by the exciting trajectory of `robotadapt excite` "
                           f"({design.harmonics} harmonics, T = {design.period:g} s, cond W = {result.cond:.4g})"}
    record = {"scenario": scenario.name, **result.as_dict(), "limits": limits.as_dict(), "before": old,
              "cond_before": old["cond"], "cond_after": result.cond, "limits_met": result.fine.met}
    out = writable_dir(args.out if args.out is not None else Path("results") / f"excite-{scenario.name}")
    atomic_write(out / "trajectory.toml", lambda f: f.write(tomli_w.dumps({"trajectory": table})))
    atomic_write(out / "scenario.toml", lambda f: f.write(tomli_w.dumps(data)))
    if not args.no_plots:
        from ..report.identification_figures import excitation_figure

        excitation_figure(model, result, s.trajectory, old, out / output.name("excite"), scenario.name, output)
    atomic_write(out / "excite.json", lambda f: json.dump(record, f, indent=2))
    print(_summary(record))
    print(f"wrote {out}/ (run it: robotadapt run {out / 'scenario.toml'}; or paste trajectory.toml's table into a "
          "scenario)")
    return 0


def _summary(record: dict[str, Any]) -> str:
    ratios = ", ".join(f"{k} {v:.3g}" for k, v in record["worst_ratio"].items() if v is not None)
    old = record["before"]
    met = "meets" if old["limits_met"] else "does not meet"
    runs = f"{record['starts_run']} of {record['starts']} starts" if record["starts_run"] < record["starts"] else (
        f"{record['starts']} start{'s' * (record['starts'] > 1)}")
    return (f"{record['scenario']}: cond W {old['cond']:.4g} (the scenario's own trajectory, which {met} the same limits)"
            f" → {record['cond_after']:.4g} ({record['objective']} objective, {record['harmonics']} harmonics, T = "
            f"{record['period']:g} s, {record['samples']} samples, {record['seconds']:.1f} s); limits "
            f"{'met' if record['limits_met'] else 'NOT met'}, largest share of each bound used: {ratios}; SLSQP "
            f"stopped: {record['stopped']} ({runs}, iterations {', '.join(map(str, record['iterations']))})")
