"""Fits, exponents and convergence measures for the paper's scaling claims.

Hulikal, Bhattacharya & Lapusta, "A threshold-force model for adhesion and mode I
fracture", Sec. 3-4 (see ``shared/PHYSICS.md``):

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
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from scipy import stats

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


def _t_quantile(dof: int, confidence: float) -> float:
    if dof <= 0:
        return math.inf
    return float(stats.t.ppf(0.5 + confidence / 2.0, dof))


def _clean(x, y):
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"x and y must have the same shape, got {x.shape} and {y.shape}")
    return x, y


def fit_power_law(x, y, confidence: float = CONFIDENCE) -> PowerLawFit:
    """OLS fit of ln y = ln c + exponent ln x, with a Student-t interval on the exponent.

    Points with x <= 0 or y <= 0 have no logarithm and are refused (drop them first,
    e.g. the k_th = 0 run of the paper's Fig. 6a)."""
    x, y = _clean(x, y)
    if np.any(x <= 0) or np.any(y <= 0):
        raise ValueError("fit_power_law: x and y must be > 0 (log-log fit)")
    n = x.size
    if n < 2:
        raise ValueError("fit_power_law: need at least two points")
    lx, ly = np.log(x), np.log(y)
    sxx = float(np.sum((lx - lx.mean()) ** 2))
    if sxx == 0.0:
        raise ValueError("fit_power_law: all x are equal")
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
    """OLS straight line with a Student-t interval on the slope."""
    x, y = _clean(x, y)
    n = x.size
    if through_origin:
        sxx = float(np.sum(x * x))
        slope = float(np.sum(x * y) / sxx)
        inter = 0.0
        dof = n - 1
        resid = y - slope * x
    else:
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


def convergence_ratios(spacing, values) -> pd.DataFrame:
    """Successive refinement ratios: F(finer)/F(coarser) and the local slope between them.

    Rows are sorted from the coarsest spacing to the finest. ``local_slope`` is
    ln(F_i+1 / F_i) / ln(spacing_i+1 / spacing_i), the two-point estimate of the exponent."""
    s = np.asarray(spacing, dtype=float)
    v = np.asarray(values, dtype=float)
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
    interval uses Student-t on n - 2 degrees of freedom."""
    a_ = np.asarray(alphas, dtype=float)
    s_ = np.asarray(slopes, dtype=float)
    n = a_.size
    if n < 2:
        raise ValueError("convergent_alpha: need slopes at two alphas at least")
    X = np.column_stack([np.ones(n), a_])
    coef, *_ = np.linalg.lstsq(X, s_, rcond=None)
    a, b = float(coef[0]), float(coef[1])
    if b == 0:
        raise ValueError("convergent_alpha: the slope does not change with alpha")
    root = -a / b
    dof = n - 2
    if dof > 0:
        resid = s_ - X @ coef
        s2 = float(resid @ resid) / dof
        cov = s2 * np.linalg.inv(X.T @ X)
        var = (cov[0, 0] + root ** 2 * cov[1, 1] + 2 * root * cov[0, 1]) / b ** 2
        se = math.sqrt(max(var, 0.0))
        half = _t_quantile(dof, confidence) * se
    else:
        se = half = math.inf
    return ZeroCrossing(root, se, root - half, root + half, a, b, n, confidence)


def kernel_slopes(summary: pd.DataFrame, value: str = "r_pull_off_force",
                  by: tuple[str, ...] = ("p_kernel", "p_alpha")) -> pd.DataFrame:
    """One spacing slope per group of a campaign summary (default: per kernel and alpha)."""
    rows = []
    for key, g in summary.groupby(list(by), sort=True):
        g = g[g[value] > 0]
        if g["p_spacing"].nunique() < 2:
            continue
        fit = spacing_slope(g["p_spacing"], g[value])
        key = key if isinstance(key, tuple) else (key,)
        rows.append({**dict(zip(by, key)), "slope": fit.exponent, "stderr": fit.exponent_stderr,
                     "ci_low": fit.ci_low, "ci_high": fit.ci_high, "n": fit.n,
                     "spacings": ", ".join(_fraction(s) for s in sorted(g["p_spacing"], reverse=True))})
    return pd.DataFrame(rows)


def hertz_errors(curve: pd.DataFrame, radius: float, spacing: float, min_fraction: float = 0.25) -> dict:
    """Loading-branch error against Hertz: force at the deepest point and the worst
    relative force error for indentations above ``min_fraction`` of the deepest one
    (the shallow start has a contact only a few springs wide), plus the contact radius
    error in spacings."""
    from .theory import hertz_force, hertz_radius

    load = curve[curve["phase"] == "load"]
    load = load[load["indent"] > 0]
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


# ---- ensembles over seeds (rough surfaces, disordered thresholds) -------------------
SEED_COLUMNS = ("p_roughness_seed", "p_disorder_seed")


def hysteresis(curve: pd.DataFrame) -> float:
    """Energy dissipated over the load-unload cycle: the area between the loading and
    unloading curves, the integral of P d(delta) along the whole path from first contact
    (delta = 0, P = 0) until no spring touches (P = 0). Trapezoidal in the steps."""
    delta = np.concatenate([[0.0], curve["indent"].to_numpy(dtype=float)])
    force = np.concatenate([[0.0], curve["force"].to_numpy(dtype=float)])
    return float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(delta)))


def area_at_max_load(curve: pd.DataFrame) -> float:
    """Contact area at the step of largest compressive force (the end of loading)."""
    return float(curve["contact_area"].iloc[int(np.argmax(curve["force"].to_numpy()))])


def run_metrics(curve: pd.DataFrame) -> dict:
    """Pull-off force, hysteresis and contact area at maximum load of one run's curve."""
    return {"pull_off_force": float(max(-curve["force"].min(), 0.0)),
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
    table = run_metrics_table(summary, curves)
    seeds = [s for s in seeds if s in table.columns]
    if by is None:
        by = [c for c in table.columns if c.startswith("p_") and c not in seeds
              and table[c].astype(str).nunique() > 1]
    by = list(by)
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
