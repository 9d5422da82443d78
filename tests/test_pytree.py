"""Values JAX understands (robotadapt.pytree): every model, law, plant and trajectory of every packaged scenario is a
pytree whose leaves are its float arrays; flattening round-trips; a new gain value (DCAL's and the repetitive law's
scalars included) reuses the compiled program; a host field (a sensor's seed) is not part of a program's key; derived
constants are part of the tree from construction on, and `replace` recomputes them from the new leaves."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from robotadapt import pytree
from robotadapt.controllers import DCAL, InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, Sampled, simulate
from robotadapt.studies.scenarios import available, load
from robotadapt.tracing import PROGRAMS, jax_module
from robotadapt.trajectories import Reference, sinusoid

ARM, PHI = TwoLinkArm(), np.array([0.8, 2.3])
SKIP = ("panda-mujoco",)  # its plant is MuJoCo's, stepped on the host


def _is_array(a: object) -> bool:
    return isinstance(a, np.ndarray | jax.Array) and np.issubdtype(a.dtype, np.floating)


@pytest.mark.parametrize("name", [n for n in available() if n not in SKIP])
def test_every_packaged_object_is_a_pytree_of_its_arrays(name: str) -> None:
    jax_module()
    s = load(name).setup
    for obj in (s.controller, s.controller.model, s.plant, s.plant.model, s.trajectory):
        leaves = jax.tree_util.tree_leaves(obj)
        assert all(_is_array(a) for a in leaves), (name, type(obj).__name__)
        assert [id(a) for a in leaves] == [id(a) for a in pytree.leaves(obj)]
    assert jax.tree_util.tree_leaves(s.plant)[0] is not None
    # the tree rebuilt from its leaves computes the same torque
    ctrl = s.controller
    rebuilt = jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(ctrl), jax.tree_util.tree_leaves(ctrl))
    assert type(rebuilt) is type(ctrl) and rebuilt is not ctrl
    n = ctrl.model.n
    q, dq = np.linspace(0.1, 0.4, n), np.linspace(-0.2, 0.3, n)
    ref = s.trajectory(0.3)
    if ctrl.needs_acceleration:  # a law that needs q̈ gives its torque alone
        a, b = ctrl.torque(0.3, ctrl.initial_state(q, dq), q, dq, ref), rebuilt.torque(
            0.3, rebuilt.initial_state(q, dq), q, dq, ref)
    else:
        a, b = ctrl(0.3, ctrl.initial_state(q, dq), q, dq, ref)[0], rebuilt(
            0.3, rebuilt.initial_state(q, dq), q, dq, ref)[0]
    np.testing.assert_array_equal(a, b)


def test_gains_are_leaves_and_structure_is_static() -> None:
    jax_module()
    law = DCAL(ARM, Kv=10, Kp=5, Ka=1, Gamma=20, phi_hat0=[0, 0])
    leaves = jax.tree_util.tree_leaves(law)
    assert any(a.shape == () and float(a) == 10.0 for a in leaves)  # K_v is a leaf, not part of the structure
    other = DCAL(ARM, Kv=12, Kp=6, Ka=2, Gamma=30, phi_hat0=[0.1, 0.2])
    assert jax.tree_util.tree_structure(law) == jax.tree_util.tree_structure(other)
    assert pytree.key(law) == pytree.key(other)
    assert pytree.key(law) != pytree.key(DCAL(ARM, Kv=10, Kp=5, Ka=1, Gamma=20, phi_hat0=[0, 0], precompute=True))
    # jax.tree_util.tree_map and vmap reach the leaves
    doubled = jax.tree_util.tree_map(lambda a: 2 * a, law)
    assert float(doubled.Kv) == 20.0 and float(law.Kv) == 10.0
    q, dq = np.array([0.1, 0.2]), np.zeros(2)
    ref = Reference(np.zeros(2), np.zeros(2), np.zeros(2))
    stacked = jax.tree_util.tree_map(lambda a, b: np.stack([a, b]), law, other)

    def torque(ctrl: DCAL) -> jax.Array:
        return ctrl(0.0, ctrl.phi_hat0, q, dq, ref)[0]

    with jax.enable_x64(True):
        both = jax.vmap(torque)(stacked)
    np.testing.assert_allclose(both[0], torque(law), rtol=1e-14)
    np.testing.assert_allclose(both[1], torque(other), rtol=1e-14)


@pytest.mark.parametrize("backend", ["jax", "c"])
@pytest.mark.parametrize("make", [
    lambda k: DCAL(ARM, Kv=k, Kp=k / 2, Ka=1.0, Gamma=20, phi_hat0=[0, 0]),
    lambda k: InertiaRelated(ARM, Lam=2.5, Kv=k, Gamma=20, phi_hat0=[0, 0]),
], ids=["dcal", "slotine-li"])
def test_a_new_gain_value_reuses_the_compiled_program(make: object, backend: str) -> None:
    """Two runs that differ only in gains (Python numbers in the scenario, leaves in the law) share one program."""
    runs = []
    for k in (10.0, 17.0):
        before = PROGRAMS.keys()
        res = simulate(Plant(ARM, PHI), make(k), sinusoid(2), t_final=0.5,  # type: ignore[operator]
                       integrator=RK4(1e-3, backend=backend))
        runs.append((res, PROGRAMS.keys(), before))
        assert res.status == "ok"
    (first, _, _), (second, after, before) = runs
    assert after == before  # the second gain compiled nothing new (no XLA, C or map program)
    assert not np.allclose(first.tau, second.tau)  # and its gain took effect: its own numbers
    ref = simulate(Plant(ARM, PHI), make(17.0), sinusoid(2), t_final=0.5,  # type: ignore[operator]
                   integrator=RK4(1e-3, backend="numpy"))
    np.testing.assert_allclose(second.q, ref.q, rtol=1e-9, atol=1e-12)


def test_a_sensor_seed_is_a_host_field() -> None:
    from robotadapt.plant.sensors import Sensor

    a, b = Sensor(2, noise_q=[1e-3, 1e-3], seed=1), Sensor(2, noise_q=[1e-3, 1e-3], seed=2)
    assert pytree.key(a) == pytree.key(b)
    assert pytree.unflatten(pytree.key(b), pytree.leaves(b)).seed == 2  # it travels with the structure
    assert pytree.key(a) != pytree.key(Sensor(2, noise_q=[1e-3, 1e-3], velocity="difference"))


def test_derived_constants_are_leaves_and_replace_recomputes_them() -> None:
    law = InertiaRelated(ARM, Lam=2.5, Kv=10, Gamma=[20, 40], phi_hat0=[0, 0])
    before = pytree.key(law)
    simulate(Plant(ARM, PHI), law, sinusoid(2), t_final=0.05, integrator=RK4(1e-3, backend="numpy"))
    assert pytree.key(law) == before  # a run leaves the law's key as it was
    inverse = [a for a in pytree.leaves(law) if np.allclose(a, np.diag([1 / 20, 1 / 40]))]
    assert inverse, "Γ⁻¹ is a leaf of the tree"
    new = pytree.replace(law, ("Gamma",), np.diag([5.0, 8.0]))
    np.testing.assert_allclose(new.geometry._Gamma_inv, np.diag([1 / 5, 1 / 8]))
    np.testing.assert_allclose(law.geometry._Gamma_inv, np.diag([1 / 20, 1 / 40]))  # the original untouched


def test_sampled_runs_share_a_program_across_gains() -> None:
    before = len(PROGRAMS)
    for k in (10.0, 14.0):
        res = simulate(Plant(ARM, PHI), DCAL(ARM, Kv=k, Kp=5.0, Ka=1.0, Gamma=20, phi_hat0=[0, 0]), sinusoid(2),
                       t_final=0.2, integrator=Sampled(0.002, backend="jax"))
        assert res.status == "ok"
    assert len(PROGRAMS) - before <= 1
