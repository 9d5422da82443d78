"""`robotadapt.realtime` (issue 18): the controller a robot driver calls, step by step, gives the simulator's run.

The loop is closed here by hand, the way a driver's callback would (examples/realtime_mujoco.py), around a plant
stepped by MuJoCo or by RK4 written out in this file; the simulator (`Scenario.run`) is the independent computation.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from robotadapt.arrays import rk4
from robotadapt.plant.mujoco import load_mujoco
from robotadapt.realtime import RealtimeController
from robotadapt.studies.scenarios import load
from robotadapt.validation import ConfigError


def drive(ctrl: RealtimeController, advance: Any, q0: np.ndarray, dq0: np.ndarray, ticks: int) -> np.ndarray:
    """The driver's loop: measure, step, send; the states at ticks 0 … `ticks`."""
    n = q0.size
    state = np.concatenate([q0, dq0])
    ctrl.reset(q0, dq0)
    out = [state]
    for k in range(ticks):
        tau = ctrl.step(k * ctrl.Ts, state[:n], state[n:])
        state = advance(k * ctrl.Ts, state, tau)
        out.append(state)
    return np.array(out)


@pytest.mark.parametrize("backend", ["jax", "numpy"])
def test_driving_mujoco_through_the_interface_equals_the_simulation(backend: str) -> None:
    try:
        load_mujoco()
    except ConfigError:  # pragma: no cover - `make test` installs the extra
        pytest.skip("the mujoco extra is not installed")
    overrides = ["plant.engine=mujoco", "simulation.t_final=2"]
    scenario = load("example-6.3.1", overrides)
    setup = scenario.setup
    ctrl = RealtimeController.from_scenario("example-6.3.1", overrides, backend=backend)
    assert ctrl.backend == backend and ctrl.Ts == 1e-3
    z = drive(ctrl, lambda t, s, tau: setup.plant.advance(t, s, tau, 1, 1e-3), setup.q0, setup.dq0, 2000)
    run = scenario.run()
    np.testing.assert_allclose(z, np.concatenate([run.q, run.dq], axis=1), rtol=0, atol=1e-11)
    np.testing.assert_allclose(ctrl.x, run.x[-1], rtol=0, atol=1e-11)  # x_2000, the last tick's


def test_driving_our_own_plant_equals_the_sampled_data_simulation() -> None:
    """Slotine–Li on the two-link arm, Ts = 2 ms, the plant by two RK4 steps written out here."""
    scenario = load("digital-6.3.1", ["simulation.control_period=2e-3", "simulation.t_final=1"])
    setup = scenario.setup
    plant = setup.plant

    def advance(_t: float, s: np.ndarray, tau: np.ndarray) -> np.ndarray:
        def f(t: float, y: np.ndarray) -> np.ndarray:
            return np.concatenate([y[2:], plant.acceleration(t, y[:2], y[2:], tau)])

        return rk4(f, 0.0, rk4(f, 0.0, s, 1e-3), 1e-3)

    ctrl = RealtimeController.from_scenario("digital-6.3.1", ["simulation.control_period=2e-3"])
    z = drive(ctrl, advance, setup.q0, setup.dq0, 500)
    run = scenario.run()
    np.testing.assert_allclose(z, np.concatenate([run.q, run.dq], axis=1), rtol=0, atol=1e-11)


def test_compiled_once() -> None:
    """A second reset keeps the compiled step; the state starts over."""
    ctrl = RealtimeController.from_scenario("example-6.3.1", backend="jax")
    ctrl.reset(np.zeros(2), np.zeros(2))
    program = ctrl._step
    first = [ctrl.step(0.001 * k, np.zeros(2), np.ones(2)) for k in range(3)]
    ctrl.reset(np.zeros(2), np.zeros(2))
    assert ctrl._step is program
    np.testing.assert_array_equal(first, [ctrl.step(0.001 * k, np.zeros(2), np.ones(2)) for k in range(3)])


def test_bad_use_is_a_config_error() -> None:
    ctrl = RealtimeController.from_scenario("example-6.3.1", backend="numpy")
    with pytest.raises(ConfigError, match=r"^realtime: call reset"):
        ctrl.step(0.0, np.zeros(2), np.zeros(2))
    with pytest.raises(ConfigError, match=r"^q: "):
        ctrl.reset(np.zeros(3), np.zeros(2))
    with pytest.raises(ConfigError, match=r"^simulation\.backend: "):
        RealtimeController.from_scenario("example-6.3.1", backend="gpu")
