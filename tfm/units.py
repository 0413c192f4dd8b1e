"""Physical units: SI <-> the paper's nondimensional units, and K_th from the work of adhesion.

The paper (Hulikal, Bhattacharya & Lapusta, Sec. 2 and its last equation) measures
lengths in L* and forces in F* = 2 pi G L*^2 / (1 - nu) = pi E* L*^2, with
E* = E / (1 - nu^2) = 2 G / (1 - nu); then C_ij = 1/r_ij. Its fit
F_max = c K_th^2 R (c = 7.6) with the JKR pull-off F_max = (3/2) pi gamma R gives

    K_th = pi sqrt(3 G gamma / (c (1 - nu)))            (SI: Pa m^(1/2))

for the threshold F_th = K_th A^(3/4) (alpha = 0.75, the LEFM scaling; other alphas make
the relation depend on the spacing, so an SI run with ``work_of_adhesion`` needs
alpha = 0.75). ``k_th_coefficient`` is c: a number, or a name from
``K_TH_COEFFICIENTS`` ("paper" = 7.6, the paper's fit at spacing 1/256; "jkr" =
3 pi^2/4, the continuum JKR/LEFM value), or "limit", this model's measured continuum
limit for the run's self term (``LIMIT_COEFFICIENTS``). With c equal to the coefficient
the model actually shows at the run's resolution, the pull-off equals (3/2) pi gamma R.

An SI run is solved as a paper-units run with L* = 1 m: lengths keep their numbers (in
metres), forces are divided by F* = pi E* (1 m)^2, and K_th becomes
K_th (1 - nu) / (2 pi G) (per m^(1/2)). The model is scale-free, so the choice of L*
changes no result; 1 m keeps every length's number as the user wrote it.
"""
from __future__ import annotations

import math

from .theory import JKR_COEFFICIENT, PAPER_COEFFICIENT

#: named values of k_th_coefficient (c in F_max = c K_th^2 R). Add a name here to make
#: it selectable.
K_TH_COEFFICIENTS: dict[str, float] = {
    "paper": PAPER_COEFFICIENT,
    "jkr": JKR_COEFFICIENT,
}

#: k_th_coefficient = "limit": this model's own continuum limit c_inf of F_max/(K_th^2 R),
#: measured per self term by `make limit` (results/limit/summary.json, paraboloid fits,
#: alpha = 0.75, a_c/Delta up to 256 at every self term;
#: tests/test_units.py keeps the two in step). It depends on the self term, and it may
#: move as the campaign is refined, so a record stores the number, not the name
#: (tfm.params).
LIMIT_COEFFICIENTS: dict[float, float] = {
    2.9732: 5.634,
    3.5255: 7.022,
    3.8: 7.692,
}


def limit_coefficient(self_term: float) -> float:
    """c_inf measured for this self term (``k_th_coefficient = "limit"``)."""
    for s, c in LIMIT_COEFFICIENTS.items():
        if abs(self_term - s) <= 1e-9 * s:
            return c
    known = ", ".join(f"{s:g}" for s in LIMIT_COEFFICIENTS)
    raise ValueError(f"k_th_coefficient: 'limit' is measured only for self_term in {{{known}}}, "
                     f"got self_term = {self_term!r}; give the coefficient as a number")

#: L* of an SI run, in metres
LENGTH_SCALE_SI = 1.0

#: units of the curve and summary columns, per unit system. Every curve column and
#: summary value that carries a dimension is listed (tests/test_units.py derives the
#: columns from a run); counts and relative quantities (max_residual) have none. An SI
#: run's "force" columns are those scaled to newtons (``to_si_curve``, ``to_si_summary``).
COLUMN_UNITS = {
    "paper": {"length": "L* (paper units)", "force": "F* = 2 pi G L*^2/(1 - nu)", "area": "L*^2", "time": "s",
              "columns": {"d": "length", "indent": "length", "force": "force",
                          "contact_area": "area", "contact_radius": "length",
                          "pull_off_force": "force", "pull_off_indent": "length",
                          "pull_off_contact_radius": "length", "max_indent": "length",
                          "jump_off_force": "force", "jump_off_indent": "length",
                          "jump_off_contact_radius": "length",
                          "f_th": "force", "max_force": "force", "max_contact_radius": "length",
                          "first_snap_indent": "length", "half_width": "length", "wall_time": "time"}},
    "si": {"length": "m", "force": "N", "area": "m^2", "time": "s"},
}
COLUMN_UNITS["si"]["columns"] = COLUMN_UNITS["paper"]["columns"]
#: the parameters (a campaign's p_* columns) that carry a dimension, in the same systems;
#: k_th (paper units only) is F* per L*^(2 alpha), since F_th = K_th A^alpha, and E and
#: gamma exist only in SI. The others are dimensionless (tests/test_units.py checks that
#: every float parameter is in one list or the other).
_PARAMETER_LENGTHS = ("spacing", "radius", "extent", "max_indent", "step", "rms_height",
                      "short_cutoff", "long_cutoff", "map_pixel_size")
_PARAMETER_FORCES = ("f_th", "max_load", "load_step")
_DIMENSIONED = {**dict.fromkeys(_PARAMETER_LENGTHS, "length"), **dict.fromkeys(_PARAMETER_FORCES, "force")}
COLUMN_UNITS["paper"]["parameters"] = {**_DIMENSIONED, "k_th": "k_th"}
COLUMN_UNITS["paper"]["k_th"] = "F*/L*^(2 alpha)"
COLUMN_UNITS["si"]["parameters"] = {**_DIMENSIONED, "youngs_modulus": "modulus",
                                    "work_of_adhesion": "work_of_adhesion"}
COLUMN_UNITS["si"]["modulus"] = "Pa"
COLUMN_UNITS["si"]["work_of_adhesion"] = "J/m^2"
FORCE_COLUMNS = tuple(k for k, dim in COLUMN_UNITS["paper"]["columns"].items() if dim == "force")


def resolve_coefficient(value) -> float:
    """c from a number or a name of ``K_TH_COEFFICIENTS``."""
    if isinstance(value, str):
        try:
            return K_TH_COEFFICIENTS[value]
        except KeyError:
            raise ValueError(f"k_th_coefficient: unknown name {value!r}; "
                             f"known: {', '.join(K_TH_COEFFICIENTS)}, or a number") from None
    return float(value)


def shear_modulus(youngs_modulus: float, poisson_ratio: float) -> float:
    return youngs_modulus / (2.0 * (1.0 + poisson_ratio))


def plane_strain_modulus(youngs_modulus: float, poisson_ratio: float) -> float:
    """E* = E / (1 - nu^2) of an elastic body pressed by a rigid one."""
    return youngs_modulus / (1.0 - poisson_ratio ** 2)


def force_scale(p) -> float:
    """F* = 2 pi G L*^2 / (1 - nu) in newtons for an SI run (1 for paper units)."""
    if p.units != "si":
        return 1.0
    G = shear_modulus(p.youngs_modulus, p.poisson_ratio)
    return 2.0 * math.pi * G * LENGTH_SCALE_SI ** 2 / (1.0 - p.poisson_ratio)


def k_th_from_work_of_adhesion(work_of_adhesion: float, youngs_modulus: float,
                               poisson_ratio: float, coefficient=PAPER_COEFFICIENT) -> float:
    """The paper's last equation: K_th = pi sqrt(3 G gamma / (c (1 - nu))), in Pa m^(1/2)."""
    c = resolve_coefficient(coefficient)
    G = shear_modulus(youngs_modulus, poisson_ratio)
    return math.pi * math.sqrt(3.0 * G * work_of_adhesion / (c * (1.0 - poisson_ratio)))


def k_th_si(p) -> float:
    """K_th of an SI run (Pa m^(1/2))."""
    return k_th_from_work_of_adhesion(p.work_of_adhesion, p.youngs_modulus, p.poisson_ratio,
                                      p.k_th_coefficient)


def jkr_pull_off_si(work_of_adhesion: float, radius: float) -> float:
    """(3/2) pi gamma R, in newtons."""
    return 1.5 * math.pi * work_of_adhesion * radius


def to_paper(p, **overrides):
    """The same run in the paper's units (L* = 1 m): an SI record's twin that the solver
    runs, with ``overrides`` of its fields. A paper-units record is returned as it is."""
    if p.units != "si":
        return p
    F = force_scale(p)
    changes = dict(units="paper", youngs_modulus=None, poisson_ratio=None, work_of_adhesion=None,
                   k_th_coefficient="paper")
    if p.work_of_adhesion is not None:
        # F_th = K A^0.75 in N  ->  F_th / F* = (K L*^1.5 / F*) (A / L*^2)^0.75
        changes.update(k_th=k_th_si(p) * LENGTH_SCALE_SI ** 1.5 / F, f_th=None)
    else:
        changes.update(f_th=p.f_th / F, k_th=None)
    # force control: the loads are forces too
    if p.max_load is not None:
        changes["max_load"] = p.max_load / F
    if p.load_step is not None:
        changes["load_step"] = p.load_step / F
    changes.update(overrides)
    import dataclasses
    return dataclasses.replace(p, **changes)


def _forces_to_si(table, p):
    """A copy of the paper twin's curve (DataFrame) or summary (dict) with its force
    columns in newtons; lengths and areas keep their numbers (L* = 1 m)."""
    out = table.copy()
    F = force_scale(p)
    for key in FORCE_COLUMNS:
        if key in out:
            out[key] = out[key] * F
    return out


def to_si_curve(curve, p):
    """Scale a paper-units curve (L* = 1 m) of the twin of SI record ``p`` to SI."""
    return _forces_to_si(curve, p)


def to_si_summary(summary: dict, p) -> dict:
    """Scale the summary of the twin of SI record ``p`` to SI."""
    return _forces_to_si(summary, p)


def unit_suffixes(p) -> tuple[str, str]:
    """(length, force) units after a number: " m", " N" for an SI run, none in paper units."""
    return (" m", " N") if p is not None and p.units == "si" else ("", "")


def unit_labels(p) -> dict:
    """What the run's curve and summary are measured in (for the tables' metadata)."""
    return {"system": p.units, **COLUMN_UNITS[p.units]}
