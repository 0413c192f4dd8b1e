"""The tensile threshold F_th of each spring: the one home of the formula.

Paper (Sec. 2): a spring in contact snaps when its tensile force exceeds
F_th = K_th A^alpha, with A the spring's tributary area; or an explicit F_th is given.
The tributary area depends on the layout (Delta^2 on the square and jittered grids,
sqrt(3)/2 Delta^2 on the hexagonal one), so the mean threshold does too.

In SI units (``units="si"``) K_th follows from the work of adhesion by the paper's last
equation (``tfm.units.k_th_si``) and F_th is in newtons.

Disorder (``threshold_disorder``): F_th,i = mean F_th * xi_i with independent xi_i of
mean 1 and standard deviation ``disorder_width`` (the coefficient of variation), drawn
in spring order from ``numpy.random.default_rng(disorder_seed)``:

- "uniform": xi uniform on [1 - sqrt(3) w, 1 + sqrt(3) w] (w <= 1/sqrt(3): F_th >= 0);
- "weibull": xi = W / Gamma(1 + 1/m) with W a standard Weibull variable of modulus m,
  the m whose coefficient of variation is w (m = 1 at w = 1, m ~ pi/(sqrt(6) w) = 1.28/w for small w).
  The weakest-link distribution of brittle strength; its lower tail pins crack fronts.

Random thresholds make the crack front of the pull-off a pinned elastic line, the
setting of the ContactEngineering CrackFront code (Sanner & Pastewka, J. Mech. Phys.
Solids 160 (2022) 104781). The same seed and layout give the same thresholds.
"""
from __future__ import annotations

import math

import numpy as np


def nominal_area(p) -> float:
    """Tributary area of one spring of the layout (the same for every spring)."""
    if p.layout == "hexagonal":
        return math.sqrt(3.0) / 2.0 * p.spacing ** 2
    return p.spacing ** 2


def _k_th(p) -> float:
    if p.units == "si":
        from .units import k_th_si
        return k_th_si(p)
    return float(p.k_th)


def mean_threshold(p) -> float:
    """F_th of a spring of the layout's nominal area (the summary's ``f_th``)."""
    if p.f_th is not None:
        return float(p.f_th)
    return _k_th(p) * nominal_area(p) ** p.alpha


def threshold_forces(p, area: np.ndarray) -> np.ndarray:
    """F_th per spring, from each spring's own tributary area, times its disorder."""
    if p.f_th is not None:
        f = np.full(area.size, float(p.f_th))
    else:
        f = _k_th(p) * np.asarray(area, dtype=float) ** p.alpha
    if p.threshold_disorder != "none":
        f = f * disorder_factors(p.threshold_disorder, p.disorder_width, p.disorder_seed, f.size)
    return f


def weibull_modulus(width: float) -> float:
    """The Weibull modulus m whose coefficient of variation is ``width``:
    Gamma(1 + 2/m) / Gamma(1 + 1/m)^2 - 1 = width^2 (decreasing in m)."""
    from scipy.optimize import brentq
    from scipy.special import gammaln

    def excess(log_m):
        m = math.exp(log_m)
        return math.expm1(gammaln(1 + 2 / m) - 2 * gammaln(1 + 1 / m)) - width ** 2
    return math.exp(brentq(excess, math.log(0.2), math.log(1e4), xtol=1e-14))


def disorder_factors(kind: str, width: float, seed: int, n: int) -> np.ndarray:
    """n independent factors of mean 1 and standard deviation ``width`` (see module)."""
    rng = np.random.default_rng(seed)
    if kind == "uniform":
        half = math.sqrt(3.0) * width
        return rng.uniform(1.0 - half, 1.0 + half, size=n)
    if kind == "weibull":
        m = weibull_modulus(width)
        return rng.weibull(m, size=n) / math.gamma(1.0 + 1.0 / m)
    raise ValueError(f"threshold_disorder: unknown kind {kind!r}")
