"""`robotadapt compare` on an arm other than the book's (robotadapt.studies.compare, module docstring): the scenario's
own law is the reference, the other laws' gains follow the arm by the documented rule, every law starts from the
scenario's φ̂(0), refusals are one short line, the repetitive law keeps the scenario's step (its delay line rounded,
checked against Table 7.2.2 written out), and a run that stopped early reports no µs/step."""

from __future__ import annotations

import contextlib
import io
import json
import re

import numpy as np
import pytest
import tomli_w

from robotadapt.cli import main
from robotadapt.controllers.repetitive import Repetitive
from robotadapt.plant.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim.integrators import RK4
from robotadapt.sim.simulation import simulate
from robotadapt.studies.compare import brief, compare, contenders, lineup
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid
from robotadapt.validation import ConfigError

LENGTH, MASSES = 1.0, [2.0, 1.5, 1.0]
KV, LAM, GAMMA = 20.0, 5.0, 5.0  # the scenario's Slotine–Li: s = λ_min(K_v) / 10 of Example 6.3.1 = 2
PLANAR = {
    "description": "a newcomer's 3-link planar arm under Slotine–Li",
    "robot": {"kind": "planar", "n_links": 3, "lengths": LENGTH, "masses": MASSES, "model": "sympy"},
    "plant": {"q0": [0.0, 0.0, 0.0], "dq0": [0.0, 0.0, 0.0]},
    "trajectory": {"kind": "sinusoid", "amplitude": 0.5, "omega": 1.0},
    "controller": {"kind": "slotine_li", "Lam": LAM, "Kv": KV, "Gamma": GAMMA, "phi_hat0": {"scale": 0.7}},
    "simulation": {"t_final": 0.5, "dt": 1e-3, "method": "rk4"},
}
NUMBER_ARRAY = re.compile(r"\[\s*[-+\d.]")  # the start of an array's repr: [0.1 0.1 …], [[10. …


def _scenario(tmp_path, name="planar3.toml", controller=None, **sections):
    """`PLANAR` written to `tmp_path`: `controller` in place of its own, the keys of `sections` added to theirs."""
    pytest.importorskip("sympy")  # the planar arm's sympy model: 20× faster in numpy than the tree, for a short test
    data = {k: dict(v) if isinstance(v, dict) else v for k, v in PLANAR.items()}
    data["controller"] = controller or data["controller"]
    for section, values in sections.items():
        data[section].update(values)
    path = tmp_path / name
    path.write_text(tomli_w.dumps(data))
    return path


@pytest.fixture
def planar(tmp_path):
    return load(_scenario(tmp_path))


def _by_name(entries):
    return {e.name: e for e in entries}


def test_the_scenarios_own_law_is_the_reference_with_its_own_gains(planar):
    entries, _ = lineup(planar)
    refs = [e for e in entries if e.reference]
    assert [e.name for e in refs] == ["slotine_li"]
    assert refs[0].scenario.data["controller"] == PLANAR["controller"]  # exactly as the scenario gives it
    assert "the reference" in refs[0].source


def test_the_other_laws_gains_follow_the_arm_by_the_documented_rule(planar):
    """s = λ_min(K_v) / 10 = 2: a gain of the same part in the scenario's law is taken (Λ, K_v, Γ), a torque or
    adaptation gain the book's × s, a rate and computed torque's K_p, K_v the book's."""
    s = KV / 10.0
    ctrl = {name: e.scenario.data["controller"] for name, e in _by_name(lineup(planar)[0]).items()}
    assert {k: ctrl["dcal"][k] for k in ("Kv", "Kp", "Ka", "Gamma")} == {"Kv": 50 * s, "Kp": 50 * s, "Ka": 50 * s,
                                                                         "Gamma": GAMMA}
    assert {k: ctrl["repetitive"][k] for k in ("Kv", "Kp", "Ka", "kL")} == dict.fromkeys(("Kv", "Kp", "Ka", "kL"), 50 * s)
    assert (ctrl["pd"]["Kv"], ctrl["pd"]["Kp"]) == (KV, KV * LAM)  # K_p = K_v Λ of the scenario's
    assert {k: ctrl["composite"][k] for k in ("Lam", "Kv", "a", "P0")} == {"Lam": LAM, "Kv": KV, "a": 1.0, "P0": 10 * s}
    assert (ctrl["passivity_pi"]["law"]["K_I"], ctrl["passivity_pi"]["law"]["F_p"]) == (20 * s, 2 * s)
    assert ctrl["passivity_pi"]["servo"] == {"kind": "pid", "Lam": LAM, "Psi": 1.0}
    assert ctrl["sigma"]["law"]["Gamma"] == GAMMA and ctrl["sigma"]["Kv"] == KV
    assert ctrl["sign_robust"]["kd"] == pytest.approx(2.2 * s)
    assert (ctrl["computed_torque"]["Kp"], ctrl["computed_torque"]["Kv"]) == (4.0, 4.0)  # act through M̂
    source = _by_name(lineup(planar)[0])["dcal"].source
    assert "scaled by s = 2 (the scenario's λ_min(K_v) = 20 over Example 6.3.1's 10): Kv, Kp, Ka" in source
    assert "from the scenario: Gamma" in source


def test_without_a_K_v_on_r_the_scale_is_the_arms_inertia_over_the_book_arms(tmp_path):
    """The scenario's law is computed torque (K_p, K_v act through M̂): s = λ_max M(q0) / λ_max M_book(0), M of point
    masses at the link ends written out, M_ij(0) = Σ_{k ≥ i, j} m_k (x_k − x_i)(x_k − x_j) along the stretched arm."""
    path = _scenario(tmp_path, controller={"kind": "computed_torque", "Kp": 9.0, "Kv": 6.0, "phi_hat0": {"scale": 0.7}})
    joints, masses = LENGTH * np.arange(3), LENGTH * np.arange(1, 4)
    M = np.array([[sum(MASSES[k] * (masses[k] - joints[i]) * (masses[k] - joints[j]) for k in range(max(i, j), 3))
                   for j in range(3)] for i in range(3)])
    book = np.array([[0.8 + 2.3 + 2.3 + 2 * 2.3, 2.3 + 2.3], [2.3 + 2.3, 2.3]])  # (m1 + m2) l1² + m2 l2² + 2 m2 l1 l2, …
    s = np.linalg.eigvalsh(M).max() / np.linalg.eigvalsh(book).max()
    ctrl = _by_name(lineup(load(path))[0])["dcal"].scenario.data["controller"]
    assert ctrl["Kv"] == pytest.approx(50 * s, rel=1e-12) and ctrl["Gamma"] == pytest.approx(20 * s, rel=1e-12)


def test_on_the_book_arm_made_twice_as_heavy_every_law_but_composite_repeats_the_books_error():
    """The rule's invariance (module docstring): M, V_m, G twice the book arm's (φ = 2 φ_book) and the scenario's K_v,
    Γ, φ̂(0) twice Example 6.3.1's; every law then gives Example 6.3.1's e(t) with twice its torque (adaptive computed
    torque with Γ × s², its box × s), but composite adaptation, whose one P weighs a torque error and r alike."""
    book = load("example-6.3.1", ["simulation.t_final=0.5", "controller.phi_hat0=[0.85, 2.2]"])
    heavy = load("example-6.3.1", ["simulation.t_final=0.5", "plant.phi=[1.6, 4.6]", "controller.Kv=20.0",
                                   "controller.Gamma=40.0", "controller.phi_hat0=[1.7, 4.4]"])
    rows, heavy_rows = compare(book)[0], compare(heavy)[0]
    assert [r.entry.name for r in rows] == [r.entry.name for r in heavy_rows] == list(contenders("joint"))
    for a, b in zip(rows, heavy_rows, strict=True):
        same = np.allclose(b.result.e, a.result.e, rtol=1e-9, atol=1e-12)
        assert same == (a.entry.name != "composite"), a.entry.name
        if same:
            np.testing.assert_allclose(b.result.tau, 2 * a.result.tau, rtol=1e-9, atol=1e-9, err_msg=a.entry.name)


def test_every_law_starts_from_the_scenarios_estimate_or_says_why_not(planar):
    phi_hat0 = planar.setup.controller.phi_hat0  # 0.7 × the true φ
    entries, skipped = lineup(planar)
    nominal = planar.setup.controller.model.default_phi  # the fixed-estimate baselines hold the nominal model
    for e in entries:
        got = getattr(e.scenario.setup.controller, "phi_hat0", None)
        if got is not None:
            want = nominal if e.name in ("pd_gravity", "computed_torque") else phi_hat0
            np.testing.assert_array_equal(got, want, err_msg=e.name)
    assert "adaptive_computed_torque" in skipped and "true parameters outside" in skipped["adaptive_computed_torque"]
    # the book's arm, φ̂(0) = 0: adaptive computed torque projected into its box; the baselines hold the true φ (the
    # arm has no nominal values), so computed torque runs (its M̂ is M)
    book = load("example-6.3.1")
    entries, skipped = lineup(book)
    acr = _by_name(entries)["adaptive_computed_torque"]
    np.testing.assert_array_equal(acr.scenario.setup.controller.phi_hat0, [0.1, 0.1])
    assert "2 of 2 entries projected into the box" in acr.note
    assert "computed_torque" not in skipped
    for e in entries:
        if e.name in ("pd_gravity", "computed_torque"):
            np.testing.assert_array_equal(e.scenario.setup.controller.phi_hat0, book.setup.plant.phi, err_msg=e.name)
        elif e.name != "adaptive_computed_torque" and hasattr(e.scenario.setup.controller, "phi_hat0"):
            np.testing.assert_array_equal(e.scenario.setup.controller.phi_hat0, [0.0, 0.0], err_msg=e.name)


def test_skipped_reasons_are_one_short_line_without_array_dumps(planar):
    _, skipped = lineup(planar)
    assert skipped
    for reason in skipped.values():
        assert len(reason) <= 160 and "\n" not in reason and not NUMBER_ARRAY.search(reason), reason
    long = ConfigError("controller.phi_hat0", f"must lie in the box = [{np.full(30, 0.1)}, {np.full(30, 10.0)}]")
    assert brief(long) == "controller.phi_hat0: must lie in the box = …"
    assert len(brief(ConfigError("controller", "x" * 400))) == 160


def test_the_repetitive_law_runs_on_the_scenarios_step_and_control_period(tmp_path):
    """Sampled data, Ts = 2 ms (T/Ts = 3141.6): the law keeps Ts and the plant's step, its delay line N = 3142."""
    base = load(_scenario(tmp_path, simulation={"control_period": 2e-3}))
    (row,), skipped = compare(base, ["repetitive"])
    integrator = row.entry.scenario.setup.integrator
    assert (integrator.control_period, integrator.dt) == (base.setup.integrator.control_period, base.setup.integrator.dt)
    assert row.result.ok and not skipped
    assert "round(T/Ts) = 3142 steps" in row.entry.note
    np.testing.assert_allclose(np.diff(row.result.t), 2e-3, rtol=1e-9)


def test_a_rounded_delay_line_is_table_7_2_2_written_out():
    """`rounded_delay`: T = 1 s, dt = 3 ms (T/dt = 333.3): (7.2.31)–(7.2.32) with a ring of N = round(T/dt) = 333
    samples, read (held) and written at every step, the torque at every RK4 stage with the held value, equals the
    simulator's run to round-off over three periods; without the flag the step is refused."""
    arm, phi, kv, kp, ka, kl, dt, n_ring = TwoLinkArm(), np.array([0.8, 2.3]), 50.0, 40.0, 30.0, 20.0, 3e-3, 333
    traj = sinusoid(2, omega=2 * np.pi)
    law = Repetitive(arm, Kv=kv, Kp=kp, Ka=ka, kL=kl)
    with pytest.raises(ConfigError, match="simulation.dt"):
        law.prepare(traj, dt, 3.0)
    res = simulate(Plant(arm, phi), Repetitive(arm, Kv=kv, Kp=kp, Ka=ka, kL=kl, rounded_delay=True), traj, t_final=3.0,
                   integrator=RK4(dt, "numpy"))

    def torque(t, q, dq, held):
        ref = traj(t)
        e, de = ref.q_des - q, ref.dq_des - dq
        r = de + e
        return held + kl * r + kv * r + kp * e + ka * (e @ e) * r, r

    def f(t, s, held):
        q, dq = s[:2], s[2:]
        tau = torque(t, q, dq, held)[0]
        ddq = np.linalg.solve(arm.mass_matrix(q, phi), tau - arm.coriolis_matrix(q, dq, phi) @ dq - arm.gravity(q, phi))
        return np.concatenate([dq, ddq])

    ring, s, qs, helds = np.zeros((n_ring, 2)), np.zeros(4), [], []
    for k in range(round(3.0 / dt)):
        t, held = k * dt, ring[k % n_ring].copy()
        ring[k % n_ring] = held + kl * torque(t, s[:2], s[2:], held)[1]
        qs.append(s[:2])
        helds.append(held)
        k1 = f(t, s, held)
        k2 = f(t + dt / 2, s + dt / 2 * k1, held)
        k3 = f(t + dt / 2, s + dt / 2 * k2, held)
        k4 = f(t + dt, s + dt * k3, held)
        s = s + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert res.ok and len(res.t) == len(qs) + 1
    np.testing.assert_allclose(res.q[:-1], qs, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.x[:-1, :2], helds, rtol=1e-10, atol=1e-12)
    assert np.abs(res.x[n_ring:, :2]).max() > 1.0  # learnt after the first period: the test reads the delay


def test_a_run_that_stopped_early_reports_no_us_per_step(tmp_path):
    base = load(_scenario(tmp_path, simulation={"max_state": 0.05}))
    (row,), _ = compare(base, ["pd"])
    assert not row.result.ok and row.result.t[-1] < base.setup.t_final
    assert row.metrics["us_per_step"] is None
    (row,), _ = compare(load(_scenario(tmp_path, "ok.toml")), ["pd"])
    assert row.result.ok and row.metrics["us_per_step"] > 0


def test_the_cli_compares_on_the_planar_arm_with_short_refusals(tmp_path):
    """Through `robotadapt compare`: the reference and the scaled gains in comparison.json, and a law that does not
    apply refused in one short line."""
    path = _scenario(tmp_path)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["compare", str(path), "--controllers", "slotine_li,dcal", "--out", str(tmp_path / "cmp")])
    assert code == 0, err.getvalue()
    rows = {r["controller"]: r for r in json.loads((tmp_path / "cmp" / "comparison.json").read_text())["rows"]}
    assert rows["slotine_li"]["reference"] and not rows["dcal"]["reference"]
    assert "Kv = 100" in rows["dcal"]["settings"] and "scaled by s = 2" in rows["dcal"]["source"]
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["compare", str(path), "--controllers", "adaptive_computed_torque", "--out", str(tmp_path / "x")])
    (line,) = err.getvalue().splitlines()
    assert code == 2 and "adaptive_computed_torque does not apply here" in line and "true parameters outside" in line
    assert len(line) < 250 and not NUMBER_ARRAY.search(line), line


def test_the_report_draws_a_run_that_stopped_at_its_first_step(tmp_path):
    """A law that diverges at once has no sample a log axis can draw: the report still draws the others, and marks
    the scenario's own law, not Slotine–Li by name, as the reference."""
    from robotadapt.report.html import write_comparison

    base = load(_scenario(tmp_path, simulation={"max_state": 1e-9}))
    rows, skipped = compare(base, ["pd", "slotine_li"])
    assert all(r.result.t[-1] == 0.0 for r in rows)
    write_comparison(base, rows, skipped, tmp_path / "report")
    assert (tmp_path / "report" / "laws.png").stat().st_size > 0
    assert json.loads((tmp_path / "report" / "comparison.json").read_text())["rows"][1]["reference"]


def test_a_fair_comparison_does_not_tune_a_learning_law_within_one_period(tmp_path):
    """t_final ≤ T: û_d(t − T) = 0 throughout, nothing is learnt, so the fair comparison runs the repetitive law with
    the lineup's gains and says why (the Panda's trajectory repeats only after 20π s)."""
    out = tmp_path / "fair"
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["compare", "example-6.3.1", "--t-final", "0.5", "--fair", "--max-torque", "150",
                     "--controllers", "repetitive", "--out", str(out)])
    assert code == 0
    (row,) = json.loads((out / "comparison.json").read_text())["rows"]
    assert row["tuned_gains"] is None and row["tune_runs"] == 0
    assert ("not tuned (simulation.t_final: 0.5 s is within one period T = 6.283 s: the law learns nothing"
            in row["note"]), row["note"]


def test_a_tuned_row_over_the_budget_says_why_measured(tmp_path):
    """A budget below gravity's torque: the row is tuned, stays over, and its note gives the peak after its runs and
    the gain that moves the peak most, with the elasticity tune.json holds."""
    out = tmp_path / "fair"
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["compare", "example-6.3.1", "--t-final", "0.3", "--fair", "--max-torque", "1", "--tune-runs", "3",
                     "--controllers", "slotine_li", "--out", str(out)])
    assert code == 0
    (row,) = json.loads((out / "comparison.json").read_text())["rows"]
    assert row["within_budget"] is False and row["tuned_gains"] is not None
    match = re.search(r"over the budget after (\d+) runs: max \|τ\| ([\d.]+); the peak moves most with (controller\.\w+) "
                      r"\(∂ln max\|τ\|/∂ln gain = (-?[\d.e+-]+)\)", row["note"])
    assert match, row["note"]
    assert int(match[1]) <= 3 and float(match[2]) == pytest.approx(row["peak_torque"], rel=1e-3)
    assert match[3] in row["tuned_gains"]


def test_the_laws_of_a_fair_comparison_tune_alike_on_worker_processes():
    """`fair` tunes its laws on spawned processes, one a law: each law's tuned gains and search are those of its tuning
    in this process, and a law refused there comes back as the ConfigError it raised (its field and reason)."""
    from robotadapt.studies.compare import _tunings

    base = load("example-6.3.1", ["simulation.t_final=0.3", 'simulation.backend="jax"'])
    entries, _ = lineup(base, ["slotine_li", "repetitive"])
    scenarios, budget = [e.scenario for e in entries], ("rms_error", 150.0, 3)
    here, apart = _tunings(scenarios, budget, 1), _tunings(scenarios, budget, 2)
    (fields, (summary, theta)), (_, refused) = here
    assert fields == ["controller.Lam", "controller.Kv", "controller.Gamma"] and isinstance(refused, ConfigError)
    assert apart[0][0] == fields
    np.testing.assert_allclose(apart[0][1][1], theta, rtol=1e-9)
    assert apart[0][1][0]["differentiated_runs"] == summary["differentiated_runs"]
    assert isinstance(apart[1][1], ConfigError)
    assert (apart[1][1].field, apart[1][1].reason) == (refused.field, refused.reason) == (
        "simulation.t_final", "0.3 s is within one period T = 6.283 s: the law learns nothing (û_d(t − T) = 0 throughout)")
