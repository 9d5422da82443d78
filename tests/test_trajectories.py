"""Desired trajectories: shapes, derivatives, closed forms, periods and input errors."""

from __future__ import annotations

import re

import numpy as np
import pytest

from robotadapt.trajectories import SumOfSines, constant, exponential_step, quintic, sinusoid
from robotadapt.validation import ConfigError

TRAJECTORIES = {
    "sinusoid": lambda: sinusoid(3, amplitude=[1.0, 0.5, 2.0], omega=[1.0, 2.0, 0.7], phase=[0.0, 0.3, -1.0],
                                 offset=[0.1, 0.0, -0.2]),
    "sum-of-sines": lambda: SumOfSines.make(2, amplitude=[1.0, 0.4], omega=[1.0, 3.0], phase=[0.0, np.pi / 2],
                                            offset=[0.0, 0.5]),
    "exponential": lambda: exponential_step(2, final=[1.0, -0.5], rate=[2.0, 0.5], start=[0.0, 0.3]),
    "quintic": lambda: quintic(2, q0=[0.0, 1.0], q1=[1.0, -1.0], t0=0.5, t1=2.0),
    "constant": lambda: constant(2, [0.3, -0.2]),
}


@pytest.mark.parametrize("name", list(TRAJECTORIES))
@pytest.mark.parametrize("t", [1.3, np.float64(1.3), np.array(1.3), 1], ids=["float", "np.float64", "0-d", "int"])
def test_scalar_time_gives_shape_n(name, t):
    traj = TRAJECTORIES[name]()
    ref = traj(t)
    assert len(ref) == 3
    for arr in ref:
        assert arr.shape == (traj.n,)
    # a scalar instant equals the same instant inside an array
    along = traj(np.array([0.0, float(t), 5.0]))
    for one, many in zip(ref, along, strict=True):
        np.testing.assert_allclose(one, many[1], rtol=1e-15, atol=0)


@pytest.mark.parametrize("name", list(TRAJECTORIES))
@pytest.mark.parametrize("shape", [(5,), (2, 3), (1,), (0,)])
def test_array_time_gives_shape_t_plus_n(name, shape):
    traj = TRAJECTORIES[name]()
    t = np.linspace(0.0, 3.0, int(np.prod(shape))).reshape(shape)
    ref = traj(t)
    for arr in ref:
        assert arr.shape == shape + (traj.n,)
    for idx in np.ndindex(*shape):
        for one, many in zip(traj(t[idx]), ref, strict=True):
            np.testing.assert_allclose(one, many[idx], rtol=1e-15, atol=0)


# Instants before, inside and after the quintic's window [0.5, 2], away from its two joins.
TIMES = np.array([0.1, 0.7, 1.0, 1.25, 1.9, 2.6, 4.0])


@pytest.mark.parametrize("name", list(TRAJECTORIES))
def test_velocity_and_acceleration_are_derivatives(name):
    traj, h = TRAJECTORIES[name](), 1e-5
    ref = traj(TIMES)
    plus, minus = traj(TIMES + h), traj(TIMES - h)
    scale = 1.0 + max(np.abs(a).max() for a in ref)
    np.testing.assert_allclose((plus.q_des - minus.q_des) / (2 * h), ref.dq_des, rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose((plus.dq_des - minus.dq_des) / (2 * h), ref.ddq_des, rtol=0, atol=1e-8 * scale)


def test_closed_forms():
    t = np.array([0.0, 0.4, 2.0, 7.5])[:, None]
    # sinusoid: offset + A sin(ω t + φ), per joint
    ref = TRAJECTORIES["sinusoid"]()(t[:, 0])
    A, w, ph, off = np.array([1.0, 0.5, 2.0]), np.array([1.0, 2.0, 0.7]), np.array([0.0, 0.3, -1.0]), \
        np.array([0.1, 0.0, -0.2])
    np.testing.assert_allclose(ref.q_des, off + A * np.sin(w * t + ph), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(ref.dq_des, A * w * np.cos(w * t + ph), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(ref.ddq_des, -A * w**2 * np.sin(w * t + ph), rtol=1e-14, atol=1e-14)
    # sin t + 0.4 cos 3t (cos x = sin(x + π/2)), offsets [0, 0.5]
    ref = TRAJECTORIES["sum-of-sines"]()(t[:, 0])
    s = np.sin(t) + 0.4 * np.cos(3 * t)
    np.testing.assert_allclose(ref.q_des, s + [0.0, 0.5], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(ref.ddq_des, -np.sin(t) - 3.6 * np.cos(3 * t) + [0.0, 0.0], rtol=1e-13, atol=1e-13)
    # the book's 1 − e^{−2t} (Example 6.5.1)
    ref = exponential_step(1)(t[:, 0])
    np.testing.assert_allclose(ref.q_des, 1 - np.exp(-2 * t), rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(ref.dq_des, 2 * np.exp(-2 * t), rtol=1e-14)
    np.testing.assert_allclose(ref.ddq_des, -4 * np.exp(-2 * t), rtol=1e-14)
    # quintic at mid-time s = ½: 10/8 − 15/16 + 6/32 = ½ of the way, speed (30/4 − 60/8 + 30/16)/T = 1.875/T, no accel.
    ref = quintic(2, q0=[0.0, 1.0], q1=[1.0, -1.0], t0=0.5, t1=2.0)(1.25)
    np.testing.assert_allclose(ref.q_des, [0.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(ref.dq_des, np.array([1.0, -2.0]) * 1.875 / 1.5, rtol=1e-14)
    np.testing.assert_allclose(ref.ddq_des, [0.0, 0.0], atol=1e-13)
    # a constant set point
    ref = constant(2, [0.3, -0.2])(t[:, 0])
    np.testing.assert_array_equal(ref.q_des, np.broadcast_to([0.3, -0.2], (4, 2)))
    np.testing.assert_array_equal(ref.dq_des, 0.0)
    np.testing.assert_array_equal(ref.ddq_des, 0.0)


def test_the_books_default_sinusoid_is_sin_t():
    t = np.linspace(0, 10, 11)
    ref = sinusoid(2)(t)
    np.testing.assert_allclose(ref.q_des, np.sin(t)[:, None] * np.ones(2), rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(ref.dq_des, np.cos(t)[:, None] * np.ones(2), rtol=1e-15, atol=1e-15)


def test_quintic_hits_its_endpoints_at_rest():
    q0, q1 = np.array([0.2, -1.0, 3.0]), np.array([1.5, 0.0, -3.0])
    traj = quintic(3, q0=q0, q1=q1, t0=1.0, t1=3.5)
    for t, q in [(1.0, q0), (3.5, q1), (0.0, q0), (-2.0, q0), (3.6, q1), (100.0, q1)]:
        ref = traj(t)
        np.testing.assert_allclose(ref.q_des, q, rtol=0, atol=1e-14)
        np.testing.assert_allclose(ref.dq_des, 0.0, rtol=0, atol=1e-14)
        np.testing.assert_allclose(ref.ddq_des, 0.0, rtol=0, atol=1e-13)
    # and actually moves between them, monotonically
    q = traj(np.linspace(1.0, 3.5, 101)).q_des
    assert np.all(np.diff(q, axis=0) * np.sign(q1 - q0) >= 0)


@pytest.mark.parametrize(
    ("traj", "period"),
    [
        (sinusoid(2), 2 * np.pi),  # sin t
        (SumOfSines.make(1, amplitude=1.0, omega=[1.0, 3.0], phase=[0.0, np.pi / 2]), 2 * np.pi),  # sin t + cos 3t
        (sinusoid(1, omega=2.0), np.pi),
        (SumOfSines.make(1, amplitude=1.0, omega=[2.0, 3.0]), 2 * np.pi),  # common period of sin 2t and sin 3t
        (sinusoid(2, omega=[1.0, 2.0]), 2 * np.pi),  # per-joint frequencies
        (SumOfSines.make(1, amplitude=[1.0, 0.0], omega=[1.0, np.sqrt(2)]), 2 * np.pi),  # the √2 term is absent
        (SumOfSines.make(1, amplitude=1.0, omega=[1.0, np.sqrt(2)]), None),  # incommensurate
        (exponential_step(2), None),
        (quintic(1, 0.0, 1.0), None),
        (constant(1, 0.0), None),
    ],
)
def test_period(traj, period):
    if period is None:
        assert traj.period is None
    else:
        assert traj.period == pytest.approx(period, rel=1e-12)
        t = np.linspace(0.0, 7.0, 50)
        for now, later in zip(traj(t), traj(t + period), strict=True):
            np.testing.assert_allclose(later, now, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: sinusoid(2, amplitude="big"), "trajectory.amplitude"),
        (lambda: sinusoid(2, amplitude=[1.0, 2.0, 3.0]), "trajectory.amplitude"),
        (lambda: sinusoid(2, amplitude=True), "trajectory.amplitude"),
        (lambda: sinusoid(2, omega=float("nan")), "trajectory.omega"),
        (lambda: sinusoid(2, phase=[[0.0, 1.0]]), "trajectory.phase"),
        (lambda: sinusoid(2, offset=None), "trajectory.offset"),
        (lambda: SumOfSines.make(2, amplitude=[[1.0, 2.0, 3.0]], omega=[1.0]), "trajectory.amplitude"),
        (lambda: SumOfSines.make(2, amplitude=1.0, omega=[1.0, 3.0], phase=[0.0, 1.0, 2.0]), "trajectory.phase"),
        (lambda: SumOfSines.make(2, amplitude=1.0, omega=[1.0, float("inf")]), "trajectory.omega"),
        (lambda: SumOfSines.make(2, amplitude=1.0, omega=1.0, offset=[1.0, 2.0, 3.0]), "trajectory.offset"),
        (lambda: exponential_step(2, rate=-1.0), "trajectory.rate"),
        (lambda: exponential_step(2, rate=[1.0, 0.0]), "trajectory.rate"),
        (lambda: exponential_step(2, final=[1.0]), "trajectory.final"),
        (lambda: exponential_step(2, start="0"), "trajectory.start"),
        (lambda: quintic(2, q0=[0.0], q1=[1.0, 1.0]), "trajectory.q0"),
        (lambda: quintic(2, q0=[0.0, 0.0], q1=[1.0, float("nan")]), "trajectory.q1"),
        (lambda: quintic(2, q0=0.0, q1=1.0, t0=2.0, t1=2.0), "trajectory.t1"),
        (lambda: quintic(2, q0=0.0, q1=1.0, t0=2.0, t1=1.0), "trajectory.t1"),
        (lambda: quintic(2, q0=0.0, q1=1.0, t0=[0.0, 1.0]), "trajectory.t0"),
        (lambda: constant(2, [1.0, 2.0, 3.0]), "trajectory.value"),
    ],
)
def test_bad_inputs_name_the_field(make, field):
    with pytest.raises(ConfigError, match=rf"^{re.escape(field)}: ") as info:
        make()
    assert info.value.field == field


def test_sum_of_sines_is_the_public_constructor_and_its_shapes_are_unambiguous():
    from robotadapt.trajectories import sum_of_sines

    t = np.linspace(0.0, 2.0, 7)
    # a scalar omega: a list amplitude is per joint
    q = sum_of_sines(3, amplitude=[1.0, 2.0, 3.0], omega=2.0)(t).q_des
    np.testing.assert_allclose(q, np.sin(2 * t)[:, None] * [1.0, 2.0, 3.0])
    # a list omega: a list amplitude is per frequency, the same on every joint (here k == n: no guessing)
    q = sum_of_sines(2, amplitude=[1.0, 0.5], omega=[1.0, 3.0])(t).q_des
    np.testing.assert_allclose(q, np.repeat((np.sin(t) + 0.5 * np.sin(3 * t))[:, None], 2, axis=1))
    # a table amplitude[joint][frequency]
    q = sum_of_sines(2, amplitude=[[1.0, 0.0, 0.2], [0.0, 2.0, 0.0]], omega=[1.0, 2.0, 5.0])(t).q_des
    np.testing.assert_allclose(q[:, 0], np.sin(t) + 0.2 * np.sin(5 * t))
    np.testing.assert_allclose(q[:, 1], 2 * np.sin(2 * t))
    with pytest.raises(ConfigError, match=r"^trajectory\.amplitude: a table is amplitude\[joint\]\[frequency\]: 2 rows "
                                          r"of 3, got shape \(3, 2\) \(transpose it"):
        sum_of_sines(2, amplitude=[[1.0, 0.0], [0.0, 2.0], [0.2, 0.0]], omega=[1.0, 2.0, 5.0])
    with pytest.raises(ConfigError, match=r"^trajectory\.amplitude: a list gives one value per frequency: expected 1, "
                                          r"got 2 \(with omega a list"):
        sum_of_sines(2, amplitude=[1.0, 2.0], omega=[1.0])


def test_the_scenario_kind_uses_the_public_constructor():
    from robotadapt.studies.scenarios.build import TARGETS

    assert TARGETS["trajectory"]["sum_of_sines"][0] == "trajectories:sum_of_sines"
