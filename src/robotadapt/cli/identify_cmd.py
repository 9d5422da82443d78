"""`robotadapt identify DATA --robot SCENARIO`: base parameters from logged joint data, physically consistent, as a
φ̂(0) for adaptation (docs/identification.md)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from .common import add_figure_arguments, figure_format, fmt


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify the base parameters from logged joint data (result.npz or CSV): "
                       "filtering, OLS/WLS, relative standard deviations, a physically consistent estimate")
    p.add_argument("data", metavar="DATA", help="a result.npz of `robotadapt run`, or a CSV with columns t, q1…qn, "
                   "optional dq1…dqn, tau1…taun (SI units)")
    p.add_argument("--robot", required=True, metavar="SCENARIO",
                   help="the scenario whose controller's model is identified (packaged name or TOML file)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a field of the robot's scenario (repeatable)")
    p.add_argument("--out", type=Path, help="folder for identified.json, identified.md, the URDF copy and the figure "
                   "(default: results/identify-SCENARIO)")
    p.add_argument("--cutoff", type=float, metavar="HZ",
                   help="zero-phase Butterworth low-pass on q, q̇ and τ alike (default: none; for measured data a few "
                   "times the trajectory's highest frequency)")
    p.add_argument("--window", type=int, default=9, metavar="N",
                   help="Savitzky–Golay window of the derivatives, odd, samples (default 9)")
    p.add_argument("--polyorder", type=int, default=6, metavar="N", help="Savitzky–Golay order (default 6)")
    p.add_argument("--trim", type=float, metavar="S", help="seconds dropped at each end (default 3/cutoff, else 0)")
    p.add_argument("--decimate", type=int, default=1, metavar="D", help="keep every D-th filtered sample (default 1)")
    p.add_argument("--holdout", type=float, default=0.25, metavar="F",
                   help="fraction of the log, at its end, held out to test the torque prediction (default 0.25)")
    p.add_argument("--estimate", default="consistent", choices=("consistent", "wls", "ols"),
                   help="which estimate identified.json hands on as phi (default consistent: J_i ⪰ ε𝟙, cvxpy)")
    p.add_argument("--epsilon", type=float, default=1e-8, metavar="E",
                   help="margin of the consistent estimate: every pseudo-inertia ⪰ E·𝟙 (default 1e-8; the Panda URDF's "
                   "own smallest eigenvalue is 8.6e-7)")
    p.add_argument("--prior", default="estimate", choices=("estimate", "nominal"),
                   help="φ₀, where the directions no data see stay and what the held-out prediction is compared with: "
                   "the scenario's initial estimate phi_hat0 (default) or the model's nominal (published) values")
    p.add_argument("--no-plots", action="store_true", help="skip the figure holdout.png")
    add_figure_arguments(p)


def main(args: argparse.Namespace) -> int:
    from ..analysis.identification import Preprocessing, identify
    from ..analysis.joint_data import read
    from ..files import atomic_write, writable_dir
    from ..studies.scenarios import load

    output = figure_format(args)
    pre = Preprocessing(args.cutoff, args.window, args.polyorder, args.trim, args.decimate)
    scenario = load(args.robot, list(args.set))
    model = scenario.setup.controller.model
    data = read(args.data, model.n)
    prior = getattr(scenario.setup.controller, "phi_hat0", None) if args.prior == "estimate" else None
    result = identify(model, data, pre, args.holdout, consistent=args.estimate == "consistent", epsilon=args.epsilon,
                      prior=prior)
    record: dict[str, Any] = {"scenario": scenario.name, "data": str(args.data), "estimate": args.estimate,
                              "phi": result.standard[args.estimate].tolist(), **result.as_dict()}
    truth = _truth(args.data, model.p)
    if truth is not None:
        K = result.basis.K
        record["base_error_relative"] = {k: float(np.linalg.norm(v - K @ truth) / np.linalg.norm(K @ truth))
                                         for k, v in {**result.base, "prior": K @ result.prior}.items()}
    urdf = _urdf_source(scenario.setup.data["robot"])
    if urdf is not None and result.consistency(args.estimate) <= 0:  # a URDF holds bodies only: decided before writing
        record["urdf"], record["urdf_skipped"] = None, (f"the {args.estimate} estimate is no rigid body (smallest "
                                                        "pseudo-inertia eigenvalue ≤ 0): use --estimate consistent")
        urdf = None
    out = writable_dir(args.out if args.out is not None else Path("results") / f"identify-{scenario.name}")
    if urdf is not None:
        from ..robots.consistency import parts
        from ..robots.urdf_export import write_identified_urdf

        links = [list(p.entries) for p in parts(model.param_names) if p.name.startswith("link")]
        write_identified_urdf(urdf[0], urdf[1], result.standard[args.estimate][np.array(links)], out / "identified.urdf")
        record["urdf"] = str(out / "identified.urdf")
    atomic_write(out / "identified.md", lambda f: f.write(_table(record)))
    if not args.no_plots:
        from ..report.identification_figures import holdout_figure

        if result.holdout_t.size:
            holdout_figure(result, out / output.name("holdout"), scenario.name, output)
    atomic_write(out / "identified.json", lambda f: json.dump(record, f, indent=2))
    print(_summary(record, data.source))
    print(f"wrote {out}/ (start a scenario from it: phi_hat0 = {{file = \"{out / 'identified.json'}\"}})")
    return 0


def _truth(path: str, p: int) -> Any:
    """The true φ a result.npz of ours records, when it has the controller's p entries."""
    if not str(path).endswith(".npz"):
        return None
    with np.load(path) as f:
        phi = np.asarray(f["phi"], dtype=float) if "phi" in f.files else None
    return phi if phi is not None and phi.shape == (p,) else None


def _urdf_source(robot: dict[str, Any]) -> tuple[Path, tuple[str, ...]] | None:
    """The URDF file and locked joints of a scenario's robot, when it comes from one."""
    locked = tuple(robot.get("locked_joints", ()))
    if robot.get("kind") == "urdf":
        return Path(robot["path"]), locked
    if robot.get("kind") == "example_robot":
        from ..robots.pinocchio import example_urdf

        path, gripper = example_urdf(robot["name"])
        return path, gripper + locked
    return None


def _table(record: dict[str, Any]) -> str:
    """identified.md: each base parameter's estimates and relative standard deviation, and the held-out fit."""
    methods = list(record["base"])
    lines = [f"# Identified base parameters of {record['scenario']}", "",
             f"From {record['data']}: {record['fit_samples']} samples fitted, {record['holdout_samples']} held out; "
             f"condition number of W {record['condition_number']:.4g}; handed on: {record['estimate']}.", "",
             "| base parameter | " + " | ".join(methods) + " | WLS rel. std (%) |",
             "|---|" + "---|" * (len(methods) + 1)]
    for i, name in enumerate(record["base_names"]):
        values = " | ".join(f"{record['base'][m][i]:.6g}" for m in methods)
        lines.append(f"| {name} | {values} | {record['relative_std_percent'][i]:.3g} |")
    if record["holdout_rms"]:
        lines += ["", "Held-out torque RMS error per joint (N·m), against the torque's own RMS "
                  f"{fmt(record['holdout_tau_rms'])}:", "", "| estimate | RMS error |", "|---|---|"]
        lines += [f"| {k} | {fmt(v)} |" for k, v in record["holdout_rms"].items()]
    return "\n".join(lines) + "\n"


def _summary(record: dict[str, Any], source: str) -> str:
    std = np.asarray(record["relative_std_percent"])
    line = (f"{record['scenario']}: {len(record['base_names'])} base parameters from {source} "
            f"({record['fit_samples']} samples, {record['holdout_samples']} held out, cond W = "
            f"{record['condition_number']:.4g}); WLS relative std median {np.median(std):.3g} %, max {np.max(std):.3g} %")
    if record["holdout_rms"]:
        held = record["holdout_rms"]
        line += (f"; held-out torque RMS error {record['estimate']} {fmt(held[record['estimate']])} N·m (prior "
                 f"{fmt(held['prior'])})")
    if "base_error_relative" in record:
        line += (f"; against the run's true φ: ‖K(φ − φ̂)‖/‖Kφ‖ = "
                 f"{record['base_error_relative'][record['estimate']]:.3g} (prior "
                 f"{record['base_error_relative']['prior']:.3g})")
    eig = record["min_pseudo_inertia_eigenvalue"][record["estimate"]]
    return line + f"; smallest pseudo-inertia eigenvalue {eig:.3g}"
