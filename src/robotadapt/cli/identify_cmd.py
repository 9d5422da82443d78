"""`robotadapt identify DATA --robot SCENARIO`: base parameters from logged joint data, physically consistent, as a
φ̂(0) for adaptation (docs/identification.md)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..validation import ConfigError, require_extra
from .common import add_figure_arguments, figure_format, fmt


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify the base parameters from logged joint data (result.npz or CSV): "
                       "filtering, OLS/WLS, relative standard deviations, a physically consistent estimate")
    p.add_argument("data", metavar="DATA", help="a result.npz of `robotadapt run`, a CSV with columns t, q1…qn, "
                   "optional dq1…dqn, tau1…taun (SI units; jittered time stamps are resampled), or a ROS 2 bag (folder, "
                   ".db3 or .mcap; ROS 1 .bag) of sensor_msgs/msg/JointState, joints matched by name")
    p.add_argument("--robot", required=True, metavar="SCENARIO",
                   help="the scenario whose controller's model is identified (packaged name or TOML file)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a field of the robot's scenario (repeatable)")
    p.add_argument("--out", type=Path, help="folder for identified.json, identified.md, the URDF copy and the figures "
                   "(default: results/identify-SCENARIO)")
    p.add_argument("--cutoff", default="auto", metavar="HZ|auto|none",
                   help="zero-phase Butterworth low-pass (order 4) applied alike to every column of the regressor W and "
                   "to τ (parallel filtering). Default auto: 5 × the excitation's band — the trajectory's highest "
                   "frequency when DATA is a result.npz beside the scenario.toml of its run, else the frequency below "
                   "which 99 %% of q's spectral energy lies; 'none': no filter")
    p.add_argument("--window", type=int, default=9, metavar="N",
                   help="Savitzky–Golay window of the derivatives, odd, samples (default 9)")
    p.add_argument("--polyorder", type=int, default=6, metavar="N", help="Savitzky–Golay order (default 6)")
    p.add_argument("--trim", type=float, metavar="S",
                   help="seconds dropped at each end of each filtered part (default 3/cutoff, else 0)")
    p.add_argument("--decimate", default="auto", metavar="D|auto",
                   help="keep every D-th filtered sample of the fit (default auto: down to 2.5 × the cutoff, where the "
                   "filter's correlation of neighbouring samples is small and the Newey–West covariance accounts for "
                   "the rest)")
    p.add_argument("--holdout", type=float, default=0.25, metavar="F",
                   help="fraction of the log, at its end, held out (before any filtering) to test the torque prediction "
                   "(default 0.25)")
    p.add_argument("--validate", metavar="OTHER",
                   help="a second log (result.npz or CSV, read like DATA) on which each estimate's and the prior's "
                   "torque prediction is scored, per joint (validation_rms)")
    p.add_argument("--topic", metavar="TOPIC", help="the sensor_msgs/msg/JointState topic of a ROS bag that has "
                   "several (default: its only one)")
    p.add_argument("--max-gap", type=float, metavar="S", help="longest gap between time stamps bridged when "
                   "resampling a jittered log (default: 10 median sample periods)")
    p.add_argument("--divergence-weight", type=float, default=1.0, metavar="G",
                   help="γ of the log-det divergence that keeps the consistent estimate's bodies near the prior's where "
                   "the data do not see them (default 1: each body known to about ±100 %% before the data; 0: the ε "
                   "bound and a 1e-6 pull only)")
    p.add_argument("--estimate", default="consistent", choices=("consistent", "wls", "ols"),
                   help="which estimate identified.json hands on as phi (default consistent: J_i ⪰ ε𝟙, cvxpy)")
    p.add_argument("--epsilon", type=float, default=1e-8, metavar="E",
                   help="margin of the consistent estimate: every pseudo-inertia ⪰ E·𝟙 (default 1e-8; the Panda URDF's "
                   "own smallest eigenvalue is 8.6e-7)")
    p.add_argument("--prior", default="estimate", choices=("estimate", "nominal"),
                   help="φ₀, where the directions no data see stay and what the held-out prediction is compared with: "
                   "the scenario's initial estimate phi_hat0 (default) or the model's nominal (published) values")
    p.add_argument("--no-plots", action="store_true", help="skip the figures holdout.png and validation.png")
    add_figure_arguments(p)


def main(args: argparse.Namespace) -> int:
    from ..analysis.identification import Preprocessing, identify
    from ..analysis.joint_data import read
    from ..files import atomic_write, writable_dir
    from ..studies.scenarios import load

    output = figure_format(args)
    if args.estimate == "consistent":  # found before any work, not after the filtering
        require_extra("cvxpy", "identify", "--estimate", "the physically consistent estimate", "choose --estimate wls")
    pre = Preprocessing(_cutoff(args.cutoff), args.window, args.polyorder, args.trim, _decimate(args.decimate))
    scenario = load(args.robot, list(args.set))
    model = scenario.setup.controller.model
    names = getattr(model, "joint_names", None)
    data = read(args.data, model.n, joint_names=names, topic=args.topic, max_gap=args.max_gap)
    for note in data.notes:
        print(note)
    other = None
    if args.validate is not None:
        try:
            other = read(args.validate, model.n, joint_names=names, topic=args.topic, max_gap=args.max_gap)
        except ConfigError as exc:
            raise ConfigError("--validate", exc.reason) from None
    band = _trajectory_band(args.data) if pre.cutoff == "auto" else None
    if band is not None:
        pre = dataclasses.replace(pre, band=band[0], band_source=band[1])
    prior = getattr(scenario.setup.controller, "phi_hat0", None) if args.prior == "estimate" else None
    result = identify(model, data, pre, args.holdout, consistent=args.estimate == "consistent", epsilon=args.epsilon,
                      prior=prior, validation=other, divergence_weight=args.divergence_weight)
    record: dict[str, Any] = {"scenario": scenario.name, "data": str(args.data), "estimate": args.estimate,
                              "phi": result.standard[args.estimate].tolist(), **result.as_dict(),
                              "data_notes": list(data.notes)}
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
        from ..report.identification_figures import holdout_figure, validation_figure

        if result.holdout_t.size:
            holdout_figure(result, out / output.name("holdout"), scenario.name, output)
        if result.validation is not None:
            validation_figure(result, out / output.name("validation"), scenario.name, output)
    atomic_write(out / "identified.json", lambda f: json.dump(record, f, indent=2))
    for warning in result.warnings:
        print(f"robotadapt: warning: {warning}", file=sys.stderr)
    print(_summary(record, data.source))
    print(f"wrote {out}/ (start a scenario from it: phi_hat0 = {{file = \"{out / 'identified.json'}\"}})")
    return 0


def _cutoff(text: str) -> float | str | None:
    """--cutoff: a frequency in Hz, 'auto' or 'none'."""
    word = str(text).strip().lower()
    if word in ("auto", "none"):
        return None if word == "none" else "auto"
    try:
        return float(word)
    except ValueError:
        raise ConfigError("--cutoff", f"expected a frequency in Hz, 'auto' or 'none', got {text!r}") from None


def _decimate(text: str) -> int | str:
    """--decimate: a whole number ≥ 1 or 'auto'."""
    word = str(text).strip().lower()
    if word == "auto":
        return "auto"
    try:
        return int(word)
    except ValueError:
        raise ConfigError("--decimate", f"expected a whole number ≥ 1 or 'auto', got {text!r}") from None


def _trajectory_band(path: str) -> tuple[float, str] | None:
    """The highest frequency (Hz) of the trajectory of the run that wrote DATA, when DATA is a result.npz beside its
    run's scenario.toml and that trajectory is a sum of sines (`fourier`, as `robotadapt excite` writes it, `sinusoid`,
    `sum_of_sines`): the excitation's band, known rather than estimated. None otherwise."""
    from ..studies.scenarios import load
    from ..trajectories import SumOfSines

    data = Path(path)
    toml = data.with_name("scenario.toml")
    if data.suffix != ".npz" or not toml.is_file():
        return None
    try:
        scenario = load(str(toml))
    except ConfigError:
        return None
    trajectory = scenario.setup.trajectory
    if not isinstance(trajectory, SumOfSines):
        return None
    amplitude = np.asarray(trajectory.amplitude)
    omega = np.abs(np.broadcast_to(np.asarray(trajectory.omega).reshape(amplitude.shape[0], -1), amplitude.shape))
    moving = omega[amplitude != 0]
    if moving.size == 0 or not np.max(moving) > 0:
        return None
    kind = scenario.data.get("trajectory", {}).get("kind", "sum-of-sines")
    return float(np.max(moving)) / (2 * np.pi), f"the highest frequency of the {kind} trajectory in {toml}"


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
    """identified.md: the preprocessing, each base parameter's estimates and relative standard deviation, and the
    torque predicted on the held-out part and on the validation log."""
    methods = list(record["base"])
    pre = record["preprocessing"]
    cov = record.get("covariance", {})
    lines = [f"# Identified base parameters of {record['scenario']}", "",
             f"From {record['data']}: {record['fit_samples']} samples fitted, {record['holdout_samples']} held out; "
             f"condition number of W {record['condition_number']:.4g}; handed on: {record['estimate']}.", "",
             f"Preprocessing: {pre['description']}. Standard deviations: Newey–West covariance over "
             f"{cov.get('lags', 0)} lags of the kept samples.", ""]
    lines += [f"Warning: {w}" for w in record.get("warnings", [])] + ([""] if record.get("warnings") else [])
    lines += ["| base parameter | " + " | ".join(methods) + " | WLS rel. std (%) |",
              "|---|" + "---|" * (len(methods) + 1)]
    for i, name in enumerate(record["base_names"]):
        values = " | ".join(f"{record['base'][m][i]:.6g}" for m in methods)
        lines.append(f"| {name} | {values} | {record['relative_std_percent'][i]:.3g} |")
    for key, what, rms in (("holdout_rms", "Held-out torque (the last part of DATA, filtered on its own)",
                            "holdout_tau_rms"),
                           ("validation_rms", f"Torque of the validation log {record.get('validation', '')}",
                            "validation_tau_rms")):
        if record.get(key):
            lines += ["", f"{what}: RMS prediction error per joint (N·m or N), against the torque's own RMS "
                      f"{fmt(record[rms])}:", "", "| model | RMS error |", "|---|---|"]
            lines += [f"| {k} | {fmt(v)} |" for k, v in record[key].items()]
    from ..analysis.consistent import bodies_table

    table = bodies_table(record["phi"], record["prior"], record["param_names"])
    if table:
        lines += ["", f"Bodies of the handed-on estimate ({record['estimate']}) beside the prior's:", "", *table]
    return "\n".join(lines) + "\n"


def _summary(record: dict[str, Any], source: str) -> str:
    std = np.asarray(record["relative_std_percent"])
    pre = record["preprocessing"]
    cut = "no low-pass" if pre["cutoff"] is None else f"low-pass {pre['cutoff']:.3g} Hz ({pre['cutoff_source']})"
    line = (f"{record['scenario']}: {len(record['base_names'])} base parameters from {source} "
            f"({cut}, 1 sample in {pre['decimate']} kept: {record['fit_samples']} samples, "
            f"{record['holdout_samples']} held out, cond W = {record['condition_number']:.4g}); WLS relative std "
            f"median {np.median(std):.3g} %, max {np.max(std):.3g} %")
    for key, what in (("holdout_rms", "held-out"), ("validation_rms", "validation")):
        if record.get(key):
            held = record[key]
            line += (f"; {what} torque RMS error {record['estimate']} {fmt(held[record['estimate']])} N·m (prior "
                     f"{fmt(held['prior'])})")
    if "base_error_relative" in record:
        line += (f"; against the run's true φ: ‖K(φ − φ̂)‖/‖Kφ‖ = "
                 f"{record['base_error_relative'][record['estimate']]:.3g} (prior "
                 f"{record['base_error_relative']['prior']:.3g})")
    eig = record["min_pseudo_inertia_eigenvalue"][record["estimate"]]
    return line + f"; smallest pseudo-inertia eigenvalue {eig:.3g}"
