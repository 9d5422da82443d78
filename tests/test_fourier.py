"""The Fourier-series trajectory of exciting experiments (Swevers 1997; issue 27): `[trajectory] kind = "fourier"`."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.studies.scenarios import load
from robotadapt.trajectories import fourier
from robotadapt.validation import ConfigError


def test_the_series_is_swevers_form_with_its_derivatives():
    """q, q̇, q̈ against the series written out, at random coefficients; its period is T."""
    rng = np.random.default_rng(27)
    n, K, T = 3, 4, 5.0
    a, b, q0 = rng.normal(size=(n, K)), rng.normal(size=(n, K)), rng.normal(size=n)
    traj = fourier(n, T, a.tolist(), b.tolist(), q0.tolist())
    t = rng.uniform(0, 20, 50)
    wl = 2 * np.pi / T * np.arange(1, K + 1)
    arg = t[:, None, None] * wl[None, None, :]  # (t, joint, harmonic)
    q = q0 + (a / wl * np.sin(arg) - b / wl * np.cos(arg)).sum(-1)
    dq = (a * np.cos(arg) + b * np.sin(arg)).sum(-1)
    ddq = (-a * wl * np.sin(arg) + b * wl * np.cos(arg)).sum(-1)
    ref = traj(t)
    for got, want in zip(ref, (q, dq, ddq), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert traj.period == pytest.approx(T)


def test_a_scenario_takes_the_fourier_kind_and_refuses_a_bad_table():
    sets = ['trajectory={kind = "fourier", period = 4.0, a = [[0.2, 0.1], [0.1, -0.3]], b = [[0.0, 0.1], [0.2, 0.0]]}']
    scenario = load("example-6.3.1", sets)
    assert scenario.setup.trajectory.period == pytest.approx(4.0)
    with pytest.raises(ConfigError) as info:
        load("example-6.3.1", ['trajectory={kind = "fourier", period = 4.0, a = [[0.2, 0.1, 0.3]], b = 0.0}'])
    assert info.value.field == "trajectory.a"
