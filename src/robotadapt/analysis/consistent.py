"""The physically consistent estimate of identification (step 4 of :mod:`robotadapt.analysis.identification`): the
standard φ that fits the weighted data with every link's pseudo-inertia J_i(φ) ⪰ ε𝟙 and every physical scalar ≥ ε
(:mod:`robotadapt.robots.consistency`; Sousa & Cortesão 2014, Wensing, Kim & Slotine 2017), plus a pull toward the prior
φ₀ that fixes the directions no data sees. A semidefinite program, solved by cvxpy with Clarabel."""

from __future__ import annotations

import warnings

import numpy as np

from ..robots.consistency import BASIS, parts
from ..robots.identifiability import BaseParameters
from ..validation import ConfigError

Array = np.ndarray
PRIOR_WEIGHT = 1e-6


def consistent_estimate(basis: BaseParameters, W: Array, tau: Array, sigma: Array, prior: Array,
                        epsilon: float = 1e-8, prior_weight: float = PRIOR_WEIGHT) -> tuple[Array, str]:
    """Step 4: the standard φ minimising ‖Σ^{-1/2}(W K φ − 𝛕)‖ / ‖Σ^{-1/2}𝛕‖ + w · ‖(φ − φ₀)/s‖ / √p, s = |φ₀| + 0.01,
    subject to J_i(φ) ⪰ ε𝟙 for every link and θ ≥ ε for every physical scalar. The data term is reduced to its R factor
    first (W = QR), so the program has b rows whatever the number of samples. Returns φ and the solver's status
    ("optimal", or "optimal_inaccurate" when Clarabel stopped short of its 1e-10 tolerances)."""
    try:
        import cvxpy as cp
    except ModuleNotFoundError:
        raise ConfigError("--estimate", "the physically consistent estimate needs cvxpy: pip install "
                          "'robotadapt[identify]', or choose --estimate wls") from None
    names = basis.model.param_names
    layout = parts(names)
    rel = sigma / np.mean(sigma)  # relative weights only: noise-free data must not divide by zero
    Ww = (W / rel[:, None]).reshape(-1, W.shape[-1])
    tw = (tau / rel).reshape(-1)
    Q, R = np.linalg.qr(Ww)
    z, norm = Q.T @ tw, float(np.linalg.norm(tw))
    A = R @ basis.K
    phi = cp.Variable(len(names))
    scale = np.abs(prior) + 0.01
    objective = (cp.norm(A @ phi - z) / norm
                 + prior_weight * cp.norm(cp.multiply(1 / scale, phi - prior)) / np.sqrt(len(names)))
    constraints = []
    for part in layout:
        idx = list(part.entries)
        if len(idx) == 10:
            J = sum(phi[i] * BASIS[k] for k, i in enumerate(idx))
            constraints.append(J >> epsilon * np.eye(4))
        else:
            constraints.append(phi[idx[0]] >= epsilon)
    problem = cp.Problem(cp.Minimize(objective), constraints)
    try:
        with warnings.catch_warnings():  # "optimal_inaccurate" is returned as the status, not printed
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL, tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    except cp.error.SolverError as exc:
        raise ConfigError("--estimate", f"the semidefinite program failed ({exc}); try --estimate wls") from None
    if phi.value is None or problem.status not in ("optimal", "optimal_inaccurate"):
        raise ConfigError("--estimate", f"the semidefinite program ended {problem.status}; try --estimate wls")
    return np.asarray(phi.value, dtype=float), str(problem.status)
