"""Fits, exponents and convergence measures for the paper's scaling claims.

Hulikal, Bhattacharya & Lapusta, "A threshold-force model for adhesion and mode I
fracture", Sec. 3-4 (see ``docs/physics.md``):

- ``F_max ~ K_th^beta`` with beta = 2 and ``F_max ~ R^gamma`` with gamma = 1 (JKR);
- ``F_max ~ spacing^(4 alpha - 3)`` for the Boussinesq kernel, so alpha = 0.75 converges;
- ``F_max ~ spacing^(4 alpha - 4)`` for the local (Winkler) kernel, so alpha = 1 converges.

Every fit is ordinary least squares in log-log space with a Student-t confidence
interval on n - 2 degrees of freedom (n - 1 for a line through the origin). With two
points a power law is determined exactly and its interval is infinite: a measured
exponent from two runs carries no statistical error bar, only the physics' tolerance.
Pure functions on arrays and DataFrames; nothing here runs a simulation or writes a file.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd
from scipy import optimize, stats

CONFIDENCE = 0.95


@dataclass(frozen=True)
class PowerLawFit:
    """``y = prefactor * x**exponent`` fitted in log-log space."""

    exponent: float
    exponent_stderr: float
    ci_low: float
    ci_high: float
    prefactor: float
    n: int
    r2: float
    confidence: float = CONFIDENCE

    @property
    def ci(self) -> tuple[float, float]:
        return (self.ci_low, self.ci_high)

    @property
    def half_width(self) -> float:
        return 0.5 * (self.ci_high - self.ci_low)

    def predict(self, x):
        return self.prefactor * np.asarray(x, dtype=float) ** self.exponent

    def contains(self, value: float) -> bool:
        return self.ci_low <= value <= self.ci_high

    def text(self, digits: int = 3) -> str:
        if math.isfinite(self.half_width):
            return f"{self.exponent:.{digits}f} ± {self.half_width:.{digits}f}"
        return f"{self.exponent:.{digits}f} (2 points: no CI)"

    def to_dict(self) -> dict:
        return asdict(self)


class _Interval:
    """An estimate ``value`` with a confidence interval [ci_low, ci_high]."""

    value_name = "value"

    @property
    def half_width(self) -> float:
        return 0.5 * (self.ci_high - self.ci_low)

    def text(self, digits: int = 3) -> str:
        value = getattr(self, self.value_name)
        if math.isfinite(self.half_width):
            return f"{value:.{digits}f} ± {self.half_width:.{digits}f}"
        return f"{value:.{digits}f} (no CI)"


@dataclass(frozen=True)
class LineFit(_Interval):
    """``y = slope * x`` (through the origin) or ``y = intercept + slope * x``."""

    value_name = "slope"
    slope: float
    slope_stderr: float
    ci_low: float
    ci_high: float
    intercept: float
    n: int
    confidence: float = CONFIDENCE


def _check_confidence(confidence, who: str) -> None:
    """A confidence level is a probability: 95 for 0.95 gave NaN intervals, without a word."""
    if isinstance(confidence, bool) or not isinstance(confidence, numbers.Real) or not 0.0 < confidence < 1.0:
        raise ValueError(f"{who}: confidence must be in (0, 1), e.g. 0.95, got {confidence!r}")


def _t_quantile(dof: int, confidence: float) -> float:
    if dof <= 0:
        return math.inf
    return float(stats.t.ppf(0.5 + confidence / 2.0, dof))


def _clean(x, y, who: str, names: tuple[str, str] = ("x", "y")):
    """x and y as float arrays of one shape, every value finite: a NaN or inf would
    otherwise pass the sign checks and come out as a NaN fit (with r2 = 1)."""
    x, y = (_numbers(v, who, name) for v, name in zip((x, y), names))
    if x.shape != y.shape:
        raise ValueError(f"{who}: {names[0]} and {names[1]} must have the same shape, got {x.shape} and {y.shape}")
    if x.ndim > 1:                       # a table's columns given as a 2-D array were flattened into one fit
        raise ValueError(f"{who}: {names[0]} and {names[1]} must be one-dimensional, got shape {x.shape}")
    for name, v in zip(names, (x, y)):
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise ValueError(f"{who}: {name} must be finite, got {v[bad[0]]} at index {bad[0]}")
    return x, y


def _numbers(v, who: str, name: str) -> np.ndarray:
    try:
        return np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:       # NumPy's own message names neither
        raise ValueError(f"{who}: {name} must be numbers ({exc})") from None


def _curve(curve, who: str, columns: tuple[str, ...]) -> pd.DataFrame:
    """One run's curve table (a DataFrame, or columns by name), with rows and ``columns``."""
    if not isinstance(curve, pd.DataFrame):
        try:
            curve = pd.DataFrame(curve)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{who}: expected one run's curve table (a DataFrame), got "
                             f"{type(curve).__name__} ({exc})") from None
    missing = [c for c in columns if c not in curve.columns]
    if missing:
        raise ValueError(f"{who}: the curve lacks the column{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(missing)} (one run's curve table has them)")
    if len(curve) == 0:
        raise ValueError(f"{who}: the curve has no rows")
    return curve


def _two_distinct(x: np.ndarray, who: str, name: str = "x") -> None:
    """Refuse x with fewer than two distinct values: a fitted slope needs two."""
    if x.size < 2:
        raise ValueError(f"{who}: need at least two points, got {x.size}")
    if np.unique(x).size < 2:
        raise ValueError(f"{who}: need at least two distinct {name}, all are {x[0]:g}")


def _positive(x, y, who: str, names: tuple[str, str] = ("x", "y")):
    """``_clean`` for a log-log fit: points with x <= 0 or y <= 0 have no logarithm."""
    x, y = _clean(x, y, who, names)
    if np.any(x <= 0) or np.any(y <= 0):
        raise ValueError(f"{who}: {names[0]} and {names[1]} must be > 0 (log-log)")
    return x, y


def fit_power_law(x, y, confidence: float = CONFIDENCE) -> PowerLawFit:
    """OLS fit of ln y = ln c + exponent ln x, with a Student-t interval on the exponent.

    Points with x <= 0 or y <= 0 have no logarithm and are refused (drop them first,
    e.g. the k_th = 0 run of the paper's Fig. 6a)."""
    _check_confidence(confidence, "fit_power_law")
    x, y = _positive(x, y, "fit_power_law")
    _two_distinct(x, "fit_power_law")
    n = x.size
    lx, ly = np.log(x), np.log(y)
    sxx = float(np.sum((lx - lx.mean()) ** 2))
    slope = float(np.sum((lx - lx.mean()) * (ly - ly.mean())) / sxx)
    inter = float(ly.mean() - slope * lx.mean())
    resid = ly - (inter + slope * lx)
    dof = n - 2
    if dof > 0:
        s2 = float(np.sum(resid ** 2)) / dof
        se = math.sqrt(s2 / sxx)
    else:
        se = math.inf
    half = _t_quantile(dof, confidence) * se if dof > 0 else math.inf
    sst = float(np.sum((ly - ly.mean()) ** 2))
    r2 = 1.0 - float(np.sum(resid ** 2)) / sst if sst > 0 else 1.0
    return PowerLawFit(slope, se, slope - half, slope + half, math.exp(inter), n, r2, confidence)


def fit_line(x, y, through_origin: bool = False, confidence: float = CONFIDENCE) -> LineFit:
    """OLS straight line with a Student-t interval on the slope.

    A free line needs two distinct x, one through the origin one x != 0; with exactly
    that many the line is determined and its interval is infinite."""
    _check_confidence(confidence, "fit_line")
    x, y = _clean(x, y, "fit_line")
    n = x.size
    if through_origin:
        if not np.any(x != 0):
            raise ValueError(f"fit_line: a line through the origin needs an x != 0, got {n} points at x = 0")
        sxx = float(np.sum(x * x))
        slope = float(np.sum(x * y) / sxx)
        inter = 0.0
        dof = n - 1
        resid = y - slope * x
    else:
        _two_distinct(x, "fit_line")
        sxx = float(np.sum((x - x.mean()) ** 2))
        slope = float(np.sum((x - x.mean()) * (y - y.mean())) / sxx)
        inter = float(y.mean() - slope * x.mean())
        dof = n - 2
        resid = y - inter - slope * x
    se = math.sqrt(float(np.sum(resid ** 2)) / dof / sxx) if dof > 0 else math.inf
    half = _t_quantile(dof, confidence) * se if dof > 0 else math.inf
    return LineFit(slope, se, slope - half, slope + half, inter, n, confidence)


def spacing_slope(spacing, f_max, confidence: float = CONFIDENCE) -> PowerLawFit:
    """d ln F_max / d ln spacing over a refinement series (Boussinesq: 4 alpha - 3)."""
    return fit_power_law(spacing, f_max, confidence)


#: the smallest relative step between two spacings that convergence_ratios takes as a
#: refinement (the finest studies halve or take cube roots of 2: 26 %)
MIN_SPACING_STEP = 0.01


def convergence_ratios(spacing, values) -> pd.DataFrame:
    """Successive refinement ratios: F(finer)/F(coarser) and the local slope between them.

    Rows are sorted from the coarsest spacing to the finest. ``local_slope`` is
    ln(F_i+1 / F_i) / ln(spacing_i+1 / spacing_i), the two-point estimate of the exponent.
    One value per spacing: several runs at one spacing (seeds) have no ratio between
    them, and which of them to pair with the next spacing is the caller's choice, so
    they are refused; average them first (e.g. ``groupby(spacing).mean()``)."""
    s, v = _positive(spacing, values, "convergence_ratios", ("spacing", "values"))
    uniq, counts = np.unique(s, return_counts=True)
    if np.any(counts > 1):
        dup = ", ".join(f"{fraction_text(x)} ({c} values)" for x, c in zip(uniq, counts) if c > 1)
        raise ValueError(f"convergence_ratios: spacing repeats: {dup}; average the runs at one spacing "
                         "(e.g. over seeds) first")
    # two spacings a rounding apart (1/48 and 0.0208333) gave a local slope of -6219
    close = np.flatnonzero(uniq[1:] / uniq[:-1] < 1 + MIN_SPACING_STEP)
    if close.size:
        a, b = uniq[close[0]], uniq[close[0] + 1]
        raise ValueError(f"convergence_ratios: spacings {a!r} and {b!r} differ by {b / a - 1:.2g} (relative), "
                         f"less than {MIN_SPACING_STEP:g}: one spacing written two ways? Their ratio has no slope")
    order = np.argsort(-s)
    s, v = s[order], v[order]
    rows = []
    for i in range(len(s) - 1):
        ratio = v[i + 1] / v[i]
        rows.append({"spacing_coarse": s[i], "spacing_fine": s[i + 1], "ratio": ratio,
                     "local_slope": math.log(ratio) / math.log(s[i + 1] / s[i])})
    return pd.DataFrame(rows, columns=["spacing_coarse", "spacing_fine", "ratio", "local_slope"])


@dataclass(frozen=True)
class ZeroCrossing(_Interval):
    """Where a straight-line fit of ``slope(alpha)`` crosses zero, with its interval."""

    value_name = "alpha"
    alpha: float
    stderr: float
    ci_low: float
    ci_high: float
    intercept: float
    gradient: float          # d slope / d alpha (Boussinesq and local: 4)
    n: int
    confidence: float = CONFIDENCE


def convergent_alpha(alphas, slopes, confidence: float = CONFIDENCE) -> ZeroCrossing:
    """The alpha at which F_max stops depending on the spacing.

    Fits slope = a + b alpha by OLS over the measured spacing slopes and returns
    alpha* = -a/b. Its standard error comes from the fit's covariance by the delta
    method, var(alpha*) = (var a + alpha*^2 var b + 2 alpha* cov ab) / b^2, and the
    interval uses Student-t on n - 2 degrees of freedom.

    Needs two distinct alphas (slopes at one alpha say nothing about d slope/d alpha).
    A slope that does not change with alpha (b zero to rounding) has no crossing and is
    refused. If b is not significantly nonzero (its own interval contains 0), the
    crossing's confidence set is unbounded (Fieller's theorem) and the interval is
    returned as (-inf, inf), where the delta method would give a finite but meaningless one."""
    _check_confidence(confidence, "convergent_alpha")
    a_, s_ = _clean(alphas, slopes, "convergent_alpha", ("alphas", "slopes"))
    _two_distinct(a_, "convergent_alpha", "alphas")
    n = a_.size
    X = np.column_stack([np.ones(n), a_])
    coef, *_ = np.linalg.lstsq(X, s_, rcond=None)
    a, b = float(coef[0]), float(coef[1])
    # the fitted change of slope over the alphas, against rounding of the slopes
    if abs(b) * float(np.ptp(a_)) <= 1e-12 * float(np.max(np.abs(s_))):
        raise ValueError(f"convergent_alpha: the slopes do not change with alphas (d slope/d alpha = {b:.3g}): "
                         "no zero crossing")
    root = -a / b
    dof = n - 2
    se = half = math.inf
    if dof > 0:
        resid = s_ - X @ coef
        s2 = float(resid @ resid) / dof
        cov = s2 * np.linalg.inv(X.T @ X)
        t = _t_quantile(dof, confidence)
        if abs(b) > t * math.sqrt(cov[1, 1]):
            var = (cov[0, 0] + root ** 2 * cov[1, 1] + 2 * root * cov[0, 1]) / b ** 2
            se = math.sqrt(max(var, 0.0))
            half = t * se
    return ZeroCrossing(root, se, root - half, root + half, a, b, n, confidence)


def _column_list(names, what: str, table: pd.DataFrame) -> list[str]:
    """Column names given as one name or several, each a column of ``table``: a single
    string was split into its characters."""
    names = [names] if isinstance(names, str) else list(names)
    missing = [n for n in names if n not in table.columns]
    if missing:
        raise ValueError(f"{what}: no column {', '.join(map(repr, missing))} in the table "
                         f"(its parameter columns: {', '.join(c for c in table.columns if c.startswith('p_'))})")
    return names


def _distinct(values: pd.Series) -> int:
    """How many different values a column holds, a missing one (None, NaN: an unset
    optional parameter) counting as a value of its own. astype(str).nunique() left NaN
    out under pandas 3, and runs with and without a parameter became one ensemble."""
    return values.astype(object).where(values.notna(), "<missing>").astype(str).nunique()


def kernel_slopes(summary: pd.DataFrame, value: str = "r_pull_off_force",
                  by: tuple[str, ...] = ("p_kernel", "p_alpha")) -> pd.DataFrame:
    """One spacing slope per group of a campaign summary (default: per kernel and alpha).

    Refused, naming the group: two runs at one spacing (they differ in a parameter that
    is not in ``by``, which is named: runs at other radii, self terms or seeds were pooled
    into one fit), a value that is missing or not positive (no log), and a group with one
    spacing; these used to be pooled or left out without a word."""
    rows = []
    by = _column_list(by, "kernel_slopes: by", summary)
    _column_list([value, "p_spacing"], "kernel_slopes", summary)
    for key, g in summary.groupby(by, sort=True, dropna=False):
        group = dict(zip(by, key if isinstance(key, tuple) else (key,)))
        repeated = g[g["p_spacing"].duplicated(keep=False)]
        if len(repeated):
            differ = [c for c in g.columns if c.startswith("p_") and c not in by
                      and repeated.groupby("p_spacing")[c].agg(_distinct).max() > 1]
            advice = (f"they differ in {', '.join(differ)}: give by={(*by, *differ)!r} for one fit each"
                      if differ else "they are one run repeated: drop the duplicates")
            raise ValueError(f"kernel_slopes: the group {group} has {len(repeated)} runs at "
                             f"{repeated['p_spacing'].nunique()} spacing(s); {advice}")
        bad = g[~(pd.to_numeric(g[value], errors="coerce") > 0)]
        if len(bad):
            raise ValueError(f"kernel_slopes: the group {group} has {len(bad)} run(s) whose {value} is missing "
                             f"or not > 0 (spacings {', '.join(_fraction(h) for h in bad['p_spacing'])}): a "
                             "power law has no log there; leave those rows out of the table first")
        if len(g) < 2:
            raise ValueError(f"kernel_slopes: the group {group} has one spacing only "
                             f"({_fraction(g['p_spacing'].iloc[0])}): a slope needs two")
        fit = spacing_slope(g["p_spacing"], g[value])
        rows.append({**group, "slope": fit.exponent, "stderr": fit.exponent_stderr,
                     "ci_low": fit.ci_low, "ci_high": fit.ci_high, "n": fit.n,
                     "spacings": ", ".join(_fraction(s) for s in sorted(g["p_spacing"], reverse=True))})
    return pd.DataFrame(rows)


def hertz_errors(curve: pd.DataFrame, radius: float, spacing: float, min_fraction: float = 0.25) -> dict:
    """Loading-branch error against Hertz: force at the deepest point and the worst
    relative force error for indentations above ``min_fraction`` of the deepest one
    (the shallow start has a contact only a few springs wide), plus the contact radius
    error in spacings."""
    from .theory import hertz_force, hertz_radius

    curve = in_step_order(curve)
    load = curve[curve["phase"] == "load"]
    load = load[load["indent"] > 0]
    if load.empty:
        raise ValueError("hertz_errors: the curve has no loading step with indent > 0")
    deepest = load.iloc[-1]
    p_th = float(hertz_force(deepest["indent"], radius))
    deep = load[load["indent"] >= min_fraction * deepest["indent"]]
    rel = deep["force"].to_numpy() / hertz_force(deep["indent"].to_numpy(), radius) - 1.0
    a_err = deep["contact_radius"].to_numpy() - hertz_radius(deep["indent"].to_numpy(), radius)
    return {"indent": float(deepest["indent"]), "force": float(deepest["force"]), "hertz_force": p_th,
            "force_error": float(deepest["force"] / p_th - 1.0),
            "max_abs_force_error": float(np.max(np.abs(rel))),
            "contact_radius_over_spacing": float(deepest["contact_radius"] / spacing),
            "max_abs_radius_error_spacings": float(np.max(np.abs(a_err)) / spacing)}


def _fraction(s: float) -> str:
    inv = 1.0 / s
    return f"1/{inv:.0f}" if abs(inv - round(inv)) < 1e-6 else f"{s:.4g}"


fraction_text = _fraction


# ---- the continuum limit: y = y_inf + C x^-p ----------------------------------------
# The convergence exponent p is searched on a log grid over this range. At p -> 0 the
# term C x^-p becomes a constant and y_inf and C can no longer be told apart, so the
# lower bound is what keeps y_inf finite; a fit whose p interval reaches it says so.
LIMIT_P_BOUNDS = (0.05, 5.0)
LIMIT_P_GRID = 4001


@dataclass(frozen=True)
class LimitFit:
    """``y = y_inf + C x**-p`` fitted by least squares with profile-likelihood intervals.

    The confidence set is {(y_inf, C, p): RSS <= RSS_min (1 + F_q(1, n-3) / (n-3))}, the
    profile likelihood of one parameter under Gaussian errors of unknown variance
    (Bates & Watts, *Nonlinear Regression Analysis*, 1988, Sec. 6.1). For a fixed p the
    model is linear, so the set is an ellipse in (y_inf, C) and its extent is exact;
    p runs over a grid. ``y_inf`` is the limit x -> infinity (here a_c/spacing)."""

    y_inf: float
    y_inf_low: float
    y_inf_high: float
    c: float
    p: float
    p_low: float
    p_high: float
    rss: float
    n: int
    p_bounds: tuple[float, float] = LIMIT_P_BOUNDS
    confidence: float = CONFIDENCE
    _grid: tuple = field(default=(), repr=False, compare=False)   # (p, y_inf, C, rss, (X'X)^-1, threshold) per p

    @property
    def sigma(self) -> float:
        """Residual standard deviation of the best fit."""
        return math.sqrt(self.rss / max(self.n - 3, 1))

    @property
    def p_open(self) -> tuple[bool, bool]:
        """Whether the p interval reaches the search bounds (then it is open there)."""
        lo, hi = self.p_bounds
        return (self.p_low <= lo * (1 + 1e-9), self.p_high >= hi * (1 - 1e-9))

    @property
    def p_at_bound(self) -> bool:
        lo, hi = self.p_bounds
        return self.p <= lo * (1 + 1e-6) or self.p >= hi * (1 - 1e-6)

    def contains(self, value: float) -> bool:
        return self.y_inf_low <= value <= self.y_inf_high

    def predict(self, x):
        return self.y_inf + self.c * np.asarray(x, dtype=float) ** -self.p

    def band(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper edge of the model curves in the confidence set at each x (at
        x = inf this is the y_inf interval)."""
        p = self._grid[0]
        x = np.atleast_1d(np.asarray(x, dtype=float))
        z = np.where(np.isinf(x)[None, :], 0.0, x[None, :] ** -p[:, None])
        lo, hi = _limit_extent(self._grid, z)
        return lo, hi

    def text(self, digits: int = 3) -> str:
        """y_inf [low, high]; when the p interval reaches a search bound, the y_inf interval
        holds only for p within the bounds, and says so (2 + x^-0.01 gave '2.770 [2.763,
        2.860]' without a word, the true 2 outside it)."""
        out = self.interval_text(digits)
        lo, hi = self.p_open
        if lo or hi:
            out += f" (if p {'≥' if lo else '≤'} {self.p_bounds[0 if lo else 1]:g}: p {self.p_text()})"
        return out

    def interval_text(self, digits: int = 3) -> str:
        """y_inf [low, high] alone, for a table whose p column says the rest (p_text)."""
        return f"{self.y_inf:.{digits}f} [{self.y_inf_low:.{digits}f}, {self.y_inf_high:.{digits}f}]"

    def p_text(self, digits: int = 2) -> str:
        lo, hi = self.p_open
        left = "≤" if lo else ""
        right = "≥" if hi else ""
        return f"{self.p:.{digits}f} [{left}{self.p_low:.{digits}f}, {right}{self.p_high:.{digits}f}]"

    def crossing(self, value: float) -> float:
        """The x at which the best-fit curve equals ``value`` (nan if it never does)."""
        ratio = (value - self.y_inf) / self.c if self.c != 0 else math.nan
        return ratio ** (-1.0 / self.p) if ratio > 0 else math.nan


def _limit_extent(grid, z) -> tuple[np.ndarray, np.ndarray]:
    """min and max of y_inf + C z over the confidence set, for z = x^-p per grid row."""
    p, y0, c, rss, inv, threshold = grid
    ok = rss <= threshold
    slack = np.clip(threshold - rss[ok], 0.0, None)
    # g = (1, z): centre y0 + C z, half-width sqrt(slack g' (X'X)^-1 g)
    zz = z[ok]
    centre = y0[ok, None] + c[ok, None] * zz
    quad = inv[ok, 0, 0, None] + 2.0 * inv[ok, 0, 1, None] * zz + inv[ok, 1, 1, None] * zz * zz
    half = np.sqrt(slack[:, None] * np.clip(quad, 0.0, None))
    return (centre - half).min(axis=0), (centre + half).max(axis=0)


def fit_limit(x, y, confidence: float = CONFIDENCE, p_bounds: tuple[float, float] = LIMIT_P_BOUNDS) -> LimitFit:
    """Fit ``y = y_inf + C x**-p`` (y_inf, C, p free) with profile-likelihood intervals.

    For each p on a log grid over ``p_bounds`` the model is linear in (y_inf, C) and is
    solved exactly; the best p minimises the residual sum of squares. The interval of
    y_inf is its extent over the confidence set (see ``LimitFit``), that of p the grid
    points whose best RSS is under the threshold. Needs at least four points."""
    _check_confidence(confidence, "fit_limit")
    x, y = _clean(x, y, "fit_limit")
    if np.any(x <= 0):
        raise ValueError("fit_limit: x must be > 0")
    n = x.size
    if n < 4:
        raise ValueError(f"fit_limit: three free parameters need at least four points, got {n}")
    if np.unique(x).size < 3:
        raise ValueError("fit_limit: need at least three distinct x")
    lo, hi = p_bounds
    if not 0 < lo < hi < math.inf:         # an infinite bound reached SciPy's own error
        raise ValueError(f"fit_limit: p_bounds must satisfy 0 < low < high < inf, got {p_bounds}")
    p = np.geomspace(lo, hi, LIMIT_P_GRID)
    z = x[None, :] ** -p[:, None]                       # (grid, n)
    s0, s1 = float(n), z.sum(axis=1)
    s11 = (z * z).sum(axis=1)
    sy, szy = y.sum(), (z * y[None, :]).sum(axis=1)
    det = s0 * s11 - s1 * s1
    with np.errstate(divide="ignore", invalid="ignore"):
        y0 = (s11 * sy - s1 * szy) / det
        c = (s0 * szy - s1 * sy) / det
    resid = y[None, :] - y0[:, None] - c[:, None] * z
    rss = (resid * resid).sum(axis=1)
    good = np.isfinite(rss) & (det > 1e-14 * s0 * s11)
    if not good.any():
        raise ValueError("fit_limit: the model is degenerate for every p (x nearly constant?)")
    rss = np.where(good, rss, np.inf)
    k = int(np.argmin(rss))
    rss_min = float(rss[k])
    dof = n - 3
    threshold = rss_min * (1.0 + float(stats.f.ppf(confidence, 1, dof)) / dof) if dof > 0 else math.inf
    inv = np.empty((p.size, 2, 2))
    inv[:, 0, 0], inv[:, 0, 1], inv[:, 1, 1] = s11 / det, -s1 / det, s0 / det
    inv[:, 1, 0] = inv[:, 0, 1]
    grid = (p, y0, c, rss, inv, threshold)
    inside = np.flatnonzero(rss <= threshold)
    ylo, yhi = _limit_extent(grid, np.zeros((p.size, 1)))
    # refine the best p between its grid neighbours (the grid step is 0.1 % in p)
    best = optimize.minimize_scalar(lambda q: _limit_linear(x, y, q)[2], method="bounded",
                                    bounds=(p[max(k - 1, 0)], p[min(k + 1, p.size - 1)]))
    pk, y0k, ck, rssk = (float(best.x), *_limit_linear(x, y, float(best.x))) if best.fun < rss_min else \
        (float(p[k]), float(y0[k]), float(c[k]), rss_min)
    return LimitFit(y0k, float(min(ylo[0], y0k)), float(max(yhi[0], y0k)), ck, pk,
                    float(min(p[inside.min()], pk)), float(max(p[inside.max()], pk)), rssk, n, (lo, hi),
                    confidence, grid)


def _limit_linear(x, y, p: float) -> tuple[float, float, float]:
    """(y_inf, C, RSS) of the linear least-squares fit at a fixed p."""
    X = np.column_stack([np.ones_like(x), x ** -p])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    return float(coef[0]), float(coef[1]), float(r @ r)


def step_sampling_bound(curve: pd.DataFrame, window: int = 10) -> float:
    """How much the sampled pull-off force can miss the top of the force curve, relative.

    Between two snaps the contact set is fixed and the tension grows linearly with the
    unloading; F_max is sampled once per step, so it misses the top of the last such
    rise by up to one step's rise. Returns the largest tension rise over one step with no
    snap and no entry, among the ``window`` steps before the pull-off, over F_max.

    On fine grids every step near the pull-off snaps some springs, and no rise is seen
    whole. Then the rise is the one a fixed contact of the pull-off radius a would make
    over that step: the unloading stiffness of a Boussinesq contact of radius a is the
    flat punch's, 2 E* a, whatever the shape (Johnson 1985, Sec. 5.5; on the 57 paraboloid
    limit runs that have quiet rises the two agree within 2 %). nan if neither is available."""
    c = curve.sort_values("step")
    tension = -c["force"].to_numpy()
    k = int(np.argmax(tension))
    if tension[k] <= 0:
        return math.nan
    quiet = (c["n_snapped"].to_numpy() == 0) & (c["n_entered"].to_numpy() == 0)
    rises = [tension[i] - tension[i - 1] for i in range(max(1, k - window), k + 1)
             if quiet[i] and c["phase"].iloc[i] == "unload" and c["phase"].iloc[i - 1] == "unload"]
    rises = [r for r in rises if r > 0]
    if rises:
        return float(max(rises) / tension[k])
    if k == 0 or not {"d", "contact_radius"} <= set(c.columns):
        return math.nan
    from .theory import flat_punch_force
    d = c["d"].to_numpy()
    return float(flat_punch_force(abs(d[k] - d[k - 1]), c["contact_radius"].iloc[k]) / tension[k])


@dataclass(frozen=True)
class Plateau(_Interval):
    """Mean of y over the points with x >= x_min, with a Student-t interval; the points
    averaged lie in [x_low, x_high]."""

    value_name = "mean"
    mean: float
    ci_low: float
    ci_high: float
    n: int
    x_min: float
    drift: LineFit | None = None     # y against ln x over the same points
    confidence: float = CONFIDENCE
    x_low: float = math.nan
    x_high: float = math.nan

    def contains(self, value: float) -> bool:
        return self.ci_low <= value <= self.ci_high

    @property
    def enough(self) -> bool:
        """Whether the points can show a drift: at least PLATEAU_MIN_POINTS of them, over
        the top octaves (less one step of three per octave). Five points over 1.3 octaves
        passed as flat, with an interval that excluded the level of all 16."""
        span = math.log2(self.x_high / self.x_low) if self.x_low > 0 else 0.0
        return self.n >= PLATEAU_MIN_POINTS and span >= PLATEAU_OCTAVES - 1.0 / 3.0 - 1e-9

    @property
    def flat(self) -> bool:
        """Whether enough points show no drift: the interval of dy/d ln x contains 0."""
        return (self.enough and self.drift is not None
                and self.drift.ci_low <= 0.0 <= self.drift.ci_high)


# the plateau is taken over the top two octaves of x: far enough from the coarse end,
# with enough points (six at three per octave) for a t interval and a drift test
PLATEAU_OCTAVES = 2.0
PLATEAU_MIN_POINTS = 6


def plateau(x, y, confidence: float = CONFIDENCE) -> Plateau:
    """The level of y over the top ``PLATEAU_OCTAVES`` octaves of x.

    Where the limit fit cannot find a trend (its p interval open), this is the estimate
    that assumes none is left: it is only as good as that assumption, and says so by its
    width (the scatter of the points, e.g. the staircase of the discrete contact edge)."""
    _check_confidence(confidence, "plateau")
    x, y = _clean(x, y, "plateau")
    if x.size == 0:
        raise ValueError("plateau: need at least one point")
    x_min = float(x.max()) / 2.0 ** PLATEAU_OCTAVES
    keep = x >= x_min * (1 - 1e-12)
    sel = y[keep]
    n = sel.size
    mean = float(sel.mean())
    half = _t_quantile(n - 1, confidence) * float(sel.std(ddof=1)) / math.sqrt(n) if n > 1 else math.inf
    drift = fit_line(np.log(x[keep]), sel, confidence=confidence) if n > 2 else None
    return Plateau(mean, mean - half, mean + half, n, x_min, drift, confidence,
                   float(x[keep].min()), float(x[keep].max()))


# ---- ensembles over seeds (rough surfaces, disordered thresholds) -------------------
SEED_COLUMNS = ("p_roughness_seed", "p_disorder_seed", "p_seed")     # p_seed: the jittered layout's


def in_step_order(curve: pd.DataFrame) -> pd.DataFrame:
    """The curve's rows in the order of its steps: a path integral or "the deepest
    loading step" of rows in another order (a user's sort, a sample) was silently wrong."""
    if "step" in curve.columns and not curve["step"].is_monotonic_increasing:
        return curve.sort_values("step", kind="stable")
    return curve


def hysteresis(curve: pd.DataFrame) -> float:
    """Energy dissipated over the load-unload cycle: the area between the loading and
    unloading curves, the integral of P d(delta) along the whole path from first contact
    (delta = 0, P = 0) until no spring touches (P = 0). Trapezoidal in the steps. The last
    row is at the pull-off's indent under force control (and one step on under
    displacement control), so the loop closes with a drop at the jump: under force control
    the part of the unloading branch past the largest tension is never followed, and the
    hysteresis is smaller than under displacement control (1/64: 7.6e-5 against 1.25e-4)."""
    curve = in_step_order(_curve(curve, "hysteresis", ("indent", "force")))
    delta = np.concatenate([[0.0], curve["indent"].to_numpy(dtype=float)])
    force = np.concatenate([[0.0], curve["force"].to_numpy(dtype=float)])
    return float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(delta)))


def area_at_max_load(curve: pd.DataFrame) -> float:
    """Contact area at the step of largest compressive force (the end of loading)."""
    curve = _curve(curve, "area_at_max_load", ("force", "contact_area"))
    return float(curve["contact_area"].iloc[int(np.argmax(curve["force"].to_numpy()))])


def run_metrics(curve: pd.DataFrame) -> dict:
    """Pull-off force, hysteresis and contact area at maximum load of one run's curve."""
    curve = _curve(curve, "run_metrics", ("indent", "force", "contact_area"))
    tension = -float(curve["force"].min())
    return {"pull_off_force": tension if tension > 0 else 0.0,     # never -0.0 (a run without adhesion)
            "hysteresis": hysteresis(curve),
            "area_at_max_load": area_at_max_load(curve)}


def run_metrics_table(summary: pd.DataFrame, curves: pd.DataFrame) -> pd.DataFrame:
    """The campaign summary with one column per ``run_metrics`` entry (``m_<name>``)."""
    metrics = {rid: run_metrics(c) for rid, c in curves.groupby("run_id", sort=False)}
    out = summary.copy()
    for name in ("pull_off_force", "hysteresis", "area_at_max_load"):
        out["m_" + name] = [metrics[rid][name] if rid in metrics else math.nan for rid in out["run_id"]]
    return out


def ensemble_stats(summary: pd.DataFrame, curves: pd.DataFrame, by=None,
                   seeds=SEED_COLUMNS, confidence: float = CONFIDENCE) -> pd.DataFrame:
    """Mean and spread over seeds of pull-off force, hysteresis and area at maximum load.

    Runs are grouped by ``by`` (default: every swept ``p_`` column except the seed
    columns); within a group the seeds are the ensemble. Columns per metric: ``<m>_mean``,
    ``<m>_std`` (sample standard deviation, ddof = 1: the seed-to-seed scatter),
    ``<m>_ci`` (half-width of the Student-t interval of the mean), and ``n`` seeds."""
    _check_confidence(confidence, "ensemble_stats")
    table = run_metrics_table(summary, curves)
    # the default seed columns are those of every kind of run; columns named by the caller
    # must be there
    seeds = ([s for s in seeds if s in table.columns] if seeds is SEED_COLUMNS
             else _column_list(seeds, "ensemble_stats: seeds", table))
    if by is None:
        by = [c for c in table.columns if c.startswith("p_") and c not in seeds
              and _distinct(table[c]) > 1]
    by = _column_list(by, "ensemble_stats: by", table)
    rows = []
    groups = table.groupby(by, sort=True, dropna=False) if by else [((), table)]
    for key, g in groups:
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(by, key))
        row["n"] = len(g)
        for name in ("pull_off_force", "hysteresis", "area_at_max_load"):
            v = g["m_" + name].to_numpy(dtype=float)
            std = float(np.std(v, ddof=1)) if v.size > 1 else math.nan
            row[name + "_mean"] = float(np.mean(v))
            row[name + "_std"] = std
            row[name + "_ci"] = _t_quantile(v.size - 1, confidence) * std / math.sqrt(v.size) if v.size > 1 else math.nan
        rows.append(row)
    return pd.DataFrame(rows)
