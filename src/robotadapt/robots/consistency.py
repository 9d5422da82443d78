"""Physical consistency of a parameter vector φ (docs/arms.md#physical-consistency; issue "Physically consistent
adaptation").

A link's 10 standard parameters (`LINK_PARAMS`: m, h = m·c, I about the link frame's origin) map linearly to its 4×4
pseudo-inertia (Wensing, Kim & Slotine, RA-L 2017)::

    J = [[½ tr(I) 𝟙 − I, h], [hᵀ, m]] = ∫ [x; 1][x; 1]ᵀ dm(x)

and the link is a real body (mass, centre of mass and inertia with the triangle inequalities) iff J ≻ 0. The other
parameters of the project's models are physical scalars that a body keeps non-negative: the book's point masses (m1,
m2, m), rotor inertias (Ia), viscous, Coulomb and smooth-Coulomb coefficients (fv, fc, fs, b). The "smallest eigenvalue"
of such a part is its value. φ is consistent when every part's smallest eigenvalue is ≥ 0: on the closure of the set,
so that the book's φ̂(0) = 0 (no mass yet) counts, and a part below zero has left it. A constant torque offset (off)
has either sign: it is no part (:func:`unformed`), so no bound holds it.
"""

from __future__ import annotations

import re
from typing import Any, NamedTuple

import numpy as np

from ..arrays import array_namespace
from .dh import LINK_PARAMS

Array = Any
_LINK = re.compile(rf"^({'|'.join(LINK_PARAMS)})(\d+)$")
# the models' scalar physical parameters, ≥ 0: point masses, rotor inertias, viscous, Coulomb and smooth-Coulomb
# friction, joint stiffness (not a torque offset "off1", which has either sign)
_SCALAR = re.compile(r"^(m|Ia|fv|fc|fs|b|k)\d*$")


def _basis() -> Array:
    """J of each unit parameter vector: J(v) = Σ_k v_k E_k, `(10, 4, 4)`."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = np.eye(len(LINK_PARAMS))
    inertia = np.stack([np.stack([ixx, ixy, ixz], -1), np.stack([ixy, iyy, iyz], -1), np.stack([ixz, iyz, izz], -1)], -2)
    sigma = 0.5 * (ixx + iyy + izz)[:, None, None] * np.eye(3) - inertia
    h = np.stack([hx, hy, hz], -1)
    return np.concatenate([np.concatenate([sigma, h[:, :, None]], -1), np.concatenate([h, m[:, None]], -1)[:, None, :]], -2)


BASIS = _basis()
# the dual basis: tr(E_k F_j) = δ_kj, so v_k = tr(F_k J(v)) and B = Σ_k b_k F_k is the symmetric matrix with
# tr(J(v) B) = vᵀb for every v (the natural law's B, docs/natural.md)
DUAL = np.einsum("jk,kab->jab", np.linalg.inv(np.einsum("kab,jba->kj", BASIS, BASIS)), BASIS)


def pseudo_inertia(link: Array) -> Array:
    """J of a link's 10 parameters `(..., 10)` in `LINK_PARAMS` order, `(..., 4, 4)`, in the namespace of `link`."""
    return array_namespace(link).einsum("...k,kab->...ab", link, BASIS)


def link_parameters(J: Array) -> Array:
    """The 10 parameters of a pseudo-inertia `(..., 4, 4)`: the inverse of :func:`pseudo_inertia`."""
    return array_namespace(J).einsum("...ab,kab->...k", J, DUAL)


class Part(NamedTuple):
    """A part of φ that is checked as one: a link (10 entries, J ≻ 0) or a scalar (≥ 0); `name` as reported."""

    name: str
    entries: tuple[int, ...]


def parts(param_names: tuple[str, ...] | list[str]) -> list[Part]:
    """φ's parts by its parameter names: every complete set of `LINK_PARAMS` with one link number is a link, a mass,
    rotor inertia, friction coefficient or stiffness (`m2`, `Ia3`, `fv1`, `fc1`, `fs1`, `b`, `k`) a scalar. Other
    parameters (base-parameter combinations, a torque offset `off1`, which has either sign) have no physical form:
    :func:`unformed` names them."""
    links: dict[str, dict[str, int]] = {}
    for k, name in enumerate(param_names):
        match = _LINK.match(name)
        if match:
            links.setdefault(match[2], {})[match[1]] = k
    out: list[Part] = []
    used: set[int] = set()
    for number, found in links.items():
        if len(found) == len(LINK_PARAMS):
            index = tuple(found[p] for p in LINK_PARAMS)
            out.append(Part(f"link {number}", index))
            used.update(index)
    out += [Part(name, (k,)) for k, name in enumerate(param_names) if k not in used and _SCALAR.match(name)]
    return out


def unformed(param_names: tuple[str, ...] | list[str]) -> list[str]:
    """The parameters that belong to no part of :func:`parts` (no pseudo-inertia or positive-scalar form)."""
    used = {k for part in parts(param_names) for k in part.entries}
    return [name for k, name in enumerate(param_names) if k not in used]


def smallest_eigenvalues(phi: Array, layout: list[Part]) -> Array:
    """The smallest eigenvalue of each part of φ `(..., p)`: of J for a link, the value for a scalar; `(..., parts)`."""
    phi = np.asarray(phi, dtype=float)
    columns = [np.linalg.eigvalsh(pseudo_inertia(phi[..., list(part.entries)]))[..., 0] if len(part.entries) == 10
               else phi[..., part.entries[0]] for part in layout]
    return np.stack(columns, -1) if columns else np.zeros(phi.shape[:-1] + (0,))


def consistency_metrics(t: Array, phi_hat: Array, param_names: tuple[str, ...] | list[str]) -> dict[str, Any]:
    """metrics.json's keys for the estimates φ̂(t) `(T, p)`: `min_pseudo_inertia_eigenvalue` (over parts and time),
    `physically_consistent` (every part ≥ 0 at every sample), `left_consistent_set_t` and `left_consistent_set_part`
    (the first sample where a part went below zero, or None) and `final_min_eigenvalues` at the end, one per part of
    `consistency_parts`. Empty for a law without φ̂."""
    layout = parts(param_names)
    if not layout or np.shape(phi_hat)[-1] == 0:
        return {}
    lows = smallest_eigenvalues(phi_hat, layout)
    bad = np.argwhere(lows < 0.0)
    left = bad.size > 0
    return {"min_pseudo_inertia_eigenvalue": float(lows.min()), "physically_consistent": not left,
            "left_consistent_set_t": float(t[bad[0, 0]]) if left else None,
            "left_consistent_set_part": layout[int(bad[0, 1])].name if left else None,
            "consistency_parts": [part.name for part in layout],
            "final_min_eigenvalues": [float(v) for v in lows[-1]]}
