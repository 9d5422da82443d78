"""Identification on the Panda, closed into adaptation (issue 27, docs/identification.md).

    python examples/identification_study.py [--out results/identification]

1. **Excitation**: `robotadapt excite panda-slotine-li --harmonics 5 --period 10`, once per objective (cond, logdet),
   within the URDF's position, velocity and torque limits; cond W against the packaged sum of sines.
2. **Adaptation driven by it**: Slotine–Li as packaged (20 s, φ̂(0) = 0.7 φ) on the packaged trajectory and on the
   cond-optimal one, with the packaged Γ = 20, a Γ scaled to each parameter (`{scale = 20, eps = 0.01}`) and the natural
   law (γ = 0.01): the base-parameter error at 20 s.
3. **Noise**: τ = Y φ on each trajectory (the URDF's φ), Gaussian noise of σ_τ on every torque and σ_q on every position,
   identified by `identify` (WLS and the consistent SDP estimate): the base-parameter error against the noise level.
4. **The loop closed**, every step a `robotadapt` command: `run` the cond-optimal scenario on a "real" arm — the URDF
   plus unmodelled joint friction (viscous and Coulomb, [P]), encoder quantisation and position noise, sampled-data
   control at 1 kHz (panda-natural's servo gains, `GAINS`), the estimate held at the URDF's (`adaptation = "none"`: an
   identification experiment runs a fixed controller), every sample logged; `identify` the log with the scenario's
   friction-free model and with friction columns (`--set robot.viscous=true --set robot.coulomb=true`); then `run
   panda-slotine-li` (its sum of sines, `GAINS`) on the same arm picking up a 1.5 kg payload at t = 10 s, from the
   identified estimate (`phi_hat0 = {file = …}`) and from the packaged 30 % low one, under each of `LOOP_LAWS`: the
   packaged Γ = 20 with the friction-free model, then with the identified friction columns in the controller's model
   too, the packaged Γ, a Γ scaled to each parameter and the natural law.

Writes `study.json` and `study.md` (the tables docs/identification.md quotes) into the output folder.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np

from robotadapt.analysis.identification import Preprocessing, identify
from robotadapt.analysis.joint_data import JointData
from robotadapt.cli import main
from robotadapt.robots.identifiability import base_parameters
from robotadapt.studies.scenarios import load
from robotadapt.studies.scenarios.loader import assignment

SCENARIO = "panda-slotine-li"
VISCOUS = [0.6, 0.6, 0.6, 0.6, 0.2, 0.2, 0.2]  # [P] N·m·s/rad, the order Gaz et al. (RA-L 2019) fit on a real Panda
COULOMB = [0.5, 0.5, 0.5, 0.5, 0.2, 0.2, 0.2]  # [P] N·m
ENCODER = 2 * np.pi / 2**18  # [P] rad, an 18-bit encoder
NOISE_Q = 2e-5  # [P] rad
PAYLOAD = ["plant.payload=1.5", "plant.payload_offset=[0.0, 0.0, 0.1]", "plant.payload_time=10.0"]  # [P]
# panda-natural's servo gains: panda-slotine-li's (Λ = 10, K_v = 50 on joints 1–4) sampled at 1 kHz go unstable where
# joints 1 and 3 align (q_2 ≈ 0: the mode that turns them against each other has little inertia), which the exciting
# trajectory crosses
GAINS = ["controller.Lam=5.0", "controller.Kv=[10.0, 10.0, 10.0, 10.0, 2.0, 2.0, 0.5]"]
LAWS = {"Γ = 20 (packaged)": [], "Γ = {scale = 20, eps = 0.01}": ["controller.Gamma={scale = 20.0, eps = 0.01}"],
        "natural, γ = 0.01": ['controller.adaptation="natural"', "controller.gamma=0.01"]}
FRICTION = ["robot.viscous=true", "robot.coulomb=true"]  # the controller's model with the identified friction columns
LOOP_LAWS = {"Γ = 20, friction-free model": [], "Γ = 20": FRICTION,
             "Γ = {scale = 5, eps = 0.01}": [*FRICTION, "controller.Gamma={scale = 5.0, eps = 0.01}"],
             "natural, γ = 0.1": [*FRICTION, 'controller.adaptation="natural"', "controller.gamma=0.1"]}
NOISE_LEVELS = [(0.0, 0.0), (0.01, 0.0), (0.1, 0.0), (1.0, 0.0), (0.1, 1e-5), (0.1, 1e-4)]  # (σ_τ N·m, σ_q rad)
COMPARED_NOISE = (0.1, 1e-5)
CUTOFF = 5.0  # Hz, 10 × the optimised trajectory's highest harmonic (0.5 Hz)


def command(*args: object) -> None:
    if main([str(a) for a in args]) != 0:
        raise SystemExit(f"robotadapt {' '.join(map(str, args))} failed")


def sets(assignments: list[str]) -> list[str]:
    return sum((["--set", a] for a in assignments), [])


def real_arm(phi: np.ndarray) -> list[str]:
    """--set assignments of the "real" arm: the URDF with friction the controller's model lacks, an encoder, noise."""
    robot = {"kind": "example_robot", "name": "panda", "viscous": True, "coulomb": True}
    return [assignment("plant.robot", robot), assignment("plant.phi", [*map(float, phi), *VISCOUS, *COULOMB]),
            f"plant.encoder_resolution={ENCODER!r}", f"plant.noise_q={NOISE_Q!r}", "simulation.control_period=1e-3",
            *GAINS]


def base_error(phi_hat: np.ndarray, phi: np.ndarray, K: np.ndarray) -> float:
    return float(np.linalg.norm(K @ (phi_hat - phi)) / np.linalg.norm(K @ phi))


def excitation(out: Path) -> dict:
    """Part 1."""
    rows = {}
    for objective in ("cond", "logdet"):
        folder = out / f"excite-{objective}"
        command("excite", SCENARIO, "--harmonics", 5, "--period", 10, "--objective", objective, "--out", folder)
        r = json.loads((folder / "excite.json").read_text())
        rows[objective] = {"folder": str(folder), "cond": r["cond_after"], "log_det": r["log_det"],
                           "cond_packaged": r["cond_before"], "log_det_packaged": r["before"]["log_det"],
                           "worst_ratio_packaged": r["before"]["worst_ratio"],
                           "worst_ratio": r["worst_ratio"], "seconds": r["seconds"]}
    return rows


def adaptation(out: Path, optimised: Path, phi: np.ndarray, K: np.ndarray) -> dict:
    """Part 2."""
    rows = {}
    for label, law in LAWS.items():
        for trajectory, scenario in (("packaged", SCENARIO), ("optimised", str(optimised))):
            folder = out / "adapt" / f"{trajectory}-{len(rows)}"
            command("run", scenario, *sets(law), "--t-final", 20, "--no-plots", "--out", folder)
            rows[f"{label} | {trajectory}"] = base_error(np.load(folder / "result.npz")["phi_hat"][-1], phi, K)
    return rows


def noise(trajectories: dict[str, Path | str], phi: np.ndarray, K: np.ndarray) -> list[dict]:
    """Part 3: 20 s at 500 Hz, τ = Y φ with noise, identified: unfiltered where only τ is noisy (the least squares
    average white noise out), else with the `CUTOFF` low-pass on q and τ alike (positions are differentiated twice)."""
    rows = []
    for name, scenario in trajectories.items():
        setup = load(str(scenario)).setup
        model = setup.controller.model
        t = np.arange(0.0, 20.0, 2e-3)
        ref = setup.trajectory(t)
        tau0 = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ phi
        levels = NOISE_LEVELS if name == "cond-optimal" else [COMPARED_NOISE]
        for k, (s_tau, s_q) in enumerate(levels):
            rng = np.random.default_rng(k)
            data = JointData(t, ref.q_des + s_q * rng.standard_normal(ref.q_des.shape), ref.dq_des,
                             tau0 + s_tau * rng.standard_normal(tau0.shape), f"{name}, noise {k}")
            cutoff = None if s_q == 0 else CUTOFF
            res = identify(model, data, Preprocessing(cutoff=cutoff), prior=0.7 * phi)
            rows.append({"trajectory": name, "sigma_tau": s_tau, "sigma_q": s_q, "cutoff": cutoff,
                         "cond": res.condition_number,
                         "wls": base_error(res.standard["wls"], phi, K),
                         "consistent": base_error(res.standard["consistent"], phi, K),
                         "median_relative_std_percent": float(np.median(res.relative_std))})
    return rows


def closed_loop(out: Path, optimised: Path, phi: np.ndarray, K: np.ndarray) -> dict:
    """Part 4."""
    log = out / "log"
    experiment = [*real_arm(phi), 'controller.adaptation="none"', "controller.phi_hat0={scale = 1.0}",
                  "simulation.log_every=1"]
    command("run", optimised, *sets(experiment), "--t-final", 30, "--no-plots", "--out", log)
    ident = {}
    for label, extra in (("friction-free model", []), ("friction columns", FRICTION)):
        folder = out / ("identify-friction" if extra else "identify")
        command("identify", log / "result.npz", "--robot", SCENARIO, *sets(extra), "--cutoff", 10, "--out", folder)
        r = json.loads((folder / "identified.json").read_text())
        friction = {n: v for n, v in zip(r["param_names"], r["phi"], strict=True) if n.startswith(("fv", "fc"))}
        ident[label] = {"folder": str(folder), "base_error": base_error(np.array(r["phi"][:70]), phi, K),
                        "holdout_rms": r["holdout_rms"][r["estimate"]], "prior_rms": r["holdout_rms"]["prior"],
                        "median_relative_std_percent": float(np.median(r["relative_std_percent"])),
                        "friction": friction}
    identified = out / "identify-friction" / "identified.json"
    starts = {"identified": assignment("controller.phi_hat0", {"file": str(identified)}),
              "30 % low": "controller.phi_hat0={scale = 0.7}"}
    runs = {}
    after = np.asarray(load(SCENARIO, [*real_arm(phi), *PAYLOAD]).setup.plant.phi_at(20.0))[:70]  # payload on link 7
    for (law, settings), (label, start) in itertools.product(LOOP_LAWS.items(), starts.items()):
        folder = out / f"payload-{len(runs)}"
        command("run", SCENARIO, *sets([*real_arm(phi), *PAYLOAD, *settings, start]), "--no-plots", "--out", folder)
        res = np.load(folder / "result.npz")
        t, e, phi_hat = res["t"], res["q_des"] - res["q"], res["phi_hat"][:, :70]
        before = t < 10.0
        runs[f"{law} | {label}"] = {
            "base_error_at_0": base_error(phi_hat[0], phi, K),
            "base_error_at_10": base_error(phi_hat[before][-1], phi, K),
            "base_error_at_20": base_error(phi_hat[-1], after, K),
            "rms_deg_0_10": float(np.degrees(np.sqrt(np.mean(e[before] ** 2)))),
            "rms_deg_10_20": float(np.degrees(np.sqrt(np.mean(e[~before] ** 2)))),
            "max_deg_first_second": float(np.degrees(np.max(np.abs(e[t < 1.0])))),
        }
    return {"identify": ident, "payload": runs}


def markdown(study: dict) -> str:
    ex = study["excitation"]

    def shares(ratios: dict) -> str:
        return ", ".join(f"{kind} {r:.3g}" for kind, r in ratios.items() if r is not None)

    lines = ["| trajectory | cond W | log det WᵀW | largest share of a bound used |", "|---|---|---|---|",
             f"| packaged sum of sines (20 s) | {ex['cond']['cond_packaged']:.4g} | {ex['cond']['log_det_packaged']:.1f} "
             f"| {shares(ex['cond']['worst_ratio_packaged'])} |"]
    lines += [f"| {k}-optimal (5 harmonics, 10 s) | {v['cond']:.4g} | {v['log_det']:.1f} | {shares(v['worst_ratio'])} |"
              for k, v in ex.items()]
    lines += ["", "| Slotine–Li law | base error at 20 s, packaged trajectory | optimised trajectory |", "|---|---|---|"]
    adapt = study["adaptation"]
    for label in LAWS:
        lines.append(f"| {label} | {adapt[f'{label} | packaged']:.3g} | {adapt[f'{label} | optimised']:.3g} |")
    lines += ["", "| trajectory | σ_τ (N·m) | σ_q (rad) | low-pass | cond W | WLS base error | consistent base error | "
              "median rel. std (%) |", "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['trajectory']} | {r['sigma_tau']:g} | {r['sigma_q']:g} | "
              f"{'none' if r['cutoff'] is None else str(r['cutoff']) + ' Hz'} | {r['cond']:.4g} | {r['wls']:.3g} | "
              f"{r['consistent']:.3g} | {r['median_relative_std_percent']:.3g} |" for r in study["noise"]]
    loop = study["closed_loop"]
    lines += ["", "| identified with | base error | median rel. std (%) | held-out torque RMS error (N·m) | prior's |",
              "|---|---|---|---|---|"]
    lines += [f"| {k} | {v['base_error']:.3g} | {v['median_relative_std_percent']:.3g} | "
              f"{', '.join(f'{x:.3g}' for x in v['holdout_rms'])} | {', '.join(f'{x:.3g}' for x in v['prior_rms'])} |"
              for k, v in loop["identify"].items()]
    lines += ["", "| Slotine–Li law | from | base error t = 0 | t = 10 s | t = 20 s (payload) | RMS e 0–10 s (°) | "
              "RMS e 10–20 s (°) | max e first second (°) |", "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {k} | {v['base_error_at_0']:.3g} | {v['base_error_at_10']:.3g} | {v['base_error_at_20']:.3g} | "
              f"{v['rms_deg_0_10']:.3g} | {v['rms_deg_10_20']:.3g} | {v['max_deg_first_second']:.3g} |"
              for k, v in loop["payload"].items()]
    return "\n".join(lines) + "\n"


def run(out: Path) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    clock = time.perf_counter()
    model = load(SCENARIO).setup.controller.model
    phi, K = np.asarray(model.default_phi), base_parameters(model).K
    study: dict = {"excitation": excitation(out)}
    optimised = out / "excite-cond" / "scenario.toml"
    study["adaptation"] = adaptation(out, optimised, phi, K)
    study["noise"] = noise({"cond-optimal": optimised, "logdet-optimal": out / "excite-logdet" / "scenario.toml",
                            "packaged sum of sines": SCENARIO}, phi, K)
    study["closed_loop"] = closed_loop(out, optimised, phi, K)
    study["seconds"] = time.perf_counter() - clock
    (out / "study.json").write_text(json.dumps(study, indent=2))
    (out / "study.md").write_text(markdown(study))
    return study


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/identification"))
    study = run(parser.parse_args().out)
    print(markdown(study))
    print(f"{study['seconds']:.0f} s")
