"""`RealtimeController`'s compiled step runs synchronously, and leaves the user's JAX as it was (issue 22, item 11).

JAX's CPU client dispatches asynchronously by default: a compiled call returns before its results are computed. The
controller's step runs on a CPU client of its own with asynchronous dispatch off
(`robotadapt.realtime.sync_cpu_device`), because `jax_cpu_enable_async_dispatch` is read only when JAX creates its
client and cannot be scoped to one call.
"""

from __future__ import annotations

import numpy as np

from robotadapt.realtime import RealtimeController
from robotadapt.tracing import jax_module


def panda() -> RealtimeController:
    """The Panda's Slotine–Li step (≈ 30–100 µs of work: long enough for an asynchronous call to return first)."""
    ctrl = RealtimeController.from_scenario("panda-slotine-li", backend="jax")
    ref = ctrl.trajectory(np.zeros(1))
    ctrl.reset(ref.q_des[0], ref.dq_des[0])
    return ctrl


def test_the_compiled_step_returns_ready_results(x64: None) -> None:
    """Every output of the step's program is computed when the call returns (asynchronously, 198 of 200 were not)."""
    ctrl = panda()
    ref = ctrl.trajectory(ctrl.Ts * np.arange(50))
    assert ctrl._step is not None
    state, inputs, n = ctrl._state, np.zeros(2 + 2 * ctrl.n), ctrl.n
    pending = 0
    for k in range(50):
        inputs[0], inputs[1], inputs[2 : 2 + n], inputs[2 + n :] = k, k * ctrl.Ts, ref.q_des[k], ref.dq_des[k]
        tau, state = ctrl._step(state, inputs)
        pending += (not tau.is_ready()) + (not state.is_ready())
        tau.block_until_ready()
    assert pending == 0


def test_the_users_jax_setting_and_client_are_unchanged() -> None:
    jax = jax_module()
    setting, client = jax.config.read("jax_cpu_enable_async_dispatch"), jax.devices("cpu")[0].client
    ctrl = panda()
    ref = ctrl.trajectory(np.zeros(1))
    tau = ctrl.step(0.0, ref.q_des[0], ref.dq_des[0])
    assert tau.shape == (7,) and np.all(np.isfinite(tau))
    assert jax.config.read("jax_cpu_enable_async_dispatch") == setting
    assert jax.devices("cpu")[0].client is client
    assert all(d.client is not client for d in ctrl._state.devices())  # the step's state lives on its own client
    if setting:  # the user's own programs still dispatch asynchronously: a 600 × 600 product takes milliseconds
        a = jax.numpy.ones((600, 600))
        product = jax.jit(lambda m: m @ m @ m)
        product(a).block_until_ready()
        assert any(not product(a).is_ready() for _ in range(5))
