"""Task-space references: derivatives, geometry, closed forms, the ramp, batches, JAX, reach and input errors."""

from __future__ import annotations

import dataclasses
import importlib
import re

import numpy as np
import pytest

from robotadapt.sim.batch import stack
from robotadapt.studies.scenarios.build import TARGETS
from robotadapt.task_trajectories import Circle, FigureEight, Line, reach_check
from robotadapt.trajectories import sum_of_sines
from robotadapt.validation import ConfigError

CASES = {
    "circle-planar": lambda: Circle([1.0, 0.5], 0.3, 1.5, phase=0.4),
    "circle-xz-ramped": lambda: Circle([0.4, 0.0, 0.6], 0.2, -2.0, plane="xz", ramp=1.5),
    "circle-normal": lambda: Circle([0.5, 0.2, 0.3], 0.25, 2.5, plane=[1.0, 2.0, -0.5], phase=-1.0),
    "figure-eight-planar": lambda: FigureEight([1.0, 0.0], 0.6, 0.3, 1.2, phase=0.2),
    "figure-eight-yz-ramped": lambda: FigureEight([0.5, 0.1, 0.4], 0.4, 0.2, 3.0, plane="yz", ramp=0.8),
    "line": lambda: Line([0.2, 0.5, 0.1], [0.9, -0.3, 0.6], t0=0.5, t1=2.0),
    "sum-of-sines": lambda: sum_of_sines(3, amplitude=[0.1, 0.05], omega=[1.0, 3.0], offset=[0.6, 0.0, 0.4]),
}
# before, inside and after the ramps (0.8, 1.5) and the line's window [0.5, 2], none on a join
TIMES = np.array([-0.4, 0.05, 0.3, 0.7, 1.1, 1.45, 1.7, 2.6, 4.3])


@pytest.mark.parametrize("name", list(CASES))
def test_velocity_and_acceleration_are_the_derivatives(name, x64):
    import jax
    import jax.numpy as jnp

    traj = CASES[name]()
    ref = traj(TIMES)
    for field, rate in (("q_des", "dq_des"), ("dq_des", "ddq_des")):
        def along(t, field=field):
            return getattr(traj(t), field)

        _, derivative = jax.jvp(along, (jnp.asarray(TIMES),), (jnp.ones_like(jnp.asarray(TIMES)),))
        scale = np.abs(getattr(ref, rate)).max()
        np.testing.assert_allclose(np.asarray(derivative), getattr(ref, rate), rtol=1e-7, atol=1e-7 * scale)


@pytest.mark.parametrize("name", list(CASES))
def test_jit_equals_numpy(name, x64):
    import jax

    from robotadapt.tracing import jax_module

    jax_module()  # registers the package's pytrees: the trajectory is an argument of the program
    traj = CASES[name]()
    compiled = jax.jit(lambda trajectory, t: trajectory(t))(traj, jax.numpy.asarray(TIMES))
    for traced, plain in zip(compiled, traj(TIMES), strict=True):
        assert isinstance(traced, jax.Array)
        np.testing.assert_allclose(np.asarray(traced), plain, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("shape", [(), (5,), (2, 3), (0,)])
def test_leading_axes_of_t(name, shape):
    traj = CASES[name]()
    t = np.linspace(-0.5, 4.0, int(np.prod(shape))).reshape(shape)
    ref = traj(float(t) if shape == () else t)
    for arr in ref:
        assert arr.shape == shape + (traj.n,)
    for idx in np.ndindex(*shape):
        for one, many in zip(traj(t[idx]), ref, strict=True):
            np.testing.assert_allclose(one, many[idx], rtol=1e-15, atol=0)


NORMALS = {"xy": [0.0, 0.0, 1.0], "yz": [1.0, 0.0, 0.0], "xz": [0.0, -1.0, 0.0]}


@pytest.mark.parametrize("plane", ["planar", "xy", "yz", "xz", (1.0, 2.0, -0.5), (0.0, 0.0, -3.0)])
def test_the_circle_stays_on_its_circle_in_its_plane(plane):
    centre = [0.8, -0.3] if plane == "planar" else [0.8, -0.3, 0.4]
    circle = Circle(centre, 0.35, 1.7, phase=0.3) if plane == "planar" else Circle(centre, 0.35, 1.7, plane, phase=0.3)
    t = np.linspace(0.0, 6.0, 301)
    ref = circle(t)
    offset = ref.q_des - centre
    np.testing.assert_allclose(np.linalg.norm(offset, axis=-1), 0.35, rtol=1e-14)
    np.testing.assert_allclose(np.sum(offset * ref.dq_des, axis=-1), 0.0, atol=1e-14)  # tangent
    np.testing.assert_allclose(np.linalg.norm(ref.dq_des, axis=-1), 0.35 * 1.7, rtol=1e-14)  # uniform speed
    np.testing.assert_allclose(ref.ddq_des, -1.7**2 * offset, atol=1e-14)  # centripetal
    u, v = circle.u, circle.v
    np.testing.assert_allclose([u @ u, v @ v, u @ v], [1.0, 1.0, 0.0], atol=1e-15)
    if plane == "planar":
        np.testing.assert_array_equal(np.stack([u, v]), np.eye(2))
        return
    normal = np.asarray(NORMALS.get(plane, plane), dtype=float)
    np.testing.assert_allclose(np.cross(u, v), normal / np.linalg.norm(normal), atol=1e-15)
    np.testing.assert_allclose(offset @ normal, 0.0, atol=1e-15)


def test_named_planes_and_normals_agree_and_follow_the_stated_convention():
    t = np.linspace(0.0, 3.0, 7)
    for name, normal in NORMALS.items():
        named, by_normal = Circle([0.0, 0.0, 0.0], 1.0, 1.0, name), Circle([0.0, 0.0, 0.0], 1.0, 1.0, normal)
        np.testing.assert_allclose(by_normal(t).q_des, named(t).q_des, atol=1e-15)
    # "xz": u = e_x, v = e_z, x = c + r (cos θ, 0, sin θ)
    np.testing.assert_allclose(Circle([0.0, 0.0, 0.0], 1.0, 1.0, "xz")(t).q_des,
                               np.stack([np.cos(t), 0 * t, np.sin(t)], axis=-1), atol=1e-15)
    # a normal: u is the axis least aligned with it (here e_z), projected and normalised; v = ν̂ × u
    tilted = Circle([0.0, 0.0, 0.0], 1.0, 1.0, [1.0, 2.0, -0.5])
    nu = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    u = np.array([0.0, 0.0, 1.0]) - nu[2] * nu
    np.testing.assert_allclose(tilted.u, u / np.linalg.norm(u), atol=1e-15)
    np.testing.assert_allclose(tilted.v, np.cross(nu, tilted.u), atol=1e-15)


def test_the_ramped_circle_starts_at_rest_and_reaches_omega():
    T, w, r, phase = 2.0, 3.0, 0.25, 0.7
    circle = Circle([1.0, 0.5], r, w, phase=phase, ramp=T)
    start = circle(np.array([-1.0, 0.0]))
    np.testing.assert_allclose(start.q_des, [[1.0 + r * np.cos(phase), 0.5 + r * np.sin(phase)]] * 2, atol=1e-15)
    np.testing.assert_array_equal(start.dq_des, 0.0)
    np.testing.assert_array_equal(start.ddq_des, 0.0)
    # the speed rises monotonically to r ω and stays there; θ = φ + ω(t − T/2) after the ramp
    during = np.linalg.norm(circle(np.linspace(0.0, T, 101)).dq_des, axis=-1)
    assert np.all(np.diff(during) > 0) and 0.0 < during[1] < 1e-4
    after = np.linspace(T, T + 5.0, 50)
    late = circle(after)
    np.testing.assert_allclose(np.linalg.norm(late.dq_des, axis=-1), r * w, rtol=1e-14)
    theta = phase + w * (after - T / 2)
    np.testing.assert_allclose(late.q_des, np.stack([1.0 + r * np.cos(theta), 0.5 + r * np.sin(theta)], -1), atol=1e-14)
    # x, ẋ, ẍ continuous where the ramp ends
    for before, behind in zip(circle(T - 1e-9), circle(T + 1e-9), strict=True):
        np.testing.assert_allclose(before, behind, atol=1e-7)
    assert circle.period is None and Circle([1.0, 0.5], r, w).period == pytest.approx(2 * np.pi / w)


def test_an_unramped_circle_repeats_with_its_period():
    circle = Circle([0.1, 0.2, 0.3], 0.5, -2.0, "yz", phase=1.0)
    t = np.linspace(0.0, 3.0, 11)
    for now, later in zip(circle(t), circle(t + circle.period), strict=True):
        np.testing.assert_allclose(now, later, atol=1e-13)


def test_the_line_is_on_the_segment_and_at_rest_at_both_ends():
    x0, x1 = np.array([0.2, 0.5, 0.1]), np.array([0.9, -0.3, 0.6])
    line = Line(x0, x1, t0=0.5, t1=2.0)
    ends = line(np.array([0.0, 0.5, 2.0, 3.0]))
    np.testing.assert_allclose(ends.q_des, [x0, x0, x1, x1], atol=1e-15)
    np.testing.assert_array_equal(ends.dq_des, 0.0)
    np.testing.assert_array_equal(ends.ddq_des, 0.0)
    t = np.linspace(0.5, 2.0, 41)
    ref = line(t)
    fraction = (ref.q_des - x0) @ (x1 - x0) / np.sum((x1 - x0) ** 2)
    np.testing.assert_allclose(ref.q_des, x0 + fraction[:, None] * (x1 - x0), atol=1e-15)  # on the line
    assert np.all(np.diff(fraction) > 0) and fraction[0] == 0.0 and fraction[-1] == 1.0  # forward, within the segment
    np.testing.assert_allclose(line(1.25).q_des, (x0 + x1) / 2, atol=1e-15)
    s = (t - 0.5) / 1.5
    np.testing.assert_allclose(fraction, 10 * s**3 - 15 * s**4 + 6 * s**5, atol=1e-14)
    assert line.period is None and line.n == 3


def test_the_figure_eight_closed_form():
    width, height, w, phase = 0.6, 0.3, 1.2, 0.2
    eight = FigureEight([1.0, -0.5], width, height, w, phase=phase)
    t = np.linspace(0.0, 2 * np.pi / w, 2001)
    ref, theta, a, b = eight(t), w * t + phase, width / 2, height
    np.testing.assert_allclose(ref.q_des, np.stack([1.0 + a * np.sin(theta), -0.5 + b * np.sin(2 * theta) / 2], -1),
                               atol=1e-15)
    np.testing.assert_allclose(ref.dq_des, np.stack([a * w * np.cos(theta), b * w * np.cos(2 * theta)], -1), atol=1e-14)
    np.testing.assert_allclose(ref.ddq_des, np.stack([-a * w**2 * np.sin(theta), -2 * b * w**2 * np.sin(2 * theta)], -1),
                               atol=1e-14)
    x, y = (ref.q_des - [1.0, -0.5]).T
    np.testing.assert_allclose((x / a) ** 4, (x / a) ** 2 - (y / b) ** 2, atol=1e-14)  # Gerono's lemniscate
    np.testing.assert_allclose([np.ptp(x), np.ptp(y)], [width, height], rtol=1e-5)  # the full extents
    # in space: the same curve along (u, v), here "yz"
    spatial = FigureEight([0.0, 0.0, 0.0], width, height, w, "yz", phase=phase)(t).q_des
    np.testing.assert_allclose(spatial, np.stack([0 * t, x, y], -1), atol=1e-15)
    assert eight.period == pytest.approx(2 * np.pi / w)


def test_the_ramped_figure_eight_starts_at_rest():
    eight = FigureEight([0.5, 0.1, 0.4], 0.4, 0.2, 3.0, plane="yz", ramp=0.8)
    start = eight(0.0)
    np.testing.assert_allclose(start.q_des, [0.5, 0.1, 0.4], atol=1e-15)
    np.testing.assert_array_equal(start.dq_des, 0.0)
    np.testing.assert_array_equal(start.ddq_des, 0.0)
    late = eight(np.array([0.8, 2.0]))  # after the ramp θ = ω(t − T/2): the unramped eight with phase −ωT/2
    np.testing.assert_allclose(late.dq_des, FigureEight([0.5, 0.1, 0.4], 0.4, 0.2, 3.0, "yz", phase=-1.2)(
        np.array([0.8, 2.0])).dq_des, atol=1e-14)


@pytest.mark.parametrize("runs", [
    [Circle([1.0, 0.5], 0.3, 1.5), Circle([0.8, 0.2], 0.2, 2.0, phase=0.5)],
    [FigureEight([1.0, 0.0, 0.3], 0.6, 0.3, 1.2, "xz"), FigureEight([0.9, 0.1, 0.2], 0.4, 0.5, -1.0, "xz", phase=1.0)],
    [Line([0.2, 0.5], [0.9, -0.3], 0.5, 2.0), Line([0.0, 0.0], [0.4, 0.3], 0.5, 2.0)],
], ids=["circle", "figure-eight", "line"])
def test_per_run_fields_broadcast_over_a_run_axis(runs):
    merged = stack(runs, "trajectory")
    t = np.array([0.3, 1.1])  # one instant per run
    for i, run in enumerate(runs):
        for together, alone in zip(merged(t), run(t[i]), strict=True):
            np.testing.assert_allclose(together[i], alone, rtol=1e-15, atol=1e-15)


def test_replace_keeps_the_plane_and_validates_again():
    circle = Circle([0.0, 0.0, 0.0], 1.0, 1.0, [0.0, 0.0, -2.0])
    wider = dataclasses.replace(circle, radius=2.0)
    np.testing.assert_allclose([wider.u, wider.v], [circle.u, circle.v])
    np.testing.assert_allclose(wider(0.4).q_des, 2 * circle(0.4).q_des)
    with pytest.raises(ConfigError, match="trajectory.radius"):
        dataclasses.replace(circle, radius=-1.0)


@pytest.mark.parametrize("kind, kwargs, m", [
    ("circle", {"centre": [0.5, 0.5], "radius": 0.2, "omega": 1.0}, 2),
    ("figure_eight", {"centre": [0.5, 0.0, 0.5], "width": 0.2, "height": 0.1, "omega": 1.0, "plane": "xz"}, 3),
    ("line", {"x0": [0.5, 0.0], "x1": [0.0, 0.5], "t0": 0.0, "t1": 1.0}, 2),
    ("sum_of_sines", {"amplitude": 0.1, "omega": 1.0, "offset": [0.6, 0.0, 0.4]}, 3),
])
def test_every_task_kind_is_named_for_a_scenario(kind, kwargs, m):
    target, first = TARGETS["trajectory"][kind]
    module, _, attr = target.partition(":")
    make = getattr(importlib.import_module(f"robotadapt.{module}"), attr)
    traj = make(m, **kwargs) if first == "n" else make(**kwargs)
    assert traj.n == m and all(a.shape == (4, m) for a in traj(np.linspace(0.0, 1.0, 4)))


ARM = {"origin": [0.0, 0.0], "inner": 0.2, "outer": 1.8}  # a two-link arm, l1 = 1, l2 = 0.8


def test_reach_check_passes_a_reachable_circle():
    reach_check(Circle([1.0, 0.3], 0.5, 2.0, ramp=1.0), t_final=10.0, **ARM)
    reach_check(Line([0.5, 0.5], [-1.0, 1.0], 1.0, 3.0), t_final=5.0, **ARM)


def test_reach_check_finds_a_peak_between_samples():
    """Out by 1e-9 only at θ = 0 (the point farthest from the base), at t = 2.3 sample spacings: no sample is there."""
    spacing = 10.0 / 1999
    circle = Circle([1.2, 0.0], 0.6 + 1e-9, 1.0, phase=-2.3 * spacing)
    assert np.linalg.norm(circle(np.linspace(0.0, 10.0, 2000)).q_des, axis=-1).max() < 1.8
    with pytest.raises(ConfigError) as caught:
        reach_check(circle, t_final=10.0, **ARM)
    error = caught.value
    assert error.field == "trajectory" and "\n" not in str(error)
    time, distance = (float(v) for v in re.search(r"at t = (\S+) s: .* is (\S+) m from", str(error)).groups())
    assert time == pytest.approx(2.3 * spacing, abs=1e-6) and distance == pytest.approx(1.8, abs=1e-8)
    assert "[0.2, 1.8] m" in str(error) and "smaller radius" in str(error) and "from the base [0, 0]" in str(error)


def test_reach_check_names_the_first_point_out_of_reach():
    """Too far on every turn, first from t ≈ 1.08 s (|θ| < 0.922 with θ = t − 2): the first is named; a line through
    the base's unreachable disc is named where it enters it, with the other fix."""
    circle = Circle([1.2, 0.0], 0.8, 1.0, phase=-2.0)  # distance² = 2.08 + 1.92 cos θ
    with pytest.raises(ConfigError, match=r"at t = 1\.0[78]\d* s: x_d = \[1\.6\d*, -0\.6\d*\] is 1\.8\d* m "
                                          r".*smaller radius"):
        reach_check(circle, t_final=20.0, **ARM)
    with pytest.raises(ConfigError, match=r"t = 0\.4\d* s: x_d = \[-0\.19\d*, 0\.05\] is 0\.19\d* m from the base "
                                          r"\[0, 0\], outside \[0\.2, 1\.8\] m; move the path away from the base"):
        reach_check(Line([-1.0, 0.05], [1.0, 0.05], 0.0, 1.0), t_final=2.0, **ARM)


def test_reach_check_in_space_from_a_raised_base():
    shoulder = {"origin": [0.0, 0.0, 0.3], "inner": 0.05, "outer": 0.72}
    circle = Circle([0.4, 0.0, 0.3], 0.3, 2.0, "xz")  # 0.1 to 0.7 from the shoulder
    reach_check(circle, t_final=5.0, **shoulder)
    with pytest.raises(ConfigError, match="is 0.75 m from the base"):
        reach_check(dataclasses.replace(circle, radius=0.35), t_final=5.0, **shoulder)


def test_reach_check_takes_a_sum_of_sines():
    reach_check(sum_of_sines(2, amplitude=0.2, omega=[1.0, 2.0], offset=[1.0, 0.5]), t_final=10.0, **ARM)
    with pytest.raises(ConfigError, match="trajectory"):
        reach_check(sum_of_sines(2, amplitude=0.5, omega=[1.0, 2.0], offset=[1.2, 0.5]), t_final=10.0, **ARM)


@pytest.mark.parametrize("make, field", [
    (lambda: Circle([0.5, 0.5], 0.0, 1.0), "trajectory.radius"),
    (lambda: Circle([0.5, 0.5], -0.2, 1.0), "trajectory.radius"),
    (lambda: Circle([0.5, 0.5], 0.2, float("inf")), "trajectory.omega"),
    (lambda: Circle([0.5, 0.5], 0.2, float("nan")), "trajectory.omega"),
    (lambda: Circle([0.5, 0.5], 0.2, 0.0), "trajectory.omega"),
    (lambda: Circle([0.5, 0.5, 0.5, 0.5], 0.2, 1.0), "trajectory.centre"),
    (lambda: Circle(0.5, 0.2, 1.0), "trajectory.centre"),
    (lambda: Circle([0.5, 0.5], 0.2, 1.0, plane="yz"), "trajectory.plane"),
    (lambda: Circle([0.5, 0.5, 0.5], 0.2, 1.0, plane="zw"), "trajectory.plane"),
    (lambda: Circle([0.5, 0.5, 0.5], 0.2, 1.0, plane=[0.0, 0.0, 0.0]), "trajectory.plane"),
    (lambda: Circle([0.5, 0.5, 0.5], 0.2, 1.0, plane=[1.0, 0.0]), "trajectory.plane"),
    (lambda: Circle([0.5, 0.5], 0.2, 1.0, phase=[0.1, 0.2]), "trajectory.phase"),
    (lambda: Circle([0.5, 0.5], 0.2, 1.0, ramp=-1.0), "trajectory.ramp"),
    (lambda: FigureEight([0.5, 0.5], 0.0, 0.1, 1.0), "trajectory.width"),
    (lambda: FigureEight([0.5, 0.5], 0.2, -0.1, 1.0), "trajectory.height"),
    (lambda: FigureEight([0.5, 0.5], 0.2, 0.1, 1.0, plane="xz"), "trajectory.plane"),
    (lambda: Line([0.0, 0.0], [1.0, 1.0], t0=1.0, t1=1.0), "trajectory.t1"),
    (lambda: Line([0.0, 0.0], [1.0, 1.0, 1.0]), "trajectory.x1"),
    (lambda: Line("here", [1.0, 1.0]), "trajectory.x0"),
    (lambda: reach_check(Circle([1.0, 0.0], 0.2, 1.0), [0.0, 0.0, 0.0], 0.2, 1.8, 1.0), "origin"),
    (lambda: reach_check(Circle([1.0, 0.0], 0.2, 1.0), [0.0, 0.0], 0.2, 0.2, 1.0), "outer"),
    (lambda: reach_check(Circle([1.0, 0.0], 0.2, 1.0), [0.0, 0.0], -0.1, 1.8, 1.0), "inner"),
    (lambda: reach_check(Circle([1.0, 0.0], 0.2, 1.0), [0.0, 0.0], 0.2, 1.8, 0.0), "t_final"),
    (lambda: reach_check(Circle([1.0, 0.0], 0.2, 1.0), [0.0, 0.0], 0.2, 1.8, 1.0, samples=1), "samples"),
])
def test_bad_inputs_name_the_field(make, field):
    with pytest.raises(ConfigError) as caught:
        make()
    assert caught.value.field == field and "\n" not in str(caught.value)
