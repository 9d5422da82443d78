"""Batch simulation (`robotadapt.sim.batch`): N closed loops in one vectorized loop reproduce N calls of `simulate`; a run
that diverges or stops is frozen with its own status and partial record while the others go on; the log bounds memory.

The reference is always the single-run simulator on the same objects: the batch must give the same logged instants,
states, recomputed outputs (τ, V, r, passivity integral), statuses and metrics, to round-off (1e-12).
"""

from __future__ import annotations

import copy
import dataclasses
import tracemalloc

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, SolveIVP, simulate
from robotadapt.sim.batch import NotBatchable, simulate_batch, stack
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid
from robotadapt.validation import ConfigError

ARM = TwoLinkArm()
PHI = np.array([0.8, 2.3])  # Example 6.3.1
ARRAYS = ("t", "q", "dq", "x", "tau", "phi_hat", "V", "r", "passivity")


def slotine_li(**kw) -> InertiaRelated:
    gains = {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0, "phi_hat0": [0.0, 0.0]} | kw
    return InertiaRelated(ARM, **gains)


def assert_same_run(batch_run, single) -> None:
    """Same status, same logged instants, every array equal to 1e-12, same metrics (wall time apart)."""
    assert batch_run.status == single.status
    for name in ARRAYS:
        a, b = getattr(batch_run, name), getattr(single, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert a.shape == b.shape, name
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * max(1.0, float(np.abs(b).max(initial=0.0))), err_msg=name)
    m1, m2 = metrics(batch_run), metrics(single)
    for m in (m1, m2):
        m.pop("wall_time_s")
    assert m1.keys() == m2.keys()
    for key, value in m1.items():
        if value is None or isinstance(value, str | bool | dict) or key in ("param_names", "consistency_parts"):
            assert value == m2[key], key
        else:
            np.testing.assert_allclose(value, m2[key], rtol=1e-11, atol=1e-12, err_msg=key)


def test_monte_carlo_over_true_parameters_and_initial_states_equals_single_runs():
    """Example 6.3.1 with the true masses drawn ±30 % and random initial states: every run of the batch is the run
    `simulate` gives for its own plant and initial state."""
    rng = np.random.default_rng(3)
    N = 5
    phis = PHI * rng.uniform(0.7, 1.3, size=(N, 2))
    q0, dq0 = rng.normal(scale=0.2, size=(N, 2)), rng.normal(scale=0.5, size=(N, 2))
    ctrl, traj = slotine_li(), sinusoid(2)
    batch = simulate_batch([Plant(ARM, phi) for phi in phis], ctrl, traj, t_final=0.6, q0=q0, dq0=dq0, log_every=3)
    assert len(batch) == N and batch.ok.all()
    for i in range(N):
        assert_same_run(batch.run(i), simulate(Plant(ARM, phis[i]), ctrl, traj, t_final=0.6, q0=q0[i], dq0=dq0[i],
                                               log_every=3))
    # the runs really differ: the batch did not compute one run N times
    assert np.ptp(batch.z[-1, :, 4]) > 0.1


def test_per_run_slotine_li_gains_and_sinusoids_equal_single_runs():
    """Λ, K_v, Γ (diagonal, scalar, full SPD), φ̂(0) and the sinusoid's amplitude, frequency, phase and offset all differ
    per run: one merged controller and one merged trajectory, stacked along the run axis."""
    N = 4
    G_full = np.array([[30.0, 5.0], [5.0, 10.0]])
    ctrls = [slotine_li(Lam=[2.5, 1.0 + i], Kv=5.0 + 3 * i, Gamma=G_full if i == 2 else 10.0 + i,
                        phi_hat0=[0.2 * i, 1.0]) for i in range(N)]
    trajs = [sinusoid(2, amplitude=[1.0, 0.5 + 0.1 * i], omega=1.0 + 0.2 * i, phase=0.1 * i, offset=[0.0, 0.1 * i])
             for i in range(N)]
    plant = Plant(ARM, PHI)
    batch = simulate_batch(plant, ctrls, trajs, t_final=0.5, log_every=5)
    merged = stack(ctrls, "controller")
    assert merged.Kv.shape == (N, 2, 2) and merged.Lam.shape == (N, 2, 2) and merged.Gamma.shape == (N, 2, 2)
    for i, together in enumerate(batch.runs()):
        single = simulate(plant, ctrls[i], trajs[i], t_final=0.5, log_every=5)
        assert_same_run(batch.run(i), single)
        assert_same_run(together, single)


SCENARIOS = {  # packaged scenarios, one per controller family; overrides keep them short and running
    "example-6.2.1": [],  # computed torque, fixed estimates
    "example-6.2.2": ["controller.phi_min=0.1", "controller.phi_max=10"],  # adaptive computed torque, projection
    "example-6.5.1": [],  # Slotine–Li, one-link arm, exponential step
    "example-6.6.3": [],  # composite (state φ̂, P, τ_f, Z)
    "example-6.7.2": [],  # sign-robust on a Slotine–Li base
    "example-7.2.1": [],  # DCAL, Y_d tabulated
    "problem-7.2-2": ["controller.precompute=false"],  # DCAL on the polar arm, Y_d on line
    "problem-6.4-1": [],  # passivity-based, PID servo
    "sigma-modification": [],  # passivity-based, σ-modification
    "example-7.2.2": [],  # repetitive: the delay line, one per run
}


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_every_controller_family_batches_over_plant_parameters_and_initial_states(name):
    """Per run: true φ (±20 %), q0, and φ̂(0) where the controller class lists it in its per_run."""
    s = load(name, SCENARIOS[name]).setup
    N, dt = 3, s.integrator.dt
    t_final = 150 * dt
    scale = np.array([1.0, 1.2, 0.8])
    plants = [Plant(s.plant.model, s.plant.phi * k, s.plant.disturbance) for k in scale]
    q0 = s.q0 + 0.05 * np.arange(N)[:, None]
    ctrls = [s.controller] * N
    if "phi_hat0" in type(s.controller).per_run:
        ctrls = [dataclasses.replace(s.controller, phi_hat0=s.controller.phi_hat0 * k) for k in scale]
    batch = simulate_batch(plants, ctrls, s.trajectory, t_final=t_final, integrator=s.integrator, q0=q0, dq0=s.dq0,
                           log_every=10)
    together = batch.runs()  # the outputs of every run computed at once, over the run axis
    for i in range(N):
        single = simulate(plants[i], ctrls[i], s.trajectory, t_final=t_final, integrator=s.integrator, q0=q0[i],
                          dq0=s.dq0, log_every=10)
        assert single.ok
        assert_same_run(batch.run(i), single)
        assert_same_run(together[i], single)


def test_plants_with_more_state_than_q_and_dq_batch_too():
    """Elastic joints (θ, θ̇ per joint) and a torque limit (the applied torque saturates): the plant's own initial
    state s0 = [q0, q̇0, θ0, θ̇0] per run, per-run true masses, and the same runs as `simulate`."""
    from robotadapt.plant.actuators import Actuator
    from robotadapt.plant.unmodeled import ElasticJoint

    joint, limit = ElasticJoint(2, J=0.2, K=400.0, D=2.0), Actuator(2, torque_limit=60.0)
    plants = [Plant(ARM, PHI * k, elastic_joint=joint, actuator=limit) for k in (1.0, 1.2)]
    q0 = np.array([[0.0, 0.0], [0.2, -0.1]])
    batch = simulate_batch(plants, slotine_li(), sinusoid(2), t_final=0.3, q0=q0, log_every=10)
    assert batch.z.shape[-1] == 4 * 2 + 2 + 2  # [q, q̇, θ, θ̇], φ̂, the passivity integral and its running minimum
    for i, together in enumerate(batch.runs()):
        single = simulate(plants[i], slotine_li(), sinusoid(2), t_final=0.3, q0=q0[i], log_every=10)
        assert_same_run(batch.run(i), single)
        assert_same_run(together, single)
    assert np.max(np.abs(batch.run(0).tau)) == pytest.approx(60.0)  # the limit is reached: the path is exercised


def test_a_diverging_run_is_frozen_with_its_partial_record_and_the_others_go_on():
    """Example 6.3.1 with max_state = 40: the run started at q̇(0) = (12, −12) rad/s exceeds it at t = 0.021 s (its
    peak |z| is 57.7; the others peak below 23). Its status and partial record are those of `simulate`; the run after
    it finishes and equals its single run."""
    ctrl, traj, plant = slotine_li(), sinusoid(2), Plant(ARM, PHI)
    dq0 = np.array([[0.0, 0.0], [12.0, -12.0], [2.0, -2.0]])
    batch = simulate_batch(plant, ctrl, traj, t_final=0.5, dq0=dq0, max_state=40.0, log_every=10)
    assert batch.status[0] == batch.status[2] == "ok"
    assert batch.status[1] == "diverged at t=0.021 s: state exceeded 40 in magnitude"
    assert batch.n_logged[1] < batch.n_logged[0] == batch.t.size == 51
    for i in range(3):
        assert_same_run(batch.run(i), simulate(plant, ctrl, traj, t_final=0.5, dq0=dq0[i], max_state=40.0,
                                               log_every=10))
    assert batch.run(1).t[-1] == 0.02
    frozen = batch.z[batch.n_logged[1] :, 1]  # the state it stopped in, within the guard, for the rest of the log
    assert np.all(frozen == frozen[0]) and np.abs(frozen[:, :-2]).max() <= 40.0  # the guard skips the monitors' w


def test_a_controller_that_stops_ends_only_its_own_run():
    """Example 6.2.2 as the book ran it: with ė(0) = 1, M̂ loses definiteness in the first step (SimulationStop); with
    q̇(0) = q̇_d(0) the same controller runs. The stop is found run by run and the others continue."""
    s = load("example-6.2.2").setup
    dq0 = np.array([[1.0, 1.0], [0.0, 0.0], [1.0, 1.0]])
    batch = simulate_batch(s.plant, s.controller, s.trajectory, t_final=0.2, dq0=dq0, log_every=10)
    assert batch.status[0] == batch.status[2] == "ok"
    assert batch.status[1].startswith("diverged within the step from 0 to 0.001 s: the estimated mass matrix")
    for i in range(3):
        assert_same_run(batch.run(i), simulate(s.plant, s.controller, s.trajectory, t_final=0.2, dq0=dq0[i],
                                               log_every=10))


def test_when_every_run_stops_the_batch_ends_there():
    s = load("example-6.2.2").setup
    batch = simulate_batch(s.plant, s.controller, s.trajectory, t_final=5.0, q0=np.zeros((2, 2)))
    assert not batch.ok.any()
    assert batch.t.size == 1 and batch.run(0).t.size == 1


def _peak_bytes(N: int, steps: int, log_every: int) -> tuple[int, object]:
    tracemalloc.start()
    res = simulate_batch(Plant(ARM, PHI), slotine_li(), sinusoid(2), t_final=steps * 1e-3, q0=np.zeros((N, 2)),
                         integrator=RK4(1e-3, "numpy"), log_every=log_every)  # the compiled path: REF_BYTES bounds it
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak, res


def test_log_every_bounds_memory():
    """The log holds steps/log_every + 1 samples per run; four times the steps at four times log_every keeps the same
    peak memory, a small fraction of a per-step record of 400 runs × 400 steps (7.7 MB): the log, the carry and the
    metrics folded at every step (robotadapt.sim.running: a step's sample and the runs' sums, about 0.15 MB here)."""
    _peak_bytes(400, 10, 10)  # first-call allocations (caches) out of the way
    short, res = _peak_bytes(400, 100, 10)
    long, res_long = _peak_bytes(400, 400, 40)
    assert res.z.shape == res_long.z.shape == (11, 400, 8)
    assert long < 1.2 * short, (short, long)
    assert long < 1.2e6
    with pytest.raises(ConfigError, match=r"^simulation\.log_every: .* GB log"):
        simulate_batch(Plant(ARM, PHI), slotine_li(), sinusoid(2), t_final=1000.0, q0=np.zeros((10_000, 2)))


def test_what_cannot_vary_within_a_batch_is_named():
    plant = Plant(ARM, PHI)
    with pytest.raises(NotBatchable, match=r"^plant\.model\.l1: differs between runs"):
        simulate_batch([plant, Plant(TwoLinkArm(l1=1.5), PHI)], slotine_li(), sinusoid(2), t_final=0.01)
    s = load("example-6.2.2").setup
    with pytest.raises(NotBatchable, match=r"^controller\.Kv: .*AdaptiveComputedTorque varies only phi_hat0"):
        simulate_batch(plant, [s.controller, dataclasses.replace(s.controller, Kv=60.0)], s.trajectory, t_final=0.01)
    with pytest.raises(NotBatchable, match=r"^simulation\.method: "):
        simulate_batch(plant, slotine_li(), sinusoid(2), t_final=0.01, integrator=SolveIVP())
    with pytest.raises(ConfigError, match=r"^plant\.q0: has 2 runs where another argument has 3"):
        simulate_batch([plant] * 3, slotine_li(), sinusoid(2), t_final=0.01, q0=np.zeros((2, 2)))
    with pytest.raises(ConfigError, match=r"^plant\.phi: the mass matrix is not positive definite"):
        simulate_batch([plant, Plant(ARM, [0.8, -1.0])], slotine_li(), sinusoid(2), t_final=0.01)


def test_equal_objects_are_not_stacked_and_shared_ones_are_returned_as_they_are():
    ctrl = slotine_li()
    assert stack([ctrl] * 3, "controller") is ctrl
    merged = stack([slotine_li(), slotine_li(), slotine_li()], "controller")  # equal, distinct: nothing stacked
    assert merged.Kv.shape == (2, 2)


def test_run_indexes_like_a_sequence():
    batch = simulate_batch(Plant(ARM, PHI), slotine_li(), sinusoid(2), t_final=0.01, q0=np.zeros((2, 2)),
                           integrator=RK4(1e-3))
    assert batch.run(-1).info["run"] == 1
    with pytest.raises(IndexError):
        batch.run(2)
    assert [metrics(batch.run(i))["status"] for i in range(len(batch))] == ["ok", "ok"]


def test_a_repetitive_batch_with_a_run_that_stops_keeps_its_delay_lines_apart():
    """Table 7.2.2 with one delay line per run (carried, written by the pure ring update): run 1 starts 2 rad off and
    exceeds max_state early; the others run past the first period (the ring wraps), each equal to its single run, and
    the stopped run's log holds the state it stopped in."""
    s = load("example-7.2.2", ["trajectory.omega=10.0", "controller.period=0.6283185307179586",
                               "simulation.dt=0.0015707963267948966"]).setup
    q0 = np.array([[0.0, 0.0], [-2.0, 0.0], [0.2, 0.1]])
    kw = dict(t_final=0.7, log_every=2, max_state=580.0, integrator=s.integrator)
    batch = simulate_batch(s.plant, s.controller, s.trajectory, q0=q0, **kw)
    assert [st == "ok" for st in batch.status] == [True, False, True]
    for i in range(3):
        assert_same_run(batch.run(i), simulate(s.plant, s.controller, s.trajectory, q0=q0[i], **kw))
    frozen = batch.z[batch.n_logged[1] :, 1]
    assert np.all(frozen == frozen[0])


def test_models_built_per_run_with_tables_stack_into_one_batch():
    """Runs may hold equal model objects that are not the same object (a model built per run); a model with per-joint
    tables and cached constants (the kinematic tree of a URDF arm) is recognised as the same and the runs batch.
    (Scenarios share one model per [robot] section: built once, here copied.)"""
    pytest.importorskip("pinocchio")
    from robotadapt.studies.scenarios import load

    setups = [load("panda-slotine-li", ["simulation.t_final=0.003", f"controller.Gamma={g}"]).setup for g in (5.0, 40.0)]
    assert setups[0].controller.model is setups[1].controller.model
    own = copy.deepcopy(setups[1].controller.model)
    setups[1] = dataclasses.replace(setups[1], plant=dataclasses.replace(setups[1].plant, model=own),
                                    controller=dataclasses.replace(setups[1].controller, model=own))
    assert setups[0].controller.model is not setups[1].controller.model
    batch = simulate_batch([s.plant for s in setups], [s.controller for s in setups], setups[0].trajectory,
                           t_final=0.003, integrator=RK4(1e-3, "numpy"), q0=np.stack([s.q0 for s in setups]))
    for i, s in enumerate(setups):
        single = simulate(s.plant, s.controller, s.trajectory, t_final=0.003, integrator=RK4(1e-3, "numpy"), q0=s.q0)
        np.testing.assert_allclose(batch.run(i).x, single.x, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", ["example-6.3.1", "problem-6.4-1", "example-6.6.3", "example-7.2.1", "sigma-modification"])
def test_outputs_evaluated_by_jax_equal_the_numpy_ones(name, monkeypatch):
    """Big batches (and n-DOF runs) evaluate the outputs' pure maps by JAX (`compiled_map`); here every batch does,
    and each run's τ, φ̂, V, r and passivity integral equal the numpy evaluation, run by run, to round-off."""
    from robotadapt.sim import outputs

    s = load(name, []).setup
    plants = [Plant(s.plant.model, s.plant.phi * k, s.plant.disturbance) for k in (1.0, 1.2, 0.8)]
    batch = simulate_batch(plants, s.controller, s.trajectory, t_final=150 * s.integrator.dt, integrator=s.integrator,
                           q0=s.q0, dq0=s.dq0, log_every=10)
    numpy_runs = batch.runs()
    monkeypatch.setattr(outputs, "COMPILED_OUTPUTS", 0)
    evaluated, real = [], outputs.compiled_map
    monkeypatch.setattr(outputs, "compiled_map", lambda *args: evaluated.append(real(*args)) or evaluated[-1])
    jax_runs = batch.runs()
    assert evaluated  # JAX evaluated the maps (no fallback to numpy)
    for a, b in zip(jax_runs, numpy_runs, strict=True):
        assert_same_run(a, b)


# --------------------------------------------------------------------------------------------------------------------
# Sampled-data runs batch too (issue 23): one program mapped over the runs, or numpy run by run


@pytest.mark.parametrize("backend", ["numpy", "jax", "c"])
def test_sampled_runs_batch_and_each_equals_its_single_run(backend, monkeypatch):
    """Example 6.3.1 at Ts = 2 ms with Kv drawn per run, an actuator limit and a noisy encoder with a seed per run: each
    run of the batch is the numpy single run of its own setup (numpy: to 1e-12; compiled and mapped over the runs, or
    each run through its C program: to 1e-9), its logged torques, measurements and tick-sum passivity included. C in
    calls of 64 ticks: the runs go through the calls in lockstep, each call's noise drawn once for all runs."""
    from robotadapt.sim import Sampled, driver

    monkeypatch.setattr(driver, "CHUNK_STEPS", 64)

    kvs = (5.0, 12.5, 20.0)
    sets = ["simulation.control_period=0.002", "simulation.t_final=0.6", "plant.torque_limit=60", "plant.noise_q=1e-4"]
    setups = [load("example-6.3.1", [*sets, f"controller.Kv={kv}", f"plant.seed={i}"]).setup
              for i, kv in enumerate(kvs)]
    batch = simulate_batch([s.plant for s in setups], [s.controller for s in setups], [s.trajectory for s in setups],
                           t_final=0.6, integrator=Sampled(0.002, backend=backend), log_every=3)
    assert batch.info["backend"] == backend and batch.ok.all()
    tol = 1e-12 if backend == "numpy" else 1e-9
    for i, (s, together) in enumerate(zip(setups, batch.runs(), strict=True)):
        single = simulate(s.plant, s.controller, s.trajectory, t_final=0.6, log_every=3,
                          integrator=Sampled(0.002, backend="numpy"))
        assert together.status == single.status and metrics(together)["passivity_form"] == "tick sum"
        for name in (*ARRAYS, "monitors"):
            a, b = getattr(together, name), getattr(single, name)
            pairs = [(k, a[k], b[k]) for k in b] if name == "monitors" else [(name, a, b)]
            for key, u, v in pairs:
                np.testing.assert_allclose(u, v, rtol=0, atol=tol * max(1.0, float(np.abs(v).max())), err_msg=key)
        assert_same_run(batch.run(i), together)
    assert not np.allclose(batch.run(0).monitors["q_measured"] - batch.run(0).q,
                           batch.run(1).monitors["q_measured"] - batch.run(1).q)  # each run its own seed


@pytest.mark.parametrize("backend", ["numpy", "jax"])
def test_a_sampled_run_that_diverges_is_frozen_and_the_others_go_on(backend):
    from robotadapt.sim import Sampled

    plant, ctrl, traj = Plant(ARM, PHI), slotine_li(), sinusoid(2)
    dq0 = np.array([[0.0, 0.0], [30.0, -30.0], [0.1, 0.0]])
    kw = dict(t_final=0.3, max_state=40.0, log_every=5)
    batch = simulate_batch(plant, ctrl, traj, dq0=dq0, integrator=Sampled(0.002, backend=backend), **kw)
    assert [st == "ok" for st in batch.status] == [True, False, True]
    for i in range(3):
        single = simulate(plant, ctrl, traj, dq0=dq0[i], integrator=Sampled(0.002, backend="numpy"), **kw)
        assert batch.run(i).status == single.status
        np.testing.assert_allclose(batch.run(i).q, single.q, rtol=0, atol=1e-9)
    frozen = batch.z[batch.n_logged[1] - 1 :, 1]
    assert np.all(frozen == frozen[0])


def test_what_cannot_batch_in_sampled_time_is_named():
    """A law setting that is part of the program's structure (the composite law's bounded-gain forgetting, k0 given or
    not) differs: NotBatchable naming `simulation`, so the sweep runs them one by one; a gain (the filter pole `a`, a
    leaf of the law) may differ; a MuJoCo plant is stepped on the host: a ConfigError naming `plant.engine`."""
    from robotadapt.sim import Sampled

    s = load("example-6.6.3").setup
    bounded = dataclasses.replace(s.controller, forgetting=0.1, k0=50.0)
    with pytest.raises(NotBatchable, match=r"^simulation: the runs differ in more than their arrays"):
        simulate_batch(s.plant, [s.controller, bounded], s.trajectory, t_final=0.01,
                       integrator=Sampled(0.002, backend="jax"))
    poles = simulate_batch(s.plant, [s.controller, dataclasses.replace(s.controller, a=2.0)], s.trajectory,
                           t_final=0.01, integrator=Sampled(0.002, backend="jax"))
    assert poles.ok.all()
    pytest.importorskip("mujoco")
    m = load("example-6.3.1", ["plant.engine='mujoco'"]).setup
    with pytest.raises(ConfigError, match=r"^plant\.engine: a MuJoCo plant is stepped by MuJoCo, one run at a time"):
        simulate_batch([m.plant, m.plant], m.controller, m.trajectory, t_final=0.01, integrator=m.integrator)
