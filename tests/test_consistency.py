"""Physical consistency of φ (robotadapt.robots.consistency): the pseudo-inertia against its definition as the second
moment ∫ [x; 1][x; 1]ᵀ dm of a cloud of point masses, the triangle inequality it encodes, the URDF arms' own φ, and
the metrics every run writes against a hand check of its φ̂(t)."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.robots.consistency import parts, pseudo_inertia, smallest_eigenvalues
from robotadapt.studies.scenarios import load


def link_of_points(x: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The 10 standard parameters (m, h, I about the origin) of point masses m_k at x_k, written out."""
    h = m @ x
    inertia = sum(mk * (xk @ xk * np.eye(3) - np.outer(xk, xk)) for xk, mk in zip(x, m, strict=True))
    return np.array([m.sum(), *h, inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2],
                     inertia[2, 2]])


def test_the_pseudo_inertia_is_the_second_moment_of_the_mass():
    rng = np.random.default_rng(3)
    x, m = rng.normal(size=(6, 3)), rng.uniform(0.1, 2.0, size=6)
    moment = sum(mk * np.outer(np.append(xk, 1.0), np.append(xk, 1.0)) for xk, mk in zip(x, m, strict=True))
    np.testing.assert_allclose(pseudo_inertia(link_of_points(x, m)), moment, rtol=1e-12, atol=1e-12)
    assert np.linalg.eigvalsh(moment)[0] > 0  # six points in general position: a real body, J ≻ 0


def test_a_point_mass_is_on_the_boundary_and_a_broken_triangle_inequality_is_outside():
    point = link_of_points(np.array([[0.3, -0.1, 0.2]]), np.array([2.0]))
    assert abs(smallest_eigenvalues(point, parts([f"{p}1" for p in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz",
                                                                         "Iyz", "Izz")]))[0]) < 1e-12
    # I = diag(1, 1, 3) about the centre of mass: Ixx + Iyy < Izz, which no body has
    broken = np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 3.0])
    assert np.linalg.eigvalsh(pseudo_inertia(broken))[0] == pytest.approx(-0.5)


def test_the_panda_urdf_is_consistent_and_the_book_arms_are_scalars():
    model = load("panda-slotine-li").setup.plant.model
    layout = parts(model.param_names)
    assert [p.name for p in layout] == [f"link {i}" for i in range(1, 8)]
    lows = smallest_eigenvalues(load("panda-slotine-li").setup.plant.phi, layout)
    assert np.all(lows > 0) and lows.min() == pytest.approx(8.6e-7, rel=0.01) and lows.max() < 2.5e-3
    assert [p.name for p in parts(("m1", "m2"))] == ["m1", "m2"]


def test_every_run_says_whether_and_when_its_estimate_left_the_set():
    """Example 6.3.1 from φ̂(0) = 0: m̂1 goes negative in the transient; the metrics name the first such sample."""
    res = load("example-6.3.1", ["simulation.t_final=1.0"]).run()
    m = metrics(res)
    first = int(np.argmax(np.any(res.phi_hat < 0, axis=1)))
    assert m["physically_consistent"] is False
    assert m["left_consistent_set_t"] == float(res.t[first])
    assert m["left_consistent_set_part"] == ("m1", "m2")[int(np.argmax(res.phi_hat[first] < 0))]
    assert m["min_pseudo_inertia_eigenvalue"] == pytest.approx(float(res.phi_hat.min()))
    good = metrics(load("example-6.3.1", ["simulation.t_final=1.0", "controller.phi_hat0=[0.8, 2.3]",
                                          "controller.Gamma=0.001"]).run())
    assert good["physically_consistent"] is True and good["left_consistent_set_t"] is None
