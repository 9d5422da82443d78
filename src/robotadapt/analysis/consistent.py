"""The physically consistent estimate of identification (step 4 of :mod:`robotadapt.analysis.identification`): the
standard φ that fits the weighted data with every link's pseudo-inertia J_i(φ) ⪰ ε𝟙 and every physical scalar ≥ ε
(:mod:`robotadapt.robots.consistency`; Sousa & Cortesão 2014, Wensing, Kim & Slotine 2017), regularised toward the
prior φ₀ by the log-det (entropic, Bregman) divergence of the pseudo-inertias (Lee, Wensing & Park, "Geometric robot
dynamic identification: a convex programming approach", IEEE T-RO 36(2), 2020). A semidefinite program with
exponential cones, solved by cvxpy with Clarabel.

The program, in the data's χ² units (each joint's rows weighted by 1/σ_i, its noise)::

    min_φ  ½ ‖Σ^{-1/2}(W K φ − 𝛕)‖²  +  γ [Σ_links d(J_i(φ) ‖ J_i(φ₀)) + Σ_scalars d(θ_j ‖ θ_j0)]  +  ½ w ‖(φ − φ₀)/s‖²
    s.t.   J_i(φ) ⪰ ε𝟙,  θ_j ≥ ε

- d(J ‖ J₀) = −log det J + log det J₀ + tr(J₀⁻¹ J) − 4, the Bregman divergence of −log det: zero at J = J₀ with zero
  gradient there, convex in J, unbounded as J approaches a singular (flat or massless) body, and unchanged by the units
  (J → T J Tᵀ for any invertible T). Near J₀ it is ½ ‖J₀^{-1/2}(J − J₀)J₀^{-1/2}‖²_F: γ is the precision of a relative
  change of the body, γ = `DIVERGENCE_WEIGHT` = 1 a prior of about ±100 %, against the data's χ², which grows by 1 per
  standard deviation of the estimate. Where a log excites a direction the data outweigh it: on a well-excited log the base
  parameters move from least squares' by about one of their standard deviations (0.86 on tests/test_consistent.py's
  three-joint arm, cond W 40; 1.0 on the Panda's cond-optimal trajectory, σ_τ = 0.1 N·m), less than the noise's own
  error (√b standard deviations), and closer to the truth; what a log sees weakly or not at all stays near the prior's
  bodies (γ = 0.01 does not hold them there, 0.1 does).
- A physical scalar θ (rotor inertia Ia, friction fv, fc, fs, the book's point masses) has the 1 × 1 case,
  d(θ ‖ θ₀) = θ/θ₀ − log(θ/θ₀) − 1.
- A prior that is no body: a link whose prior mass m₀ is positive but whose J₀ is singular (a point mass, a thin rod)
  is compared with the prior's mass spread over a solid sphere of radius `DEFAULT_RADIUS` about its centre of mass,
  J₀ + m₀ r²/5 · diag(1, 1, 1, 0) (where J₀'s second moment about the centre of mass has a negative eigenvalue, a
  prior outside the set, that is first lifted to zero); a link or scalar whose prior mass or value is not positive (a
  model without nominal values, whose prior is zeros; friction a URDF does not give) has no divergence term, only the
  weak pull w (`PRIOR_WEIGHT`, s its unit scale below) that fixes what no data see, and the bound ε.
- Units, so that Clarabel converges ("optimal"): each link's parameters in its prior's mass m₀ and radius of gyration
  ℓ₀ about the link frame (m = m₀ x_m, h = m₀ℓ₀ x_h, I = m₀ℓ₀² x_I: the program's J̃ = T J Tᵀ with T = diag(1/ℓ₀,
  1/ℓ₀, 1/ℓ₀, 1)/√m₀, which leaves d unchanged), each scalar in its prior's value, SI units where there is no prior;
  the data term reduced to b rows (W = QR, then the SVD of R K), with the information on any direction of the scaled
  parameters capped at `INFORMATION_CAP` (no combination known to better than 1e-5 of the prior's scale: noise-free
  data would otherwise weigh 1e24 against the divergence, and the solver stall short of its tolerance).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..robots.consistency import BASIS, Part, parts
from ..robots.identifiability import BaseParameters
from ..validation import ConfigError, require_extra

Array = np.ndarray
PRIOR_WEIGHT = 1e-6  # w: the pull toward φ₀ that fixes the directions no data and no divergence see
DIVERGENCE_WEIGHT = 1.0  # γ: the module docstring, and tests/test_consistent.py for the measurements behind it
DEFAULT_RADIUS = 0.05  # m: the solid sphere a point-mass or rod prior is spread over for the divergence
INFORMATION_CAP = 1e10  # per direction of the scaled parameters: a standard deviation ≥ 1e-5 of the prior's scale
_SINGULAR = 1e-9  # a prior J̃₀ (scaled: mass 1, trace of its 3 × 3 block 1) with a smaller eigenvalue is no body
_E = BASIS.reshape(10, 16).T.copy()  # vec(J) = _E @ (a link's 10 parameters)


class Body(NamedTuple):
    """One link of φ as a rigid body: `mass` (kg), centre of mass `com` (3,) in the link frame (m; NaN where the mass
    is not positive), and `min_eigenvalue`, the smallest eigenvalue of its pseudo-inertia (> 0: a body)."""

    name: str
    mass: float
    com: Array
    min_eigenvalue: float


def bodies(phi: Array, param_names: tuple[str, ...] | list[str]) -> list[Body]:
    """Each link of φ (:func:`~robotadapt.robots.consistency.parts`, 10 parameters) as a :class:`Body`, in φ's order;
    none for a model without links (the book's point masses)."""
    phi = np.asarray(phi, dtype=float)
    out = []
    for part in parts(param_names):
        if len(part.entries) == 10:
            link = phi[list(part.entries)]
            mass = float(link[0])
            com = link[1:4] / mass if mass > 0 else np.full(3, np.nan)
            out.append(Body(part.name, mass, com, float(np.linalg.eigvalsh(_matrix(link))[0])))
    return out


def bodies_table(estimate: Array, prior: Array, param_names: tuple[str, ...] | list[str]) -> list[str]:
    """Markdown lines (a table) of each link's mass, centre of mass and smallest pseudo-inertia eigenvalue, the
    estimate's beside the prior's, for identified.md; no lines for a model without links."""
    rows = list(zip(bodies(estimate, param_names), bodies(prior, param_names), strict=True))
    if not rows:
        return []

    def com(c: Array) -> str:
        return "(" + ", ".join(f"{v:.3g}" for v in c) + ")"

    lines = ["| link | mass (kg) | prior's | centre of mass (m) | prior's | smallest eigenvalue of J | prior's |",
             "|---|---|---|---|---|---|---|"]
    return lines + [f"| {e.name} | {e.mass:.4g} | {p.mass:.4g} | {com(e.com)} | {com(p.com)} | {e.min_eigenvalue:.3g} "
                    f"| {p.min_eigenvalue:.3g} |" for e, p in rows]


def _matrix(link: Array) -> Array:
    """J of a link's 10 parameters (numpy)."""
    return (_E @ link).reshape(4, 4)


@dataclass(frozen=True)
class _Scaled:
    """One part of φ in the program's units, φ[entries] = scale · x: `prior` the prior there (J̃₀ (4, 4) of a link,
    θ₀/s (1,) of a scalar) or None when the part has no divergence, `floor` the bound ε there (ε T Tᵀ of a link)."""

    part: Part
    scale: Array
    prior: Array | None
    floor: Array

    @property
    def is_link(self) -> bool:
        return len(self.part.entries) == 10


def _congruence(J: Array, mass: float, length: float) -> Array:
    """T J Tᵀ with T = diag(1/ℓ, 1/ℓ, 1/ℓ, 1)/√m."""
    t = np.array([1.0 / length] * 3 + [1.0]) / np.sqrt(mass)
    return J * np.outer(t, t)


def _link(J0: Array, epsilon: float) -> tuple[Array, Array | None, Array]:
    """A link's scale (10,), prior J̃₀ (None: the prior mass is not positive) and floor, from its prior J₀."""
    mass = float(J0[3, 3])
    if not mass > 0:  # no prior body: SI units, no divergence
        mass, length, scaled = 1.0, 1.0, None
    else:
        length = float(np.sqrt(max(np.trace(J0[:3, :3]) / mass, 0.0)))
        if length == 0.0 or np.linalg.eigvalsh(_congruence(J0, mass, length))[0] <= _SINGULAR:
            about_com = J0[:3, :3] - np.outer(J0[:3, 3], J0[:3, 3]) / mass  # ∫(x − c)(x − c)ᵀ dm
            lift = max(0.0, -float(np.linalg.eigvalsh(about_com)[0]))  # a prior that is not even a point mass
            J0 = J0 + (mass * DEFAULT_RADIUS**2 / 5.0 + lift) * np.diag([1.0, 1.0, 1.0, 0.0])  # the sphere
            length = float(np.sqrt(np.trace(J0[:3, :3]) / mass))
        scaled = _congruence(J0, mass, length)
    scale = mass * np.array([1.0, length, length, length] + [length**2] * 6)
    return scale, scaled, _congruence(epsilon * np.eye(4), mass, length)


def _plan(param_names: tuple[str, ...] | list[str], prior: Array, epsilon: float) -> tuple[list[_Scaled], Array]:
    """Each part of φ in the program's units, and the scale s (p,) of every parameter (1 outside the parts)."""
    prior = np.asarray(prior, dtype=float)
    scale = np.ones(len(param_names))
    plan = []
    for part in parts(param_names):
        idx = list(part.entries)
        if len(idx) == 10:
            s, J0, floor = _link(_matrix(prior[idx]), epsilon)
            plan.append(_Scaled(part, s, J0, floor))
        else:
            value = float(prior[idx[0]])
            s = np.array([value if value > 0 else 1.0])
            plan.append(_Scaled(part, s, np.ones(1) if value > 0 else None, epsilon / s))
        scale[idx] = s
    return plan, scale


def _pseudo(x: Any) -> Any:
    """J of a link's 10 parameters as a cvxpy expression."""
    import cvxpy as cp

    return cp.reshape(_E @ x, (4, 4), order="C")


def _divergences(x: Any, plan: list[_Scaled]) -> list[Any]:
    """Each part's divergence from its prior, x the parameters in the program's units (a cvxpy expression): d(J ‖ J₀)
    of a link, d(θ ‖ θ₀) of a scalar, none for a part without prior (module docstring)."""
    import cvxpy as cp

    terms = []
    for p in plan:
        if p.prior is None:
            continue
        v = x[list(p.part.entries)]
        if p.is_link:
            J = _pseudo(v)
            terms.append(-cp.log_det(J) + np.linalg.slogdet(p.prior)[1] + cp.trace(np.linalg.inv(p.prior) @ J) - 4.0)
        else:
            r = v[0] / p.prior[0]
            terms.append(r - cp.log(r) - 1.0)
    return terms


def divergence(phi: Array, prior: Array, param_names: tuple[str, ...] | list[str]) -> float:
    """The term γ multiplies, at φ: Σ_links d(J_i(φ) ‖ J_i(φ₀)) + Σ_scalars d(θ_j ‖ θ_j0), the parts without prior left
    out (module docstring), by the expressions the program minimises; ∞ where a part that has one is no body."""
    import cvxpy as cp

    plan, scale = _plan(param_names, prior, 0.0)
    x = np.asarray(phi, dtype=float) / scale
    for p in plan:
        v = x[list(p.part.entries)]
        if p.prior is not None and not (np.linalg.eigvalsh(_matrix(v))[0] if p.is_link else v[0]) > 0:
            return float("inf")
    return float(sum(float(t.value) for t in _divergences(cp.Constant(x), plan)))


def _data_term(basis: BaseParameters, W: Array, tau: Array, sigma: Array, scale: Array) -> tuple[Array, Array]:
    """A, z with ½‖A x − z‖² = ½‖Σ^{-1/2}(W K (s·x) − 𝛕)‖² + const, A of at most b rows: the rows weighted by 1/σ_i,
    QR of [W | 𝛕] (Q never formed), then A = R K diag(s) = U S Vᵀ with the singular values below 1e-12 of the largest
    dropped and the others capped at √`INFORMATION_CAP` (z likewise, so a capped direction keeps its least-squares
    value)."""
    floor = 1e-12 * max(float(np.sqrt(np.mean(tau**2))), 1e-300)  # noise-free data: the weights stay finite
    sigma = np.maximum(np.asarray(sigma, dtype=float), floor)
    b = W.shape[-1]
    rows = np.concatenate([(W / sigma[:, None]).reshape(-1, b), (tau / sigma).reshape(-1, 1)], axis=1)
    Rz = np.asarray(np.linalg.qr(rows, mode="r"))  # [[R, Qᵀ𝛕], [0, ‖residual‖]]
    U, sv, Vt = np.linalg.svd((Rz[:b, :b] @ basis.K) * scale, full_matrices=False)
    keep = sv > 1e-12 * sv[0]
    U, sv, Vt = U[:, keep], sv[keep], Vt[keep]
    capped = np.minimum(sv, np.sqrt(INFORMATION_CAP))
    return capped[:, None] * Vt, capped / sv * (U.T @ Rz[:b, b])


def consistent_estimate(basis: BaseParameters, W: Array, tau: Array, sigma: Array, prior: Array,
                        epsilon: float = 1e-8, prior_weight: float = PRIOR_WEIGHT,
                        divergence_weight: float = DIVERGENCE_WEIGHT) -> tuple[Array, str]:
    """Step 4: the standard φ minimising ½‖Σ^{-1/2}(W K φ − 𝛕)‖² + γ Σ d(J_i(φ) ‖ J_i(φ₀)) + ½ w ‖(φ − φ₀)/s‖²
    subject to J_i(φ) ⪰ ε𝟙 for every link and θ ≥ ε for every physical scalar (module docstring): `W` (N, n, b) the
    base regressor's rows, `tau` (N, n), `sigma` (n,) each joint's noise (its absolute size sets the data's weight
    against the divergence), `prior` φ₀, γ = `divergence_weight` (0: the bound and the weak pull only, the estimate
    before the divergence), w = `prior_weight`. Returns φ and the solver's status: "optimal", or "optimal_inaccurate"
    when Clarabel stopped short of its tolerances (the caller says so)."""
    require_extra("cvxpy", "identify", "--estimate", "the physically consistent estimate", "choose --estimate wls")
    import cvxpy as cp
    if not (np.isfinite(divergence_weight) and divergence_weight >= 0):
        raise ConfigError("--divergence-weight", f"expected a number ≥ 0, got {divergence_weight!r}")
    names = basis.model.param_names
    prior = np.asarray(prior, dtype=float)
    plan, scale = _plan(names, prior, epsilon)
    A, z = _data_term(basis, np.asarray(W, dtype=float), np.asarray(tau, dtype=float), sigma, scale)
    x = cp.Variable(len(names))
    objective = 0.5 * cp.sum_squares(A @ x - z) + 0.5 * prior_weight * cp.sum_squares(x - prior / scale)
    terms = _divergences(x, plan) if divergence_weight > 0 else []
    if terms:
        objective = objective + divergence_weight * sum(terms)
    constraints = [_pseudo(x[list(p.part.entries)]) >> p.floor if p.is_link else x[p.part.entries[0]] >= p.floor[0]
                   for p in plan]
    problem = cp.Problem(cp.Minimize(objective), constraints)
    try:
        with warnings.catch_warnings():  # "optimal_inaccurate" is returned as the status, not printed
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:
        raise ConfigError("--estimate", f"the semidefinite program failed ({exc}); try --estimate wls") from None
    if x.value is None or problem.status not in ("optimal", "optimal_inaccurate"):
        raise ConfigError("--estimate", f"the semidefinite program ended {problem.status}; try --estimate wls")
    return scale * np.asarray(x.value, dtype=float), str(problem.status)
