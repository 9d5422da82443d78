"""One run grid (robotadapt.grid): the same t_final and dt give the same number of samples and the same final time on
every engine — numpy, JAX, C, sampled-data, batches, the error-controlled integrators' samples, the gradient rollout of
tuning, a sweep's logging and the comparison's step count. t_final = 1.0005 s with dt = 1 ms is not a whole number of
steps: the one rounding takes ⌈t_final/h − 1e-9⌉ = 1001 steps, the last state at 1.001 s."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.controllers import InertiaRelated
from robotadapt.grid import Grid, steps
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, Sampled, SolveIVP, simulate, simulate_batch
from robotadapt.sim.gradient import Rollout
from robotadapt.sim.loop import ClosedLoop
from robotadapt.studies.scenarios import load
from robotadapt.studies.sweep import chunk_size, log_every
from robotadapt.trajectories import sinusoid

ARM, PHI = TwoLinkArm(), np.array([0.8, 2.3])
T_FINAL, DT = 1.0005, 1e-3
SAMPLES, END = 1002, 1.001


def _law() -> InertiaRelated:
    return InertiaRelated(ARM, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])


def test_the_one_rounding() -> None:
    assert steps(10.0, 1e-3) == 10000  # 10.0 / 0.001 = 10000.000000000002 is 10 000 steps, not 10 001
    assert steps(T_FINAL, DT) == 1001 and steps(1.0, 0.3) == 4 and steps(0.9, 0.3) == 3
    grid = Grid(DT, T_FINAL, log_every=10)
    assert (grid.n, grid.samples, grid.end) == (1001, 101, pytest.approx(END))
    np.testing.assert_array_equal(grid.times(), DT * (10 * np.arange(101)))


@pytest.mark.parametrize("integrator", [RK4(DT, backend="numpy"), RK4(DT, backend="jax"), RK4(DT, backend="c"),
                                        Sampled(DT, backend="numpy"), Sampled(DT, backend="jax"),
                                        SolveIVP("RK45", dt=DT, backend="numpy")],
                         ids=["numpy", "jax", "c", "sampled-numpy", "sampled-jax", "solve_ivp"])
def test_every_engine_logs_the_same_instants(integrator: object) -> None:
    res = simulate(Plant(ARM, PHI), _law(), sinusoid(2), t_final=T_FINAL, integrator=integrator)  # type: ignore[arg-type]
    assert res.status == "ok"
    assert len(res.t) == SAMPLES and res.t[-1] == pytest.approx(END, abs=1e-15)
    np.testing.assert_array_equal(res.t, Grid(DT, T_FINAL).times())


@pytest.mark.parametrize("integrator", [RK4(DT, backend="numpy"), Sampled(DT, backend="jax")], ids=["rk4", "sampled"])
def test_batches_log_the_same_instants(integrator: object) -> None:
    res = simulate_batch([Plant(ARM, PHI), Plant(ARM, 1.1 * PHI)], _law(), sinusoid(2), t_final=T_FINAL,
                         integrator=integrator)  # type: ignore[arg-type]
    assert len(res.t) == SAMPLES and res.t[-1] == pytest.approx(END, abs=1e-15)
    assert list(res.n_logged) == [SAMPLES, SAMPLES]


def test_the_gradient_rollout_of_tuning_logs_the_same_instants() -> None:
    loop = ClosedLoop(Plant(ARM, PHI), _law(), 2, monitored=True)
    for integrator in (RK4(DT), Sampled(DT)):
        rollout = Rollout.make(loop, sinusoid(2), integrator, T_FINAL, 1)
        assert rollout.n == 1001
        np.testing.assert_array_equal(rollout.times, Grid(DT, T_FINAL).times())


def test_sweeps_and_the_comparison_count_steps_on_the_grid() -> None:
    """A sweep thins its runs' logs to at most LOG_SAMPLES + 1 = 1001 states, counted on the grid: 1001 steps (a floor
    would count 1000) need every 2nd (1001 = 7·11·13 has no divisor in [2, 4]); 1000 steps keep every one."""
    s = load("example-6.3.1", ["simulation.t_final=1.0005", "simulation.dt=0.001"]).setup
    assert log_every(s) == 2 and Grid(0.001, s.t_final, log_every(s)).samples == 501
    whole = load("example-6.3.1", ["simulation.t_final=1.0", "simulation.dt=0.001"]).setup
    assert log_every(whole) == 1 and Grid(0.001, 1.0, 1).samples == 1001
    digital = load("example-6.3.1", ["simulation.t_final=1.0005", "simulation.control_period=0.002"]).setup
    assert Grid.of(digital.integrator, digital.t_final).n == 501  # ticks of Ts, not steps of the plant's dt
    assert chunk_size(100, 2, s) >= 1
