"""Actuator and sensor effects (`robotadapt.plant.actuators`, `robotadapt.plant.sensors`): the applied torque never
exceeds its limits, the delay shifts the command by whole ticks, the measurement path is the documented recursion,
seeded noise is reproducible bit for bit, and the noise-driven drift of the gradient law has the rate the theory gives."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robotadapt.arrays import array_namespace
from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.plant.actuators import Actuator
from robotadapt.plant.sensors import Sensor
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, Sampled, simulate
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid
from robotadapt.validation import ConfigError

ARM = TwoLinkArm()
CTRL = InertiaRelated(ARM, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])  # Example 6.3.1: peak |τ| ≈ 570 N m
TS = 1e-3


def run(t_final: float = 0.5, integrator=None, **effects):
    plant = Plant(ARM, [0.8, 2.3], actuator=effects.pop("actuator", None), sensor=effects.pop("sensor", None))
    return simulate(plant, CTRL, sinusoid(2), t_final=t_final, integrator=integrator or Sampled(TS))


@pytest.mark.parametrize("limit", [50.0, [50.0, 20.0]])
@pytest.mark.parametrize("integrator", [RK4(1e-3), Sampled(TS)], ids=["continuous", "sampled"])
def test_the_logged_torque_is_the_applied_one_and_never_exceeds_the_limit(limit, integrator):
    res = run(integrator=integrator, actuator=Actuator(2, torque_limit=limit))
    bound = np.broadcast_to(limit, (2,))
    assert res.ok
    assert np.all(np.abs(res.tau) <= bound)  # exactly: clip, no tolerance
    commanded = res.monitors["tau_commanded"]
    assert np.all(np.abs(commanded).max(axis=0) > bound)  # the limit binds on both joints
    np.testing.assert_array_equal(res.tau, np.clip(commanded, -bound, bound))
    assert res.info["plant"]["actuator"] == {"torque_limit": bound.tolist()}


def test_the_rate_limit_bounds_every_step_and_binds():
    rate = 2000.0
    res = run(actuator=Actuator(2, torque_limit=100.0, torque_rate_limit=rate))
    steps = np.abs(np.diff(np.vstack([np.zeros(2), res.tau]), axis=0))  # u_{−1} = 0
    assert steps.max() <= rate * TS * (1 + 1e-12)
    assert np.isclose(steps.max(), rate * TS, rtol=1e-12)
    assert np.abs(res.tau).max() <= 100.0


@pytest.mark.parametrize("delay", [1, 3])
def test_a_computational_delay_applies_the_command_of_d_ticks_before(delay):
    res = run(actuator=Actuator(2, delay_samples=delay))
    commanded = res.monitors["tau_commanded"]
    np.testing.assert_array_equal(res.tau[:delay], 0.0)
    np.testing.assert_array_equal(res.tau[delay:], commanded[:-delay])


def test_same_seed_same_run_bit_for_bit_and_no_global_random_state():
    sensor = Sensor(2, encoder_resolution=1e-4, velocity="filter", velocity_cutoff=50.0, noise_q=1e-4, noise_dq=1e-3,
                    seed=7)
    first = run(sensor=sensor)
    np.random.seed(123)  # noqa: NPY002 -- on purpose: the global generator must play no part
    np.random.standard_normal(10)  # noqa: NPY002
    second = run(sensor=sensor)
    other = run(sensor=Sensor(2, encoder_resolution=1e-4, velocity="filter", velocity_cutoff=50.0, noise_q=1e-4,
                              noise_dq=1e-3, seed=8))
    a, b = first.arrays(), second.arrays()
    assert a.keys() == b.keys() and {"q_measured", "dq_measured"} <= a.keys()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert not np.array_equal(first.monitors["q_measured"], other.monitors["q_measured"])


def test_the_encoder_quantizes_and_the_difference_is_of_quantized_positions():
    delta = 1e-3
    res = run(sensor=Sensor(2, encoder_resolution=delta, velocity="difference"))
    q_m, dq_m = res.monitors["q_measured"], res.monitors["dq_measured"]
    counts = q_m / delta
    np.testing.assert_allclose(counts, np.round(counts), rtol=0, atol=1e-9)
    assert np.all(np.abs(q_m - res.q) <= delta / 2 * (1 + 1e-9))
    np.testing.assert_array_equal(dq_m[1:], (q_m[1:] - q_m[:-1]) / TS)
    np.testing.assert_array_equal(dq_m[0], res.dq[0])  # the first difference starts from the known q̇(0)
    assert res.info["plant"]["sensor"] == {"velocity": "difference", "encoder_resolution": [delta, delta]}


def test_the_velocity_filter_is_a_first_order_low_pass_of_the_difference():
    cutoff = 20.0
    res = run(sensor=Sensor(2, encoder_resolution=1e-4, velocity="filter", velocity_cutoff=cutoff))
    q_m, v = res.monitors["q_measured"], res.monitors["dq_measured"]
    a = math.exp(-2 * math.pi * cutoff * TS)
    np.testing.assert_allclose(v[1:], a * v[:-1] + (1 - a) * (q_m[1:] - q_m[:-1]) / TS, rtol=1e-12, atol=1e-12)


def test_measurement_noise_has_the_given_standard_deviation():
    sigma_q, sigma_dq = 2e-4, 5e-3
    res = run(t_final=2.0, sensor=Sensor(2, noise_q=sigma_q, noise_dq=[sigma_dq, 2 * sigma_dq], seed=3))
    n_q = res.monitors["q_measured"] - res.q
    n_dq = res.monitors["dq_measured"] - res.dq
    np.testing.assert_allclose(n_q.std(axis=0), sigma_q, rtol=0.1)  # 2001 samples: ±5 % at 3σ
    np.testing.assert_allclose(n_dq.std(axis=0), [sigma_dq, 2 * sigma_dq], rtol=0.1)
    assert abs(np.corrcoef(n_q[:, 0], n_q[:, 1])[0, 1]) < 0.1


@pytest.mark.parametrize("effects", [
    dict(sensor=Sensor(2, noise_q=1e-4)),
    dict(actuator=Actuator(2, torque_rate_limit=100.0)),
    dict(actuator=Actuator(2, delay_samples=1)),
])
def test_effects_that_live_at_control_ticks_need_sampled_mode(effects):
    with pytest.raises(ConfigError) as info:
        run(integrator=RK4(1e-3), **effects)
    assert info.value.field == "simulation.control_period"


@pytest.mark.parametrize(("sets", "field"), [
    (["plant.torque_limit=-5"], "plant.torque_limit"),
    (["plant.torque_limit=[1, 2, 3]"], "plant.torque_limit"),
    (["plant.delay_samples=1.5"], "plant.delay_samples"),
    (["plant.velocity='tacho'"], "plant.velocity"),
    (["plant.velocity='filter'"], "plant.velocity_cutoff"),
    (["plant.velocity_cutoff=10"], "plant.velocity_cutoff"),
    (["plant.seed=-1"], "plant.seed"),
    (["plant.noise_q=nan"], "plant.noise_q"),
    (["plant.encoder_resolution=0"], "plant.encoder_resolution"),
    (["plant.noise_dq=0.1"], "simulation.control_period"),  # builds; refused when run in continuous time
])
def test_scenario_effect_keys_are_checked(sets, field):
    with pytest.raises(ConfigError) as info:
        load("example-6.3.1", sets).run()
    assert info.value.field == field


def test_noise_drives_the_gradient_law_at_the_predicted_rate_and_sigma_modification_bounds_it():
    """noise-6.3.1, 10 s: at the set point with g = 0 the regressor's a-slot Λė and r = ė + Λe share the velocity
    noise n (σ = 0.05 rad/s), so with E[ė_i²] ≈ σ² the mean of Γ Yᵀ r is Γ Λ σ² l1² = 0.125 kg/s for m1 and
    Γ Λ σ² (l1² + 2 l2² + 2 l1 l2 cos q2) = 0.594 kg/s for m2 (the inertia columns of Y, spec §1.3, at q2 = 0.5): the
    gradient law (φ0 = 1e6) drifts at those rates, to 3 % (the loop's response to the noise changes E[ė²] slightly);
    the switching σ-modification keeps ‖φ̂‖ below 2 φ0 = 6."""
    s = load("noise-6.3.1").setup
    Gamma, Lam, sigma = 20.0, 2.5, 0.05
    gradient = load("noise-6.3.1", ["simulation.t_final=10", "controller.law.phi0=1e6"]).run()
    sigma_mod = load("noise-6.3.1", ["simulation.t_final=10"]).run()
    assert gradient.ok and sigma_mod.ok and s.plant.sensor.noise_dq.tolist() == [sigma, sigma]
    late = gradient.t >= 2.0
    rates = np.polyfit(gradient.t[late], gradient.phi_hat[late], 1)[0]
    predicted = Gamma * Lam * sigma**2 * np.array([1.0, 3.0 + 2.0 * math.cos(0.5)])
    assert np.all(np.abs(rates / predicted - 1) < 0.1), rates / predicted  # 0.98, 0.97 (seeds 2, 3: within 2 %)
    assert np.linalg.norm(gradient.phi_hat[-1]) > 6.0
    assert np.linalg.norm(sigma_mod.phi_hat, axis=1).max() < 6.0


def test_the_noise_is_drawn_ahead_in_the_documented_order():
    """Drawn a block of ticks at a time (the loop's way), the numbers are those of one draw per tick and source in the
    order n_q,0, n_q̇,0, n_q,1, … (the seed's documented stream); an unset source draws nothing and reads zeros."""
    both = Sensor(2, noise_q=1e-4, noise_dq=1e-3, seed=11)
    rng = both.generator()
    blocks = np.concatenate([both.noise(rng, 3), both.noise(rng, 4)])
    one = np.random.default_rng(11)
    np.testing.assert_array_equal(blocks, [[one.standard_normal(2), one.standard_normal(2)] for _ in range(7)])
    only_dq = Sensor(2, noise_dq=1e-3, seed=11)
    drawn = only_dq.noise(only_dq.generator(), 5)
    np.testing.assert_array_equal(drawn[:, 0], 0.0)
    np.testing.assert_array_equal(drawn[:, 1], np.random.default_rng(11).standard_normal((5, 2)))


def _effect_steps(actuator: Actuator, sensor: Sensor, q: np.ndarray, dq: np.ndarray, taus: np.ndarray,
                  noise: np.ndarray) -> tuple:
    """Five ticks of the actuator and the sensor from their start (at q = 0.1, q̇ = −0.2), states passed in and out."""
    act, meas = actuator.start(), sensor.start(np.full(2, 0.1), np.full(2, -0.2), TS)
    out = []
    for k in range(len(taus)):
        u, act = actuator.apply(act, taus[k], TS)
        measured, meas = sensor.measure(meas, q[k], dq[k], noise[k], TS)
        out.append((u, *measured))
    xp = array_namespace(taus)
    return tuple(xp.stack([o[i] for o in out]) for i in range(4))


def test_the_actuator_and_the_sensor_are_pure_and_trace_under_jax(x64):
    """State in, state out: the inputs are never written, and jax.jit of the same calls gives the same numbers."""
    actuator = Actuator(2, torque_limit=[50.0, 20.0], torque_rate_limit=3e4, delay_samples=2)
    sensor = Sensor(2, encoder_resolution=1e-3, velocity="filter", velocity_cutoff=30.0, noise_q=1e-4, noise_dq=1e-3)
    rng = np.random.default_rng(0)
    q, dq, taus = rng.normal(size=(5, 2)), rng.normal(size=(5, 2)), 80.0 * rng.normal(size=(5, 2))
    noise = sensor.noise(sensor.generator(), 5)
    state = actuator.start()
    frozen = [a.copy() for a in state]
    actuator.apply(state, taus[0], TS)
    for a, b in zip(state, frozen, strict=True):
        np.testing.assert_array_equal(a, b)
    u, q_m, dq_m, ddq_m = _effect_steps(actuator, sensor, q, dq, taus, noise)
    np.testing.assert_array_equal(u[:2], 0.0)  # the delay
    np.testing.assert_array_equal(ddq_m[0], 0.0)
    jax = pytest.importorskip("jax")
    from robotadapt.tracing import jax_module

    jnp = jax_module().numpy
    traced = jax.jit(lambda *a: _effect_steps(actuator, sensor, *a))(*(jnp.asarray(a) for a in (q, dq, taus, noise)))
    for mine, theirs in zip((u, q_m, dq_m, ddq_m), traced, strict=True):
        np.testing.assert_allclose(np.asarray(theirs), mine, rtol=1e-13, atol=1e-12)
