"""The physically consistent estimate with the log-det divergence toward the prior (analysis/consistent.py, issue item 7
"plausible bodies"): the divergence's value and gradient at the prior, its stand-ins for a prior that is no body, the
estimate held to the prior's bodies where the data do not see them and left to the data where they do, the solver's
status, and `bodies`."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from robotadapt.analysis.consistent import DEFAULT_RADIUS, bodies, bodies_table, consistent_estimate, divergence
from robotadapt.robots.catalog import example_arm, planar
from robotadapt.robots.consistency import parts, pseudo_inertia, smallest_eigenvalues
from robotadapt.robots.identifiability import base_parameters
from robotadapt.trajectories import fourier
from robotadapt.validation import ConfigError

LOCKED = ("panda_joint4", "panda_joint5", "panda_joint6", "panda_joint7")
READY = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]


@pytest.fixture(scope="module")
def arm():
    """The Panda's first three joints (4–7 locked: link 3 carries the rest of the arm) with viscous friction. The truth
    is the URDF's bodies with each link's mass also spread over a 5-cm sphere (every J_i ⪰ 3e-4 𝟙, room on every side)
    and fv = 0.5 N·m·s/rad; the prior the same bodies with masses × 0.8, 1.25, 0.9 (same centres and shapes) and fv =
    0.4, 0.6, 0.45."""
    model = example_arm("panda", locked_joints=LOCKED, viscous=True)
    truth = np.array(model.default_phi, dtype=float)
    for i in range(3):
        truth[10 * i + np.array([4, 6, 9])] += 2 / 5 * truth[10 * i] * 0.05**2  # Ixx, Iyy, Izz of the sphere
    truth[30:] = 0.5
    prior = truth.copy()
    for i, factor in enumerate([0.8, 1.25, 0.9]):
        prior[10 * i:10 * i + 10] *= factor
    prior[30:] = [0.4, 0.6, 0.45]
    return SimpleNamespace(model=model, basis=base_parameters(model), truth=truth, prior=prior)


def log(arm, moving, duration: float, noise: float, amplitude: float = 0.4, seed: int = 0):
    """W (N, n, b), τ (N, n) and σ (n,) as `identify` stacks and estimates them: q a Fourier series of 4 harmonics
    (period 2 s, one fixed draw) on the joints in `moving`, the others held at the ready pose, at 250 Hz for
    `duration` s; τ = Y φ_truth + Gaussian noise of `noise` N·m; σ_i each joint's OLS residual, corrected for b."""
    model, basis = arm.model, arm.basis
    n = model.n
    a, b = np.random.default_rng(3).uniform(-amplitude, amplitude, (2, n, 4))
    mask = np.isin(np.arange(n), list(moving))[:, None]
    ref = fourier(n, 2.0, a * mask, b * mask, READY[:n])(np.arange(0.0, duration, 4e-3))
    W = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des))[..., list(basis.independent)]
    tau = W @ (basis.K @ arm.truth)
    tau = tau + noise * np.random.default_rng(seed).standard_normal(tau.shape)
    ols = np.linalg.lstsq(W.reshape(-1, basis.count), tau.reshape(-1), rcond=None)[0]
    N = W.shape[0]
    sigma = np.sqrt(np.sum((tau - W @ ols) ** 2, axis=0) / N * (N * n) / (N * n - basis.count))
    return W, tau, np.maximum(sigma, 1e-12 * np.sqrt(np.mean(tau**2)))


def mass_ratios(phi, reference, names) -> np.ndarray:
    return np.array([b.mass for b in bodies(phi, names)]) / np.array([b.mass for b in bodies(reference, names)])


def relative_base_error(phi, arm) -> float:
    K = arm.basis.K
    return float(np.linalg.norm(K @ (phi - arm.truth)) / np.linalg.norm(K @ arm.truth))


def test_bodies_gives_each_links_mass_centre_and_smallest_eigenvalue():
    """Hand-computed: link 1 of 2 kg at the frame's origin with I = diag(0.3, 0.4, 0.5) has J = diag(0.3, 0.2, 0.1, 2)
    (Σ = ½ tr(I) 𝟙 − I), so its smallest eigenvalue is 0.1; link 2 of 0.5 kg with h = (0.05, −0.1, 0.2) has its centre
    at (0.1, −0.2, 0.4), and J written out from mass, h and the inertia about the origin; a massless link has no
    centre."""
    names = planar(3).param_names
    phi = np.zeros(30)
    phi[0:10] = [2.0, 0, 0, 0, 0.3, 0, 0.4, 0, 0, 0.5]
    phi[10:20] = [0.5, 0.05, -0.1, 0.2, 0.2, 0.01, 0.3, -0.02, 0.03, 0.25]
    out = bodies(phi, names)
    assert [b.name for b in out] == ["link 1", "link 2", "link 3"]
    assert out[0].mass == 2.0 and np.allclose(out[0].com, 0.0) and out[0].min_eigenvalue == pytest.approx(0.1)
    assert out[1].mass == 0.5 and np.allclose(out[1].com, [0.1, -0.2, 0.4])
    inertia = np.array([[0.2, 0.01, -0.02], [0.01, 0.3, 0.03], [-0.02, 0.03, 0.25]])
    h = np.array([0.05, -0.1, 0.2])
    J = np.block([[0.5 * np.trace(inertia) * np.eye(3) - inertia, h[:, None]], [h[None, :], np.array([[0.5]])]])
    assert out[1].min_eigenvalue == pytest.approx(np.linalg.eigvalsh(J)[0], rel=1e-12)
    assert out[2].mass == 0.0 and np.all(np.isnan(out[2].com)) and out[2].min_eigenvalue == 0.0
    lines = bodies_table(phi, 2 * phi, names)
    assert len(lines) == 2 + 3 and lines[2].startswith("| link 1 | 2 | 4 | (0, 0, 0) | (0, 0, 0) | 0.1 | 0.2 |")
    assert bodies_table([1.0, 2.0], [1.0, 2.0], ("m1", "m2")) == []  # the book's point masses: no links


def test_the_divergence_is_zero_with_zero_gradient_at_the_prior_and_its_closed_form_elsewhere(arm):
    """d(J‖J₀) = −log det J + log det J₀ + tr(J₀⁻¹J) − 4 per link and θ/θ₀ − log(θ/θ₀) − 1 per scalar, by the
    expressions the program minimises: 0 at the prior, central differences in random directions 0 there (dropping
    the trace term would leave −tr(J₀⁻¹ δJ)), positive on either side; at c·φ₀ every part gives c − 1 − log c, × 4
    for a link's 4 × 4 J; at the truth the written-out formula."""
    names, prior = arm.model.param_names, arm.prior
    assert divergence(prior, prior, names) == pytest.approx(0.0, abs=1e-12)
    rng = np.random.default_rng(5)
    h = 1e-6
    for _ in range(5):  # measured: slopes ≤ 1.2e-6 (the third-order term); 4 to 104 without the trace term
        v = rng.standard_normal(prior.size) * (np.abs(prior) + 1e-3)
        up, down = divergence(prior + h * v, prior, names), divergence(prior - h * v, prior, names)
        assert up > 0 and down > 0
        assert abs(up - down) / (2 * h) < 1e-4
        assert (up + down) / 2 > 100 * abs(up - down) / 2  # the curvature, not a slope, makes it positive
    c = 1.3
    assert divergence(c * prior, prior, names) == pytest.approx((4 * 3 + 3) * (c - 1 - np.log(c)), rel=1e-10)
    expected = 0.0
    for part in parts(names):
        idx = list(part.entries)
        if len(idx) == 10:
            J, J0 = pseudo_inertia(arm.truth[idx]), pseudo_inertia(prior[idx])
            expected += (-np.linalg.slogdet(J)[1] + np.linalg.slogdet(J0)[1] + np.trace(np.linalg.solve(J0, J)) - 4)
        else:
            r = arm.truth[idx[0]] / prior[idx[0]]
            expected += r - np.log(r) - 1
    assert divergence(arm.truth, prior, names) == pytest.approx(expected, rel=1e-10)
    bad = prior.copy()
    bad[10] = -1.0  # link 2 without mass: no body
    assert divergence(bad, prior, names) == np.inf


def test_a_point_mass_prior_is_spread_over_a_sphere_and_a_zero_prior_has_no_term():
    """The planar arm's point masses (J₀ singular) are compared with the same mass spread over a solid sphere of radius
    `DEFAULT_RADIUS` (inertia 2/5 m r² about each axis): that body has divergence 0, the point mass itself none finite;
    against a prior of zeros (no nominal values) nothing is compared."""
    model = planar(2)
    names, prior = model.param_names, np.asarray(model.default_phi, dtype=float)
    sphere = prior.copy()
    for i in range(2):
        sphere[10 * i + np.array([4, 6, 9])] += 2 / 5 * prior[10 * i] * DEFAULT_RADIUS**2
    assert divergence(sphere, prior, names) == pytest.approx(0.0, abs=1e-12)
    assert divergence(prior, prior, names) == np.inf
    assert divergence(2 * sphere, prior, names) == pytest.approx(2 * 4 * (1 - np.log(2)), rel=1e-10)
    assert divergence(sphere, np.zeros_like(prior), names) == 0.0


def test_a_prior_outside_the_set_still_gives_a_body(arm):
    """Link 3's prior with Ixx > Iyy + Izz (no body: the triangle inequality broken) has no finite divergence from
    itself, yet the program has a body to compare with (its centre and mass, lifted and spread) and ends optimal with
    every link inside the set."""
    prior = arm.prior.copy()
    prior[24] = 2 * (prior[26] + prior[29])  # Ixx3
    names = arm.model.param_names
    assert np.min(smallest_eigenvalues(prior, parts(names))) < 0
    assert divergence(prior, prior, names) == np.inf
    W, tau, sigma = log(arm, [0, 1], 1.0, 2.0)
    phi, status = consistent_estimate(arm.basis, W, tau, sigma, prior, 1e-8)
    assert status == "optimal"
    assert np.min(smallest_eigenvalues(phi, parts(names))) > 1e-6
    assert np.isfinite(divergence(phi, prior, names))


def test_with_data_worth_nothing_the_divergence_alone_gives_the_prior(arm):
    """σ × 1e8 leaves the data no weight and `prior_weight=0` removes the weak pull: the divergence's minimum, the prior
    itself, is the estimate (a wrong divergence — no trace term, J₀ for J₀⁻¹ — has none there, or none at all)."""
    W, tau, sigma = log(arm, range(3), 2.0, 0.1)
    phi, status = consistent_estimate(arm.basis, W, tau, 1e8 * sigma, arm.prior, 1e-8, prior_weight=0.0)
    assert status == "optimal"
    assert np.max(np.abs(phi - arm.prior)) < 1e-4 * np.max(np.abs(arm.prior))  # Clarabel's 1e-8 on d ≈ ½‖δ‖²
    assert divergence(phi, arm.prior, arm.model.param_names) < 1e-6


def test_a_poorly_excited_log_keeps_every_body_whole_where_the_weak_pull_alone_does_not(arm):
    """Joints 1 and 2 for 1 s with 2 N·m of torque noise (W of rank 9 for 18 base parameters): with the divergence
    (default weight) every link keeps its mass within a factor 2 of the truth and the prior and room inside the set;
    with the weight-1e-6 pull alone the data's noise sets the directions they hardly see, and links go to several times
    their mass, flat on the bound ε (measured: masses × 0.8, 1.26, 1.02 of the truth with the divergence, × 0.8, 3.2,
    5.1 without; smallest eigenvalue 2e-4 against 1e-8)."""
    W, tau, sigma = log(arm, [0, 1], 1.0, 2.0)
    assert np.linalg.matrix_rank(W.reshape(-1, W.shape[-1])) < arm.basis.count
    names, layout = arm.model.param_names, parts(arm.model.param_names)
    held, status = consistent_estimate(arm.basis, W, tau, sigma, arm.prior, 1e-8)
    loose, _ = consistent_estimate(arm.basis, W, tau, sigma, arm.prior, 1e-8, divergence_weight=0.0)
    assert status == "optimal"
    for reference in (arm.truth, arm.prior):
        assert np.all((mass_ratios(held, reference, names) > 0.5) & (mass_ratios(held, reference, names) < 2.0))
    assert np.min(smallest_eigenvalues(held, layout)) >= 1e-6
    assert np.max(mass_ratios(loose, arm.truth, names)) > 3.0
    assert np.min([b.min_eigenvalue for b in bodies(loose, names)]) < 1e-6
    assert relative_base_error(held, arm) < relative_base_error(loose, arm)


def test_on_a_well_excited_log_the_default_weight_moves_the_estimate_by_about_one_standard_deviation(arm):
    """All three joints for 8 s (cond W ≈ 40), 0.1 N·m of noise, the call `identify` makes (positional ε, default
    weight): status optimal, and the base parameters differ from weighted least squares (the unregularised fit) by
    less than 2e-3 of ‖K φ‖ and by less than 2 of its own standard deviations (Mahalanobis distance in its covariance;
    measured 6.6e-4 and 0.86, where the least squares' own error is 3.0 standard deviations, about √b = 4.2), and no
    farther from the truth (measured 8.0e-4 against 1.24e-3)."""
    W, tau, sigma = log(arm, range(3), 8.0, 0.1, amplitude=0.8)
    rows = (W / sigma[:, None]).reshape(-1, W.shape[-1])
    assert np.linalg.cond(rows) < 100
    wls = np.linalg.lstsq(rows, (tau / sigma).reshape(-1), rcond=None)[0]
    phi, status = consistent_estimate(arm.basis, W, tau, sigma, arm.prior, 1e-8)
    assert status == "optimal"
    shift = arm.basis.K @ phi - wls
    assert np.linalg.norm(shift) < 2e-3 * np.linalg.norm(arm.basis.K @ arm.truth)
    assert np.sqrt(shift @ (rows.T @ rows) @ shift) < 2.0
    assert relative_base_error(phi, arm) <= float(np.linalg.norm(wls - arm.basis.K @ arm.truth)
                                                  / np.linalg.norm(arm.basis.K @ arm.truth))


def test_noise_free_data_give_the_base_parameters_with_status_optimal(arm):
    """τ = Y φ exactly: the divergence cannot pull the estimate off the data (their information on each direction is
    capped at 1e10, so Clarabel converges; the pull this leaves is below 1e-9 of ‖K φ‖)."""
    W, tau, sigma = log(arm, range(3), 4.0, 0.0)
    phi, status = consistent_estimate(arm.basis, W, tau, sigma, arm.prior)
    assert status == "optimal"
    assert relative_base_error(phi, arm) < 1e-8


def test_a_negative_weight_is_refused(arm):
    W, tau, sigma = log(arm, range(3), 1.0, 0.1)
    with pytest.raises(ConfigError, match="--divergence-weight"):
        consistent_estimate(arm.basis, W, tau, sigma, arm.prior, divergence_weight=-1.0)


def test_on_the_panda_the_divergence_keeps_the_bodies_of_a_poor_log_and_helps_a_good_one():
    """The 7-joint Panda (panda-slotine-li's model and φ, prior 0.7 φ), 8 s at 250 Hz, 0.1 N·m of noise (about 8 s of
    test). Joints 1, 2 and 4 moving (W of rank 42 for 43 base parameters): the pull alone leaves link 6 at 0.24 of its
    mass and links on the bound, the divergence keeps every mass within 0.70–1.09 of the truth and cuts the base error
    from 0.020 to 0.0042. Every joint moving (cond W ≈ 380): the pull alone puts a link at 34 times its mass, the
    divergence keeps 0.70–1.09 and halves the base error (0.0049 against 0.0107). Status optimal with the divergence."""
    from robotadapt.studies.scenarios import load

    setup = load("panda-slotine-li").setup
    model = setup.controller.model
    panda = SimpleNamespace(model=model, basis=base_parameters(model), truth=np.asarray(setup.plant.phi, dtype=float))
    prior = 0.7 * panda.truth
    names = model.param_names
    W, tau, sigma = log(panda, [0, 1, 3], 8.0, 0.1)
    held, status = consistent_estimate(panda.basis, W, tau, sigma, prior, 1e-8)
    loose, _ = consistent_estimate(panda.basis, W, tau, sigma, prior, 1e-8, divergence_weight=0.0)
    assert status == "optimal"
    assert np.all((mass_ratios(held, panda.truth, names) > 0.6) & (mass_ratios(held, panda.truth, names) < 1.2))
    assert np.min(mass_ratios(loose, panda.truth, names)) < 0.5
    W, tau, sigma = log(panda, range(7), 8.0, 0.1)
    good, status = consistent_estimate(panda.basis, W, tau, sigma, prior, 1e-8)
    free, _ = consistent_estimate(panda.basis, W, tau, sigma, prior, 1e-8, divergence_weight=0.0)
    assert status == "optimal"
    assert np.all((mass_ratios(good, panda.truth, names) > 0.6) & (mass_ratios(good, panda.truth, names) < 1.2))
    assert np.max(mass_ratios(free, panda.truth, names)) > 2.0
    assert relative_base_error(good, panda) < 0.7 * relative_base_error(free, panda)
