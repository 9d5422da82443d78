"""The RK4 step's stages scanned (`rk4_step(rolled=True)`, what the differentiable rollout traces: the closed loop's
dynamics once in the program, not four times) against the classic step written out here, the law's guard included."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim.loop import ClosedLoop, rk4_step
from robotadapt.trajectories import sinusoid

jax = pytest.importorskip("jax", reason="a rolled step is traced by JAX (make test installs it)")
jnp = jax.numpy

A = np.array([[0.0, 0.0, 0.0], [-2.0, -0.5, 1.0], [0.3, 0.0, -3.0]])
DT, T0 = 0.1, 0.7
REF = sinusoid(2)


def _loop() -> ClosedLoop:
    arm = TwoLinkArm()
    return ClosedLoop(Plant(arm, [0.8, 2.3]), InertiaRelated(arm, 2.5, 10.0, 20.0, [0.0, 0.0]), 2)


def _refs():
    return tuple(REF(np.float64(T0 + c * DT)) for c in (0.0, 0.5, 1.0))


def _by_hand(f, z):
    """The classic RK4 step of `f(t, z) -> (rate, guard)`: its result and the four stage states and guards."""
    k1, g1 = f(T0, z)
    z2 = z + DT / 2 * k1
    k2, g2 = f(T0 + DT / 2, z2)
    z3 = z + DT / 2 * k2
    k3, g3 = f(T0 + DT / 2, z3)
    z4 = z + DT * k3
    k4, g4 = f(T0 + DT, z4)
    return z + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4), [z, z2, z3, z4], [g1, g2, g3, g4]


def test_a_rolled_step_of_the_closed_loop_is_the_classic_step():
    """Slotine–Li on the two-link arm: the rolled step equals the unrolled one to round-off and both equal RK4 of the
    loop's vector field written out in numpy; τ and u are the first stage's."""
    loop = _loop()
    z = np.array([0.3, -0.2, 0.5, 0.1, 0.4, 1.9])
    r0, rh, r1 = _refs()
    step = jax.jit(lambda z, rolled: rk4_step(loop, T0, z, DT, r0, rh, r1, rolled=rolled), static_argnums=1)
    with jax.enable_x64(True):
        rolled, unrolled = step(jnp.asarray(z), True), step(jnp.asarray(z), False)
    refs = {T0: r0, T0 + DT / 2: rh, T0 + DT: r1}
    want, _, _ = _by_hand(lambda t, y: (loop.respond(t, y, refs[t])[0], None), z)
    tau, u = loop.respond(T0, z, r0)[2:]
    for got in (rolled, unrolled):
        np.testing.assert_allclose(np.asarray(got[0]), want, rtol=1e-13, atol=1e-15)
        assert got[1] is None and got[2] is None
        np.testing.assert_allclose(np.asarray(got[3]), tau, rtol=1e-13)
        np.testing.assert_allclose(np.asarray(got[4]), u, rtol=1e-13)


@pytest.mark.parametrize("failing", [None, 1, 2, 3])
def test_a_rolled_step_names_the_first_stage_whose_guard_failed(failing):
    """A guarded rate (dz/dt = A z + sin t, so ż₀ = sin t > 0; its guard z₀ below a bound): `ok` is whether the guard
    held in all four stages and `z_bad` the state of the first stage where it did not (the last stage's where none
    failed), the bound placed between the stages' z₀."""
    loop = _loop()
    z = np.array([0.2, 1.0, 0.5])
    rate = lambda t, y: y @ A.T + np.sin(t)  # noqa: E731
    _, stages, _ = _by_hand(lambda t, y: (rate(t, y), None), z)
    first = [s[0] for s in stages]
    assert first == sorted(first)  # z₀ grows over the stages: a bound between two fails from there on
    bound = first[-1] + 1.0 if failing is None else (first[failing - 1] + first[failing]) / 2

    def respond(t, y, ref):
        k = y @ jnp.asarray(A).T + jnp.sin(t)
        return k, y[0] < bound, k[:2], 2.0 * k[:2]

    want, stages, guards = _by_hand(lambda t, y: (rate(t, y), y[0] < bound), z)
    r0, rh, r1 = _refs()
    with jax.enable_x64(True):
        got = jax.jit(lambda y: rk4_step(loop, T0, y, DT, r0, rh, r1, respond, rolled=True))(jnp.asarray(z))
    np.testing.assert_allclose(np.asarray(got[0]), want, rtol=1e-14)
    assert bool(got[1]) == all(guards)
    np.testing.assert_allclose(np.asarray(got[2]), stages[3 if failing is None else failing], rtol=1e-14)
    np.testing.assert_allclose(np.asarray(got[4]), 2.0 * rate(T0, z)[:2], rtol=1e-14)


def _scans(jaxpr) -> list[int]:
    """The lengths of the scans in a jaxpr, nested programs included."""
    found = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "scan":
            found.append(eqn.params["length"])
        for value in eqn.params.values():
            inner = getattr(value, "jaxpr", None)
            if inner is not None and hasattr(inner, "eqns"):
                found += _scans(inner)
    return found


def test_a_long_step_is_rolled_for_xla_only(monkeypatch):
    """The compiled step of more than LEAN_MAX operations scans its four stages for XLA and keeps them written out for
    the C translator (which calls the one function of the rates it has); a shorter step is not rolled. Both give the
    unrolled step's numbers (the threshold lowered so that the two-link arm's step counts as long)."""
    from robotadapt.sim import compiled
    from robotadapt.sim.loop import RK4Step

    loop = _loop()
    step = RK4Step(loop, DT, 1e6, REF)
    z = np.array([0.3, -0.2, 0.5, 0.1, 0.4, 1.9])
    carry, inputs = step.start(z), step.feed(REF)(3, 1)
    one = jax.tree_util.tree_map(lambda a: a[0], inputs)

    def traced(native):
        with jax.enable_x64(True):
            fn = step.compiled(native)
            return jax.make_jaxpr(fn)(carry, one).jaxpr, jax.jit(fn)(carry, one)[0][0]

    short = traced(False)
    monkeypatch.setattr(compiled, "LEAN_MAX", 10)
    rolled, native = traced(False), traced(True)
    assert _scans(short[0]) == [] and _scans(native[0]) == [] and _scans(rolled[0]) == [4]
    np.testing.assert_allclose(np.asarray(rolled[1]), np.asarray(native[1]), rtol=1e-14)
    np.testing.assert_allclose(np.asarray(rolled[1]), np.asarray(short[1]), rtol=1e-14)
