"""Analytical references, in the paper's nondimensional units (E* = 1/pi).

- Hertz (1882); Johnson, *Contact Mechanics* (1985), Sec. 4.2: P = (4/3) E* sqrt(R) delta^1.5,
  a = sqrt(R delta).
- JKR: Johnson, Kendall & Roberts, Proc. R. Soc. A 324 (1971) 301: F_max = (3/2) pi gamma R,
  critical (force-controlled) radius a_c^3 = 9 pi gamma R^2 / (8 E*).
- LEFM for an elastic body on a rigid one: gamma = K_IC^2 / (2 E*) = pi K_IC^2 / 2, so
  F_max = (3 pi^2 / 4) K_IC^2 R (Maugis, J. Colloid Interface Sci. 150 (1992) 243).
- Kendall flat punch: Kendall, J. Phys. D 4 (1971) 1186: F = sqrt(8 pi a^3 E* gamma).
- Winkler (kernel="local", C_ii = c_w / A): F_max = pi c_w sigma_th^2 R for a paraboloid
  preloaded deeper than c_w sigma_th (docs/physics.md).
- The paper's own fit: F_max = 7.6 K_th^2 R at spacing 1/256 (Hulikal et al., Sec. 4).
"""
from __future__ import annotations

import math

import numpy as np

E_STAR = 1.0 / math.pi          # plane-strain modulus in units of F*/L*^2
PAPER_COEFFICIENT = 7.6          # F_max / (K_th^2 R), the paper's measurement
JKR_COEFFICIENT = 3.0 * math.pi ** 2 / 4.0   # 7.402..., from JKR + LEFM
# Love's regularization of C_ii: 1/r integrated over a unit square (docs/physics.md, section 1,
# the self term), at its centre and averaged over it; the paper uses 3.8.
SELF_TERM_CENTRE = 4.0 * math.log(1.0 + math.sqrt(2.0))                              # 3.5255
SELF_TERM_MEAN = 4.0 * (math.log(1.0 + math.sqrt(2.0)) - (math.sqrt(2.0) - 1.0) / 3.0)   # 2.9732
PAPER_SELF_TERM = 3.8


def hertz_force(delta, radius):
    """Compressive Hertz force of a paraboloid of radius R at indentation delta."""
    delta = np.clip(np.asarray(delta, dtype=float), 0.0, None)
    return 4.0 / 3.0 * E_STAR * math.sqrt(radius) * delta ** 1.5


def hertz_indent(force, radius):
    """The indentation at which the Hertz force equals ``force`` (inverse of hertz_force)."""
    force = np.clip(np.asarray(force, dtype=float), 0.0, None)
    return (3.0 * force / (4.0 * E_STAR * math.sqrt(radius))) ** (2.0 / 3.0)


def flat_punch_force(delta, radius):
    """Boussinesq's rigid flat punch of radius a = R: P = 2 E* a delta (Johnson 1985, Sec. 3.8)."""
    return 2.0 * E_STAR * radius * np.clip(np.asarray(delta, dtype=float), 0.0, None)


def preload_force(shape, delta, radius):
    """The load that presses a smooth body of ``shape`` to ``delta`` without adhesion:
    Boussinesq's flat punch, else Hertz (a sphere as its paraboloid)."""
    return flat_punch_force(delta, radius) if shape == "flat_punch" else hertz_force(delta, radius)


def preload_indent(shape, force, radius):
    """The inverse of ``preload_force``: the depth of a non-adhesive body under ``force``."""
    if shape == "flat_punch":
        return np.clip(np.asarray(force, dtype=float), 0.0, None) / (2.0 * E_STAR * radius)
    return hertz_indent(force, radius)


def hertz_radius(delta, radius):
    delta = np.clip(np.asarray(delta, dtype=float), 0.0, None)
    return np.sqrt(radius * delta)


def gamma_from_k(k_ic):
    """Fracture energy of a rigid/elastic interface with toughness K_IC (LEFM)."""
    return k_ic ** 2 / (2.0 * E_STAR)


def jkr_pull_off(k_ic, radius):
    """JKR maximum tensile force, written with the LEFM toughness: (3 pi^2/4) K^2 R."""
    return 1.5 * math.pi * gamma_from_k(k_ic) * radius


def jkr_critical_radius(k_ic, radius):
    """Contact radius at the JKR force maximum: a_c^3 = 9 pi gamma R^2 / (8 E*)."""
    return (9.0 * math.pi * gamma_from_k(k_ic) * radius ** 2 / (8.0 * E_STAR)) ** (1.0 / 3.0)


def kendall_force(a, gamma):
    """Kendall's pull-off force of a flat punch of radius a."""
    return np.sqrt(8.0 * math.pi * np.asarray(a) ** 3 * E_STAR * gamma)     # arrays too, as the others


def winkler_pull_off(c_w, sigma_th, radius):
    """Exact continuum pull-off force of a paraboloid on a Winkler foundation."""
    return math.pi * c_w * sigma_th ** 2 * radius


def effective_toughness(f_th, spacing):
    """K_IC implied by a spring threshold: sigma_th sqrt(spacing) = F_th / spacing^1.5.

    Equal to k_th at alpha = 0.75 (the paper's LEFM scaling)."""
    return f_th / spacing ** 1.5


def neighbors_foundation_compliance(rings: int, self_term: float, spacing: float) -> float:
    """Displacement per unit uniform pressure of the truncated kernel: spacing * S(m) with
    S(m) = self_term + sum of 1/|k| over lattice points 0 < |k| <= m (S(2) = 12.63 at 3.8)."""
    k = np.arange(-rings, rings + 1)
    r = np.hypot(k[:, None], k[None, :])
    mask = (r > 0) & (r <= rings * (1 + 1e-12))
    return spacing * (self_term + float((1.0 / r[mask]).sum()))


def auto_max_indent_uncapped(p, step_floor: bool = True, step: float | None = None) -> float:
    """``auto_preload_depth``, never shallower than 10 loading steps of ``step`` (default
    ``p.step``; without ``step_floor``: the depth the physics asks for, against which
    tfm.guards measures the step)."""
    depth = auto_preload_depth(p)
    return max(depth, 10.0 * (p.step if step is None else step)) if step_floor else depth


def auto_preload_depth(p) -> float:
    """A preload deep enough that unloading starts beyond the pull-off contact radius.

    Boussinesq: the Hertz radius sqrt(R delta) must exceed the JKR critical radius, so
    delta = (1.5 a_c)^2 / R. Winkler: delta must exceed c_w sigma_th; take twice that.
    A fixed number of neighbour rings acts as a Winkler foundation with the compliance of
    ``neighbors_foundation_compliance``. sigma_th = F_th / A with A the layout's spring
    area (``tfm.threshold``, the threshold's one home).
    """
    if p.kernel == "local":
        delta = 2.0 * p.c_w * threshold_stress(p)
    elif p.kernel == "neighbors":
        delta = 2.0 * neighbors_foundation_compliance(p.neighbor_rings, p.self_term, p.spacing) * threshold_stress(p)
    else:
        delta = (1.5 * run_critical_radius(p)) ** 2 / p.radius
    return delta


def auto_preload_basis(p) -> str:
    """What ``auto_preload_depth`` estimates from, as messages name it."""
    if p.kernel == "local":
        return "the Winkler estimate (twice the depth c_w sigma_th at which springs snap)"
    if p.kernel == "neighbors":
        return "the estimate of the neighbour rings as a Winkler foundation"
    return "the JKR estimate"


def threshold_stress(p) -> float:
    """sigma_th = F_th / A, A the layout's spring area (tfm.threshold, the threshold's home)."""
    from .threshold import nominal_area

    return p.threshold_force / nominal_area(p)


def run_critical_radius(p) -> float:
    """The JKR critical radius a_c of a run's paraboloid (Boussinesq kernel, paper units):
    K_IC = sigma_th sqrt(spacing) (effective_toughness, with the layout's own area)."""
    return jkr_critical_radius(threshold_stress(p) * math.sqrt(p.spacing), p.radius)


def pull_off_estimate(p) -> float:
    """The continuum pull-off force of a run's body and threshold (paper units), the most
    tension a contact can take under force control, whatever the preload: JKR for a sphere
    (the Boussinesq kernel), Kendall for a flat punch of the run's radius, the Winkler
    foundation's for the local and neighbour kernels. A smaller preload leaves a smaller
    contact, which breaks earlier; the model's own coefficient is above JKR's by up to
    some 25 % at coarse resolution (README, "What pull-off to expect in SI")."""
    sigma = threshold_stress(p)
    if p.kernel == "local":
        return winkler_pull_off(p.c_w, sigma, p.radius)
    if p.kernel == "neighbors":
        c_w = neighbors_foundation_compliance(p.neighbor_rings, p.self_term, p.spacing)
        return winkler_pull_off(c_w, sigma, p.radius)
    k_ic = sigma * math.sqrt(p.spacing)
    if p.shape == "flat_punch":
        return float(kendall_force(p.radius, gamma_from_k(k_ic)))
    return jkr_pull_off(k_ic, p.radius)


AUTO_PRELOAD_CAP = 0.5      # times R: never as deep as the sphere itself


def auto_max_indent(p, step_floor: bool = True, step: float | None = None) -> float:
    """``auto_max_indent_uncapped``, capped at 0.5 R (tfm.guards states the cap)."""
    return min(auto_max_indent_uncapped(p, step_floor, step), AUTO_PRELOAD_CAP * p.radius)


def jkr_curve(k_ic, radius, a):
    """JKR force and indentation at contact radius ``a`` (paraboloid on a rigid flat).

    Johnson, *Contact Mechanics* (1985), Sec. 5.5, with gamma = K_IC^2 / (2 E*):
    P = 4 E* a^3 / (3 R) - sqrt(8 pi gamma E* a^3),  delta = a^2 / R - sqrt(2 pi gamma a / E*).
    P is compressive-positive as in the paper's plots. Returns ``(delta, P)``."""
    a = np.asarray(a, dtype=float)
    gamma = gamma_from_k(k_ic)
    force = 4.0 * E_STAR * a ** 3 / (3.0 * radius) - np.sqrt(8.0 * math.pi * gamma * E_STAR * a ** 3)
    delta = a ** 2 / radius - np.sqrt(2.0 * math.pi * gamma * a / E_STAR)
    return delta, force


def preload_is_deep(k_ic, radius, max_indent) -> bool:
    """Whether the Hertz radius at ``max_indent`` reaches the JKR critical radius
    (docs/physics.md, §6)."""
    return math.sqrt(radius * max_indent) >= jkr_critical_radius(k_ic, radius)
