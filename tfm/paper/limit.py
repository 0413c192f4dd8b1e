"""Beyond the paper: the continuum limit of the pull-off coefficient, with an error bar.

``tfm limit`` (``make limit``) runs ``campaigns/limit_sphere.toml`` and
``campaigns/limit_punch.toml`` (or resumes them), fits, per geometry and self term,

    y = y_inf + C (a/Δ)^-p,    y = F_max / (K² R) (paraboloid, a = a_c, the JKR radius)
                               y = F_max / F_Kendall (flat punch, a = its radius),

with ``tfm.analysis.fit_limit`` (profile-likelihood 95 % intervals), and writes
``results/limit/REPORT.md``, ``limit.png`` and ``summary.json``. The effective
toughness follows as K_eff/K_th = sqrt(y_inf / (3π²/4)) for the paraboloid and y_inf
for the punch (F ∝ K² R and F ∝ K a^1.5): a lattice constant would give the same K_eff
in both geometries. ``--analyse-only`` reads the runs stored so far without touching
the campaign's files, so it is safe while a campaign is still running.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from .. import analysis, theory
from ..analysis import fraction_text
from . import DEFAULT_OUT, LIMIT_CAMPAIGNS, POINTS_FILE  # the limit's files (defined in the package)

# fewest points for a fit with an interval (3 parameters + 2 degrees of freedom)
MIN_FIT_POINTS = 5
# The stability check refits without each point: y_inf, C and p from n - 1 points leave
# n - 4 degrees of freedom. With 1 or 2 the t quantile is 12.7 or 4.3 and every refit's
# interval holds the full fit's limit ("stable: yes" for 5 points of a/Δ 8-20, with a
# refit of [-18, 10]); from 3 (quantile 3.2) the check can fail.
LIMIT_PARAMETERS = 3
LOO_MIN_DOF = 3
REFERENCE = {"paraboloid": theory.JKR_COEFFICIENT, "flat punch": 1.0}
Y_LABEL = {"paraboloid": "F_max/(K_th² R)", "flat punch": "F_max/F_Kendall"}


# ---- the stored runs ---------------------------------------------------------------
def spec_ratio(params) -> float:
    """a/Δ of a run: the JKR critical radius (paraboloid) or the punch radius, in spacings."""
    if params.shape == "flat_punch":
        return params.radius / params.spacing
    k_eff = theory.effective_toughness(params.threshold_force, params.spacing)
    return theory.jkr_critical_radius(k_eff, params.radius) / params.spacing


def within_ratio(params, max_ratio: float) -> bool:
    """Whether a run's point counts as a_c/Δ <= max_ratio, as the campaign files name
    their points (8, 16, 32, ...): Δ = 1/n with n rounded to a whole number, so a point
    named 16 sits at 16.05; rounding n moves a/Δ by at most half of a (in lengths)."""
    ratio = spec_ratio(params)
    return ratio - 0.5 * ratio * params.spacing <= max_ratio * (1 + 1e-9)


def coefficient(params, f_max: float) -> float:
    """F_max over the continuum reference with K = K_eff: (K² R) or Kendall's force."""
    k_eff = theory.effective_toughness(params.threshold_force, params.spacing)
    if params.shape == "flat_punch":
        return f_max / theory.kendall_force(params.radius, theory.gamma_from_k(k_eff))
    return f_max / (k_eff ** 2 * params.radius)


def stored_points(geometry: str, spec, results_dir: Path) -> pd.DataFrame:
    """One row per stored run of the campaign (read-only: the run files, not the tables)."""
    from ..campaign import CampaignStore
    from ..results import read_checked

    store = CampaignStore.for_spec(spec, results_dir)
    rows = []
    for run in spec.runs:
        meta = store.run_metadata(run.run_id)
        if meta is None:
            continue
        s, p = meta["summary"], run.params
        curve = read_checked(store.run_path(run.run_id))
        rows.append({"geometry": geometry, "run_id": run.run_id, "self_term": p.self_term,
                     "spacing": p.spacing, "ratio": spec_ratio(p), "max_indent": p.delta_max,
                     "step": p.step, "F_max": s["pull_off_force"], "y": coefficient(p, s["pull_off_force"]),
                     "step_bound": analysis.step_sampling_bound(curve), "wall_time": s["wall_time"],
                     "warnings": s.get("warnings", ""), "source": _run_file_source(meta)})
    return pd.DataFrame(rows)


def _slowest(points: pd.DataFrame) -> str:
    if not len(points):
        return "none"
    row = points.loc[points["wall_time"].astype(float).idxmax()]
    return (f"{row['geometry']}, self term {row['self_term']:g}, a/Δ = {row['ratio']:.0f}, "
            f"{float(row['wall_time']) / 60:.1f} min")


def _run_file_source(meta: dict) -> str:
    """Where a stored run's point comes from: its run file, and the day it was computed."""
    started = str((meta.get("provenance") or {}).get("started_at") or "")[:10]
    return f"run file of {started}, full precision" if started else "run file, full precision"


# The points are kept with the report: every stored run's fit inputs, one row per run at
# full precision, keyed by run id (which names the run's whole parameter record). A later
# `tfm limit` takes a kept point for a run whose file is not in its results folder (a new
# clone, another machine) instead of computing the run again, so a campaign of many hours
# can be finished over several sittings and refitted from the table alone.
POINT_COLUMNS = ("geometry", "run_id", "self_term", "spacing", "ratio", "max_indent", "step", "F_max", "y",
                 "step_bound", "wall_time", "warnings", "source")


def kept_points(path: Path, specs: dict) -> pd.DataFrame:
    """The kept points of ``path`` whose run ids the campaigns still list, with their
    parameters and coefficients taken from the runs (`read_kept` says what else it found)."""
    return read_kept(path, specs)[0]


def read_kept(path: Path, specs: dict) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(kept points of the campaigns' runs, rows of ``path`` that match no run now, notes).

    A row is matched by run id and geometry; its parameter columns and coefficient are
    then the run's (a hand-edited self term or preload moved a point between fits). Rows
    that match no run (the campaign file changed) are not fitted, but they stay in the
    table that `tfm limit` writes back: they may be hours of compute."""
    from ..params import ParameterError

    empty = pd.DataFrame(columns=POINT_COLUMNS)
    if not path.exists():
        return empty, empty, []
    # a damaged table is refused by name: it gave pandas' and Python's tracebacks, and a
    # duplicated row counted as a "deeper preload" pair of itself (a 16240 % preload check)
    try:
        kept = pd.read_csv(path, dtype={"run_id": str, "warnings": str, "source": str}, keep_default_na=False)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:     # EmptyDataError too
        raise ParameterError(f"{path}: cannot be read as a points table of tfm limit ({exc})") from None
    missing = set(POINT_COLUMNS) - set(kept.columns)
    if missing:
        raise ParameterError(f"{path}: not a points table of tfm limit (missing {sorted(missing)})")
    f_max = pd.to_numeric(kept["F_max"], errors="coerce")
    if not (np.isfinite(f_max) & (f_max > 0)).all():
        bad = kept["run_id"][~(np.isfinite(f_max) & (f_max > 0))].tolist()
        raise ParameterError(f"{path}: F_max must be a finite number > 0 on every row; not on runs {bad[:5]}")
    kept["F_max"] = f_max.astype(float)
    # the results beside F_max: an empty wall_time (a hand edit) was summed as text
    for column, allow_empty in (("wall_time", False), ("step_bound", True)):
        text = kept[column].astype(str).str.strip()
        blank = (text == "") if allow_empty else pd.Series(False, index=text.index)
        value = pd.to_numeric(text, errors="coerce")          # "" -> NaN
        bad = ~(np.isfinite(value) & (value >= 0)) & ~blank
        if bad.any():
            raise ParameterError(f"{path}: {column} must be a number >= 0 on every row"
                                 + (" (or empty)" if allow_empty else "")
                                 + f"; not on runs {kept['run_id'][bad].tolist()[:5]}")
        kept[column] = value.astype(float)
    twice = kept["run_id"][kept["run_id"].duplicated()].unique().tolist()
    if twice:
        raise ParameterError(f"{path}: runs {twice[:5]} appear more than once; a points table holds one "
                             "row per run")
    runs = {run.run_id: (geometry, run) for geometry, spec in specs.items() for run in spec.runs}
    rows, other, moved = [], [], []
    for row in kept.to_dict("records"):
        if row["run_id"] in runs and runs[row["run_id"]][0] == row["geometry"]:
            p = runs[row["run_id"]][1].params
            # the run's record, not the table, says what the run was (the id is its hash)
            truth = dict(self_term=p.self_term, spacing=p.spacing, max_indent=p.delta_max, step=p.step)
            for key, value in truth.items():
                given = pd.to_numeric(pd.Series([row[key]]), errors="coerce").iloc[0]
                if not np.isclose(given, value, rtol=1e-9, atol=0.0):
                    moved.append(f"{row['run_id']} {key} {row[key]!s} (the run's: {value:g})")
            row.update(truth, ratio=spec_ratio(p), y=coefficient(p, row["F_max"]))
            rows.append(row)
        else:
            other.append(row)
    notes = []
    if moved:
        notes.append(f"{path}: {len(moved)} value(s) differ from the runs their run ids name, and the runs' are "
                     f"used: {'; '.join(moved[:3])}{' ...' if len(moved) > 3 else ''}")
    if other:
        notes.append(f"{path}: {len(other)} kept point(s) match no run of the limit campaigns now (a campaign "
                     f"file changed?), e.g. {other[0]['geometry']} {other[0]['run_id']}: they are not fitted, "
                     "and stay in the table written back")
    return (pd.DataFrame(rows, columns=POINT_COLUMNS), pd.DataFrame(other, columns=POINT_COLUMNS), notes)


def merge_points(stored: pd.DataFrame, kept: pd.DataFrame) -> pd.DataFrame:
    """Stored runs first; a kept point only where its run is not stored here."""
    if not len(stored):
        stored = pd.DataFrame(columns=POINT_COLUMNS)
    extra = kept[~kept["run_id"].isin(stored["run_id"])] if len(kept) else kept
    frames = [f for f in (stored, extra) if len(f)]
    return pd.concat(frames, ignore_index=True)[list(POINT_COLUMNS)] if frames else pd.DataFrame(columns=POINT_COLUMNS)


def write_points(path: Path, points: pd.DataFrame) -> None:
    """The points table (pandas writes each float as its shortest exact repr)."""
    # numbers sorted as numbers even when a row that matches no run holds text
    points[list(POINT_COLUMNS)].sort_values(
        ["geometry", "self_term", "spacing", "max_indent"], ascending=[True, True, False, True],
        key=lambda c: c if c.name == "geometry" else pd.to_numeric(c, errors="coerce")).to_csv(path, index=False)


def split_preloads(points: pd.DataFrame, main_preload: float | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(points at the campaign's main, shallowest preload; preload-independence pairs).
    ``main_preload``: the campaign's (`main_preloads`); without it, the shallowest point's,
    which makes the deeper series the main one when only its points are at hand."""
    if points.empty:
        return points, pd.DataFrame()
    if main_preload is None:
        main_preload = points["max_indent"].min()
    main = points[np.isclose(points["max_indent"], main_preload)].sort_values(["self_term", "ratio"])
    deep = points[~np.isclose(points["max_indent"], main_preload)]
    pairs = deep.merge(main[["self_term", "spacing", "max_indent", "F_max"]], on=["self_term", "spacing"],
                       suffixes=("_deep", ""))
    pairs["change"] = pairs["F_max_deep"] / pairs["F_max"] - 1.0
    return main.reset_index(drop=True), pairs.reset_index(drop=True)


# ---- the fits ------------------------------------------------------------------------
@dataclasses.dataclass
class LimitResult:
    geometry: str
    self_term: float
    points: pd.DataFrame
    fit: analysis.LimitFit | None
    pairs: pd.DataFrame
    level: analysis.Plateau | None = None
    _stability: dict | None = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def trend_found(self) -> bool:
        """Whether the fit pins p: its interval stays off the lower search bound, where
        y_inf and C stop being separable and y_inf runs off."""
        return self.fit is not None and not self.fit.p_open[0]

    @property
    def estimate(self) -> tuple[float, float, float, str]:
        """The limit y_inf (best, low, high) and where it comes from: the fit if it finds a
        trend, else the plateau of the top octaves (which assumes none is left)."""
        if self.trend_found:
            f = self.fit
            return f.y_inf, f.y_inf_low, f.y_inf_high, "fit"
        if self.level is not None and self.level.flat:
            lv = self.level
            return lv.mean, lv.ci_low, lv.ci_high, f"plateau, a/Δ {lv.x_low:.0f}–{lv.x_high:.0f}"
        return math.nan, math.nan, math.nan, "—"

    @property
    def why_no_estimate(self) -> str:
        """Why ``estimate`` has none: no trend to fit, and no plateau to take instead."""
        lv = self.level
        if lv is not None and not lv.enough:
            return (f"the fit cannot pin p, and {lv.n} points over {math.log2(lv.x_high / lv.x_low):.1f} "
                    f"octaves are too few to show a plateau")
        return "the fit cannot pin p and the top octaves still drift"

    @property
    def k_ratio(self) -> tuple[float, float, float]:
        """K_eff/K_th (best, low, high) from ``estimate``: y_inf itself for the punch (F ∝ K),
        sqrt(y_inf / (3π²/4)) for the paraboloid (F ∝ K²)."""
        vals = self.estimate[:3]
        if self.geometry == "flat punch":
            return vals
        ref = theory.JKR_COEFFICIENT
        return tuple(math.sqrt(v / ref) if v > 0 else math.nan for v in vals)

    def leave_one_out(self) -> list[tuple[float, analysis.LimitFit]]:
        """The fit without each point in turn: (the a/Δ left out, its fit)."""
        x, y = self.points["ratio"].to_numpy(), self.points["y"].to_numpy()
        return [(float(x[i]), analysis.fit_limit(np.delete(x, i), np.delete(y, i))) for i in range(x.size)]

    def stability(self) -> dict:
        """Whether the limit survives leaving out any one point: every such fit keeps the
        full fit's y_inf inside its 95 % interval, with p > 0 (issue 12's check). Computed
        once: the report's table and summary.json both read it."""
        if self._stability is not None:
            return self._stability
        loo = self.leave_one_out()
        full = self.fit.y_inf
        misses = [(x, f) for x, f in loo if not (f.y_inf_low <= full <= f.y_inf_high and f.p > 0)]
        worst_x, worst = max(loo, key=lambda xf: abs(xf[1].y_inf - full))
        # None: not assessable, the refits' intervals too wide to exclude anything
        assessable = len(self.points) - 1 - LIMIT_PARAMETERS >= LOO_MIN_DOF
        self._stability = {"stable": (not misses) if assessable else None,
                           "y_inf_min": min(f.y_inf for _, f in loo),
                           "y_inf_max": max(f.y_inf for _, f in loo), "p_min": min(f.p for _, f in loo),
                           "p_max": max(f.p for _, f in loo), "misses": misses, "worst": (worst_x, worst)}
        return self._stability

    @property
    def largest_ratio(self) -> float:
        return float(self.points["ratio"].max()) if len(self.points) else math.nan

    @property
    def preload_change(self) -> float:
        """The largest |F_max(deep)/F_max - 1| over the pairs (nan without pairs)."""
        return float(self.pairs["change"].abs().max()) if len(self.pairs) else math.nan


def main_preloads(specs: dict) -> dict[str, float]:
    """The main (shallowest) preload of each geometry's campaign."""
    return {g: min(run.params.delta_max for run in spec.runs) for g, spec in specs.items()}


def full_ratios(specs: dict) -> dict[str, float]:
    """The largest a/Δ of each geometry's campaign at its main preload."""
    main = main_preloads(specs)
    return {g: max(spec_ratio(r.params) for r in spec.runs if math.isclose(r.params.delta_max, main[g]))
            for g, spec in specs.items()}


def fit_all(points: pd.DataFrame, preloads: dict[str, float] | None = None) -> list[LimitResult]:
    """Fits per geometry and self term; ``preloads``: each campaign's main preload
    (`main_preloads`), else the shallowest point's."""
    out = []
    for geometry, _ in LIMIT_CAMPAIGNS:
        main, pairs = split_preloads(points[points["geometry"] == geometry] if len(points) else points,
                                     (preloads or {}).get(geometry))
        for st in sorted(set(main["self_term"])) if len(main) else []:
            pts = main[main["self_term"] == st]
            fit = analysis.fit_limit(pts["ratio"], pts["y"]) if len(pts) >= MIN_FIT_POINTS else None
            level = analysis.plateau(pts["ratio"], pts["y"]) if len(pts) >= MIN_FIT_POINTS else None
            prs = pairs[pairs["self_term"] == st] if len(pairs) else pairs
            out.append(LimitResult(geometry, st, pts, fit, prs, level))
    return out


# ---- the figure ----------------------------------------------------------------------
def plot_limit(results: list[LimitResult], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    geometries = [g for g, _ in LIMIT_CAMPAIGNS if any(r.geometry == g for r in results)]
    fig, axes = plt.subplots(1, max(1, len(geometries)), figsize=(6.2 * max(1, len(geometries)), 4.6), squeeze=False)
    colors = {theory.SELF_TERM_MEAN: "tab:blue", theory.SELF_TERM_CENTRE: "tab:green", theory.PAPER_SELF_TERM: "tab:red"}
    for ax, geometry in zip(axes[0], geometries):
        for r in (r for r in results if r.geometry == geometry):
            color = min(colors.items(), key=lambda kv: abs(kv[0] - r.self_term))[1]
            inv = 1.0 / r.points["ratio"].to_numpy()
            ax.plot(inv, r.points["y"], "o", color=color, ms=4, label=f"self term {r.self_term:g}")
            if len(r.pairs):
                ax.plot(1.0 / (r.pairs["spacing"].map(dict(zip(r.points["spacing"], r.points["ratio"])))),
                        r.pairs["F_max_deep"] / r.pairs["F_max"] * r.pairs["spacing"].map(
                            dict(zip(r.points["spacing"], r.points["y"]))),
                        "x", color=color, ms=7, label="deeper preload" if r.self_term == results[0].self_term else None)
            best, lo_y, hi_y, source = r.estimate
            if r.trend_found:
                xs = np.linspace(0.0, inv.max() * 1.05, 200)
                ratio = np.where(xs > 0, 1.0 / np.maximum(xs, 1e-300), np.inf)
                lo, hi = r.fit.band(ratio)
                ax.fill_between(xs, lo, hi, color=color, alpha=0.18, lw=0)
                ax.plot(xs, r.fit.predict(np.where(np.isinf(ratio), 1e300, ratio)), "-", color=color, lw=1)
            elif r.level is not None and r.level.flat:        # no trend: the plateau of the top octaves
                xs = np.array([0.0, 1.0 / r.level.x_low])
                ax.fill_between(xs, [lo_y] * 2, [hi_y] * 2, color=color, alpha=0.18, lw=0)
                ax.plot(xs, [best] * 2, "--", color=color, lw=1)
            if math.isfinite(best):
                ax.errorbar([0.0], [best], yerr=[[best - lo_y], [hi_y - best]], fmt="s", color=color, ms=5, capsize=3)
        ref = REFERENCE[geometry]
        ax.axhline(ref, color="k", ls="--", lw=0.8,
                   label="JKR/LEFM 3π²/4" if geometry == "paraboloid" else "Kendall")
        if geometry == "paraboloid":
            ax.axhline(theory.PAPER_COEFFICIENT, color="0.5", ls=":", lw=1, label=f"paper {theory.PAPER_COEFFICIENT:g}")
        ax.set_xlim(left=-0.004)
        ax.set_xlabel("Δ/a" + ("_c (JKR critical radius)" if geometry == "paraboloid" else " (punch radius)"))
        ax.set_ylabel(Y_LABEL[geometry])
        ax.set_title(f"{geometry}: y∞ + C (a/Δ)^-p (solid) or plateau (dashed), 95 %", fontsize=9)
        # below the axes: inside, any corner covers points of some panel (the punch's
        # upper right held its Δ/a = 0.1 points)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- the report ----------------------------------------------------------------------
def paper_ratio_range(results_dir=None) -> tuple[float, float, float]:
    """(a_c/Δ min, max, spacing) of the paper's Fig. 6 runs, from its campaign file."""
    from .run import load_spec_for

    spec = load_spec_for("paper_fig6_jkr_scaling")
    ratios = [spec_ratio(r.params) for r in spec.runs if r.params.threshold_force > 0]
    return min(ratios), max(ratios), spec.runs[0].params.spacing


def units_note(para, full_ratio: float = math.inf) -> str:
    """Whether tfm.units' "limit" coefficients are these fits (to the 3 decimals they keep).
    ``full_ratio``: the largest a_c/Δ of the campaign; a fit short of it (a partial
    campaign) is no reason to change the constants, which came from the whole range."""
    from ..units import LIMIT_COEFFICIENTS
    fitted = {r.self_term: (round(r.estimate[0], 3), r) for r in para
              if r.estimate[3] == "fit" and math.isfinite(r.estimate[0])}
    differ = {s: (c, r) for s, (c, r) in fitted.items() if LIMIT_COEFFICIENTS.get(s) != c}
    whole = {s for s, (c, r) in fitted.items() if r.largest_ratio >= full_ratio * (1 - 1e-9)}
    # a constant in the code follows a fit only if that fit covers the campaign's whole
    # range and survives leaving out any point
    stale = [f"{s:g}: {LIMIT_COEFFICIENTS.get(s)} vs {c:.3f}" for s, (c, r) in differ.items()
             if r.stability()["stable"] and s in whole]
    partial = {s: (c, r) for s, (c, r) in differ.items() if r.stability()["stable"] and s not in whole}
    unsure = [f"{s:g}: {c:.3f}" for s, (c, r) in partial.items()]
    unstable = [f"{s:g}: {c:.3f}" for s, (c, r) in differ.items() if not r.stability()["stable"]]
    shaky = [s for s, (c, r) in fitted.items() if s in LIMIT_COEFFICIENTS and not r.stability()["stable"]]
    used = ", ".join(f"{c:.3f} (self term {s:g}" + (", a fit not stable without any one point: see Stability"
                                                     if s in shaky else "") + ")"
                     for s, c in LIMIT_COEFFICIENTS.items())
    if stale:
        return ("`k_th_coefficient = \"limit\"` still holds older values; update "
                f"`tfm.units.LIMIT_COEFFICIENTS` ({'; '.join(stale)}).")
    text = (f"`k_th_coefficient = \"limit\"` derives K_th from γ with these fitted c∞: {used} "
            "(`tfm.units.LIMIT_COEFFICIENTS`; a record stores the number).")
    if unsure:
        text += (f" These data fit other values ({'; '.join(unsure)}), but only up to a_c/Δ = "
                 f"{max(r.largest_ratio for c, r in partial.values()):.0f} of the campaign's "
                 f"{full_ratio:.0f}: no reason to change the constants until the campaign is complete.")
    if unstable:
        text += (f" These data fit other values ({'; '.join(unstable)}), but those fits are not shown "
                 "stable without any one point (Stability), so they are no reason to change them.")
    return text


def verdict_76(res: LimitResult) -> str:
    """What the limit at the paper's self term says about the paper's 7.6."""
    best, low, high, source = res.estimate
    c = theory.PAPER_COEFFICIENT
    if not math.isfinite(best):
        return (f"no verdict yet: at the a_c/Δ reached {res.why_no_estimate}, "
                "so there is no limit estimate to set beside it.")
    lo, hi, spacing = paper_ratio_range()
    where = f"the paper's fit at Δ = {fraction_text(spacing)} spans a_c/Δ = {lo:.0f}–{hi:.0f} in our units"
    cross = res.fit.crossing(c) if res.trend_found else math.nan
    at = f"; the fitted curve passes {c:g} at a_c/Δ ≈ {cross:.0f}" if math.isfinite(cross) else ""
    if low <= c <= high:
        return (f"{c:g} lies inside the 95 % interval of the limit ({source}), so these data cannot tell "
                f"it from a converged number ({where}{at}).")
    if c > high:
        return (f"{c:g} is above the 95 % interval of the limit ({source}): it is a value at the paper's "
                f"spacing, not a converged number ({where}{at}).")
    return (f"{c:g} is below the 95 % interval of the limit ({source}), which these data place higher "
            f"({where}{at}).")


def _interval(lo, best, hi, digits=3) -> str:
    return f"{best:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def _plateau_doubt(level: analysis.Plateau) -> str:
    if level.flat:
        return ""
    if not level.enough:
        return (f", too few points to tell: {level.n} over {math.log2(level.x_high / level.x_low):.1f} "
                f"octaves, {analysis.PLATEAU_MIN_POINTS} over {analysis.PLATEAU_OCTAVES:g} needed")
    return ", still drifting"


def summary_table(results: list[LimitResult]) -> pd.DataFrame:
    rows = []
    for r in results:
        f = r.fit
        k, klo, khi = r.k_ratio
        rows.append({
            "geometry": r.geometry, "self term": f"{r.self_term:g}", "points": len(r.points),
            "largest a/Δ": f"{r.largest_ratio:.0f}",
            "fit y∞ (95 %)": f.interval_text(3) if f else "—",     # p_text beside it
            "fit p (95 %)": f.p_text(2) if f else "—",
            "plateau (95 %)": (f"{r.level.mean:.3f} [{r.level.ci_low:.3f}, {r.level.ci_high:.3f}] "
                               f"(a/Δ {r.level.x_low:.0f}–{r.level.x_high:.0f}" + _plateau_doubt(r.level)
                               + ")") if r.level else "—",
            "K_eff/K_th (95 %)": f"{_interval(klo, k, khi)} ({r.estimate[3]})" if math.isfinite(k) else "—",
            "residual σ": f"{f.sigma:.3g}" if f else "—",
            "preload check: max |ΔF_max|": (f"{100 * r.preload_change:.2f} % ({len(r.pairs)} pairs)"
                                            if len(r.pairs) else "no pairs yet"),
            "step bound (max)": f"{100 * r.points['step_bound'].max():.2f} %",
        })
    return pd.DataFrame(rows)


def same_constant(results: list[LimitResult]) -> list[str]:
    """Whether the paraboloid and the punch give the same K_eff/K_th per self term."""
    out = []
    by = {(r.geometry, round(r.self_term, 4)): r for r in results if r.fit is not None}
    for (geometry, st), r in sorted(by.items()):
        if geometry != "paraboloid" or ("flat punch", st) not in by:
            continue
        a, b = r.k_ratio, by[("flat punch", st)].k_ratio
        if not (math.isfinite(a[0]) and math.isfinite(b[0])):
            out.append(f"- self term {st:g}: not yet comparable (no limit estimate for "
                       + " and ".join(g for g, v in (("the paraboloid", a), ("the punch", b)) if not math.isfinite(v[0]))
                       + ").")
            continue
        overlap = a[1] <= b[2] and b[1] <= a[2]
        out.append(f"- self term {st:g}: K_eff/K_th = {_interval(a[1], a[0], a[2])} (paraboloid) and "
                   f"{_interval(b[1], b[0], b[2])} (flat punch): "
                   + ("the intervals overlap, consistent with one lattice constant."
                      if overlap else f"the intervals do not overlap (difference {100 * (a[0] / b[0] - 1):+.1f} %): "
                      "not one constant at the a/Δ reached."))
    return out


def stability_section(results: list[LimitResult]) -> list[str]:
    """Leave-one-out refits of every paraboloid fit that pins p: a table and a verdict."""
    rows, notes = [], []
    for r in results:
        if r.geometry != "paraboloid" or not r.trend_found:
            continue
        st = r.stability()
        wx, wf = st["worst"]
        rows.append({"self term": f"{r.self_term:g}", "full fit y∞": f"{r.fit.y_inf:.3f}",
                     "y∞ without one point": f"{st['y_inf_min']:.3f}–{st['y_inf_max']:.3f}",
                     "p without one point": f"{st['p_min']:.2f}–{st['p_max']:.2f}",
                     "largest move": f"without a/Δ = {wx:.0f}: {wf.y_inf:.3f} [{wf.y_inf_low:.3f}, {wf.y_inf_high:.3f}], "
                                     f"p = {wf.p:.2f}",
                     "stable": {True: "yes", False: "no"}.get(st["stable"],
                                                                f"not assessable ({len(r.points)} points)")})
        if st["stable"] is False:
            left = ", ".join(f"{x:.0f}" for x, _ in st["misses"])
            notes.append(f"- self term {r.self_term:g}: without the point(s) at a/Δ = {left} the interval "
                         f"excludes the full fit's {r.fit.y_inf:.3f}. The limit then depends on whether those "
                         f"points belong to the asymptotic range: read it as {st['y_inf_min']:.2f}–"
                         f"{max(st['y_inf_max'], r.fit.y_inf):.2f}, not as the interval above.")
    if not rows:
        return []
    from .report import md_table

    return (["## Stability: the fit without any one point", "",
             "Each paraboloid fit that pins p, refitted once without each of its points. “Stable” means that "
             "every such fit keeps the full fit's y∞ inside its own 95 % interval, with p > 0. It needs "
             f"at least {LIMIT_PARAMETERS + LOO_MIN_DOF + 1} points: with fewer, the refits' intervals are "
             "too wide to exclude anything.", "",
             md_table(pd.DataFrame(rows)), ""] + notes + ([""] if notes else []))


def write_limit_report(out_dir: Path, points: pd.DataFrame, results: list[LimitResult], specs: dict,
                       wall: float, computed: int, jobs: int, start_load: float) -> dict:
    from .report import _link, machine, md_table
    from .run import CAMPAIGN_DIR, REPO

    report = out_dir / "REPORT.md"
    m = machine()
    pending = {g: len(spec.runs) - int((points["geometry"] == g).sum() if len(points) else 0) for g, spec in specs.items()}
    run_seconds = float(points["wall_time"].sum()) if len(points) else 0.0
    lines = [
        "# Beyond the paper: the continuum limit",
        "",
        "Generated by `tfm limit` (`make limit` for the default folders) on "
        f"{_dt.datetime.now().strftime('%Y-%m-%d %H:%M')}. Do not edit by hand. Back to the [paper report]"
        f"({_link(REPO / 'results' / 'paper' / 'REPORT.md', report)}).",
        "",
        "The paper's pull-off coefficient c = F_max/(K_th² R) = 7.6 was measured at one spacing. tfm's "
        "coefficient still falls as the JKR radius a_c grows in units of the spacing Δ, so here "
        "α = 0.75 runs are refined until a_c/Δ is large and fitted, per self term, with",
        "",
        "    y = y∞ + C (a/Δ)^-p        (y∞, C, p free; profile-likelihood 95 % intervals, `tfm.analysis.fit_limit`)",
        "",
        f"with y = F_max/(K_th² R) for the paraboloid (a = a_c; JKR/LEFM: 3π²/4 = {theory.JKR_COEFFICIENT:.3f}) and "
        "y = F_max/F_Kendall for a flat punch of radius a (Kendall: 2√π K a^1.5). The effective toughness "
        "is K_eff/K_th = √(y∞/(3π²/4)) (paraboloid) and y∞ (punch). Campaigns: "
        + ", ".join(f"[`{stem}`]({_link(CAMPAIGN_DIR / f'{stem}.toml', report)})" for _, stem in LIMIT_CAMPAIGNS)
        + " (their comments give every choice: preload, step, points).",
        "",
        "## Run",
        "",
        (f"- this `tfm limit`: {wall / 60:.1f} min wall with `--jobs {jobs}`, {computed} runs computed now; "
         if computed else "- this `tfm limit`: a refit of the points at hand, 0 runs computed now; ") +
        f"the {len(points)} runs' own compute time adds up to {run_seconds / 60:.1f} min "
        f"(the slowest: {_slowest(points)}).",
        "- points: " + ", ".join(f"{n} from {src}" for src, n in
                                 (points["source"].value_counts().items() if len(points) else [])) +
        f" (one row per run, with its source: [{POINTS_FILE}]({POINTS_FILE}); `tfm limit` computes only the "
        "runs it lacks).",
        f"- machine: {m['nproc']} cores, {m['cpu']}; load average {start_load:.1f} at the start and "
        f"{m['load'][0]:.1f} at the end (shared machine: times are pessimistic).",
        "- runs with a point / in the campaign: " + ", ".join(
            f"{g} {len(spec.runs) - pending[g]}/{len(spec.runs)}" for g, spec in specs.items()) + ".",
    ]
    if any(pending.values()):
        lines += [f"- **incomplete**: {sum(pending.values())} runs are still pending. Finish with the same "
                  "`tfm limit` command without --max-ratio or --where (`make limit` for the default folders; it "
                  "resumes; the largest a_c/Δ cost most).", ""]
    lines += ["", "## The limit per self term", "", md_table(summary_table(results)), "",
              "y∞ is F_max/(K_th² R) extrapolated to Δ → 0 for the paraboloid and F_max/F_Kendall for the punch. "
              "“step bound” is how much the sampled F_max can miss the top of the force curve (one step's rise "
              "just before the pull-off, `tfm.analysis.step_sampling_bound`; where every step there snaps "
              "springs, the rise of a fixed contact of the pull-off radius, stiffness 2E*a); “preload check” "
              "compares F_max at "
              "a deeper preload with the main one at the same spacing. A p interval marked ≤ or ≥ reaches the "
              f"search range {analysis.LIMIT_P_BOUNDS} and is open there.", ""]
    lines += stability_section(results)
    lines += ["## What it means", ""]
    para = [r for r in results if r.geometry == "paraboloid" and r.fit is not None]
    summary = {"generated": _dt.datetime.now().isoformat(timespec="seconds"), "fits": []}
    for r in results:
        if r.fit is not None:
            best, low, high, source = r.estimate
            summary["fits"].append({"geometry": r.geometry, "self_term": r.self_term, "y_inf": best,
                                    "y_inf_low": low, "y_inf_high": high, "source": source,
                                    "fit_y_inf": [r.fit.y_inf_low, r.fit.y_inf, r.fit.y_inf_high], "p": r.fit.p,
                                    "p_low": r.fit.p_low, "p_high": r.fit.p_high, "points": len(r.points),
                                    "largest_ratio": r.largest_ratio, "k_ratio": list(r.k_ratio),
                                    "preload_change": r.preload_change})
            if r.geometry == "paraboloid" and r.trend_found:
                st = r.stability()
                summary["fits"][-1].update(stable_without_any_one_point=st["stable"],
                                           y_inf_without_one_point=[st["y_inf_min"], st["y_inf_max"]])
    for r in para:
        best, low, high, source = r.estimate
        if not math.isfinite(best):
            lines.append(f"- paraboloid, self term {r.self_term:g}: no limit estimate yet ({r.why_no_estimate}); "
                         f"points up to a_c/Δ = {r.largest_ratio:.0f}.")
            continue
        p_txt = f"p = {r.fit.p_text(2)}" if r.trend_found else "no trend the fit can pin (p interval open)"
        lines.append(f"- paraboloid, self term {r.self_term:g}: c∞ = {best:.3f} [{low:.3f}, {high:.3f}] ({source}) "
                     f"against JKR/LEFM {theory.JKR_COEFFICIENT:.3f} ({100 * (best / theory.JKR_COEFFICIENT - 1):+.1f} %) "
                     f"and the paper's {theory.PAPER_COEFFICIENT:g} ({100 * (best / theory.PAPER_COEFFICIENT - 1):+.1f} %); "
                     f"{p_txt}; points up to a_c/Δ = {r.largest_ratio:.0f}."
                     + (" The JKR value lies inside the interval." if low <= theory.JKR_COEFFICIENT <= high else ""))
    for r in results:
        if r.geometry == "flat punch" and r.fit is not None:
            best, low, high, source = r.estimate
            if not math.isfinite(best):
                lines.append(f"- flat punch, self term {r.self_term:g}: no limit estimate yet ({r.why_no_estimate}); "
                             f"points up to a/Δ = {r.largest_ratio:.0f}.")
                continue
            lines.append(f"- flat punch, self term {r.self_term:g}: F_max/F_Kendall → {best:.3f} [{low:.3f}, {high:.3f}] "
                         f"({source}); " + (f"p = {r.fit.p_text(2)}" if r.trend_found else
                                            "the fit finds no trend beyond the scatter (p interval open)")
                         + f"; points up to a/Δ = {r.largest_ratio:.0f}.")
    paper_fit = next((r for r in para if abs(r.self_term - theory.PAPER_SELF_TERM) < 1e-9), None)
    if paper_fit is not None:
        v = verdict_76(paper_fit)
        lines.append(f"- **The paper's 7.6** (self term {theory.PAPER_SELF_TERM:g}): {v}")
        summary["verdict_76"] = v
        summary["paper_self_term_c_inf"] = list(paper_fit.estimate)
    same = same_constant(results)
    if same:
        lines += ["- **One lattice constant for both geometries?**"] + ["  " + s for s in same]
    if para:
        lines.append("- **In SI runs** " + units_note(para, full_ratios(specs)["paraboloid"]))
    if not para:
        lines.append("- no paraboloid fit yet (fewer than "
                     f"{MIN_FIT_POINTS} points per self term).")
    lines += ["", "![the continuum limit](limit.png)", "",
              "Filled circles: the main preload; crosses: the deeper preload at the same spacing; squares at "
              "Δ/a = 0: y∞ with its 95 % interval; bands: every curve of the 95 % confidence set.", "",
              "## Every point", ""]
    if len(points):
        tab = points.sort_values(["geometry", "self_term", "ratio", "max_indent"])[
            ["geometry", "self_term", "spacing", "ratio", "max_indent", "F_max", "y", "step_bound", "wall_time", "warnings",
             "source"]]
        tab = tab.assign(self_term=[f"{s:g}" for s in tab["self_term"]],      # 2.9732, as the other tables
                         spacing=[fraction_text(s) for s in tab["spacing"]],
                         step_bound=[f"{100 * b:.2f} %" for b in tab["step_bound"]])
        lines += [md_table(tab.rename(columns={"ratio": "a/Δ", "y": "y (coefficient)", "wall_time": "run s"})), ""]
    lines += ["## Reproduce", "", "```", "make limit JOBS=2      # tfm limit --jobs 2: runs, resumes, fits, writes this file",
              f"tfm limit --analyse-only   # refit and rewrite from the runs stored so far and {POINTS_FILE}", "```", ""]
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "REPORT.md").write_text("\n".join(lines) + "\n")
    summary["pending"] = pending
    # strict JSON (JavaScript's JSON.parse refuses NaN): a value that does not exist is null
    (out_dir / "summary.json").write_text(json.dumps(_strict(summary), indent=1, allow_nan=False) + "\n")
    return summary


def summary_line(out_dir: Path, report: Path | None = None) -> str | None:
    """One sentence for the paper report from ``results/limit/summary.json`` (None if absent);
    ``report``: where that report is written, for the link (default results/paper/)."""
    from .report import _link

    link = _link(Path(out_dir) / "REPORT.md", report) if report is not None else "../limit/REPORT.md"
    try:
        data = json.loads((Path(out_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    fit = next((f for f in data.get("fits", []) if f["geometry"] == "paraboloid"
                and abs(f["self_term"] - theory.PAPER_SELF_TERM) < 1e-9), None)
    if fit is None:
        return None
    if fit["y_inf"] is None:
        return (f"[Beyond the paper]({link}) has no limit estimate yet at self term "
                f"{theory.PAPER_SELF_TERM:g} ({fit['points']} spacings up to a_c/Δ = {fit['largest_ratio']:.0f}).")
    return (f"Extrapolated to Δ → 0 ([Beyond the paper]({link}): {fit['points']} spacings up to "
            f"a_c/Δ = {fit['largest_ratio']:.0f}), the coefficient at self term {theory.PAPER_SELF_TERM:g} tends to "
            f"{fit['y_inf']:.3f} [{fit['y_inf_low']:.3f}, {fit['y_inf_high']:.3f}] (95 %, {fit['source']}).")


def _strict(value):
    """``value`` for strict JSON: NaN and infinities as None, NumPy numbers as Python's."""
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if isinstance(value, (bool, str, type(None))):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    value = float(value)
    return value if math.isfinite(value) else None


def select_limit_runs(specs: dict, max_ratio: float | None, where) -> dict | None:
    """Run ids to compute now per geometry: a_c/Δ <= max_ratio and every KEY=VALUE of
    ``where`` (tfm.campaign.select_runs); None for all. A ``where`` that matches no run in
    either campaign is refused."""
    from ..campaign import CampaignError, select_runs

    if max_ratio is None and not where:
        return None
    only, errors, matching = {}, [], []
    for geometry, spec in specs.items():
        runs = spec.runs
        if where:
            try:
                runs = select_runs(spec, where)
            except CampaignError as exc:
                errors.append(exc)
                runs = ()
        matching += runs
        only[geometry] = {r.run_id for r in runs if max_ratio is None or within_ratio(r.params, max_ratio)}
    if len(errors) == len(specs):         # each campaign's reason (the first alone hid the others)
        raise CampaignError("; ".join(str(e) for e in errors)) if len(errors) > 1 else errors[0]
    if max_ratio is not None and not any(only.values()):
        # it said "nothing to run, 0 of 60 runs already done" and exited 0
        smallest = min(spec_ratio(r.params) for r in matching)      # of the runs --where keeps
        raise CampaignError(f"--max-ratio: no run{' that matches --where' if where else ''} has "
                            f"a_c/Δ <= {max_ratio:g}; the smallest is {smallest:.3g}")
    return only


def main_limit(args) -> int:
    from ..params import ParameterError
    from .report import machine
    from .run import load_spec_for, run_specs

    if args.jobs < 1:
        raise ParameterError(f"jobs: must be a whole number >= 1, got {args.jobs!r}")
    if args.max_ratio is not None and not args.max_ratio > 0:
        raise ParameterError(f"max-ratio: must be > 0, got {args.max_ratio!r}")
    if args.analyse_only:
        # options of the computing that --analyse-only would not use: its fit covers every
        # stored point, which a --where could be taken to have filtered
        from ..config import CHECKPOINT_EVERY
        unused = [flag for flag, used in (("--where", args.where), ("--max-ratio", args.max_ratio is not None),
                                          ("-j", args.jobs != 1),
                                          ("--checkpoint-every/--no-checkpoints",
                                           args.checkpoint_every != CHECKPOINT_EVERY)) if used]
        if unused:
            raise ParameterError(f"analyse-only: {', '.join(unused)}: options of computing runs, and "
                                 "--analyse-only computes none (its fit covers every stored point); drop them")
    out_dir = Path(args.out)
    if out_dir.exists() and not out_dir.is_dir():
        raise ParameterError(f"out: {out_dir} is a file, not a folder")
    # before any run: a path under a file was found only after hours of compute
    ancestor = next(a for a in (out_dir.absolute(), *out_dir.absolute().parents) if a.exists())
    if ancestor != out_dir.absolute() and not (ancestor.is_dir() and os.access(ancestor, os.W_OK)):
        raise ParameterError(f"out: cannot make the folder {out_dir}: {ancestor} is "
                             + ("not a folder" if not ancestor.is_dir() else "not writable"))
    t0 = time.perf_counter()
    start_load = machine()["load"][0]
    results_dir = Path(args.results_dir)
    if args.analyse_only and not results_dir.is_dir():
        print(f"[tfm limit] results-dir {results_dir} does not exist: only kept points are fitted",
              file=sys.stderr)
    specs = {geometry: load_spec_for(stem) for geometry, stem in LIMIT_CAMPAIGNS}
    computed = 0
    # the kept points travel with the report; a new --out starts from the default folder's
    source = out_dir / POINTS_FILE
    if not source.exists() and (Path(DEFAULT_OUT) / POINTS_FILE).exists():
        source = Path(DEFAULT_OUT) / POINTS_FILE
        print(f"[tfm limit] {out_dir / POINTS_FILE} does not exist: kept points from {source}", file=sys.stderr)
    kept, unmatched, notes = read_kept(source, specs)
    for note in notes:                      # even with -q: they are about kept compute
        print(f"[tfm limit] {note}", file=sys.stderr)
    only = select_limit_runs(specs, args.max_ratio, args.where)
    if not args.analyse_only:
        # a run with a kept point is not computed again
        wanted = only or {g: {r.run_id for r in spec.runs} for g, spec in specs.items()}
        only = {g: ids - set(kept["run_id"]) for g, ids in wanted.items()}
        done = run_specs(specs, args.jobs, results_dir, quiet=args.quiet, only=only,
                         checkpoint_every=args.checkpoint_every,
                         left_out_as=f"with a kept point in {source} or not selected" if len(kept)
                         else "not selected")
        computed = sum(n for _, n in done.values())
    frames = [stored_points(g, spec, results_dir) for g, spec in specs.items()]
    stored = pd.concat([f for f in frames if len(f)], ignore_index=True) if any(len(f) for f in frames) else pd.DataFrame()
    points = merge_points(stored, kept)
    if not len(points):
        print(f"tfm limit: nothing to report: no run of the limit campaigns is stored in {results_dir} "
              f"and no kept point in {source}; run `tfm limit` to compute them", file=sys.stderr)
        return 1
    results = fit_all(points, main_preloads(specs))
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"out: cannot make the folder {out_dir}: {exc.strerror or exc}") from None
    if len(points):
        write_points(out_dir / POINTS_FILE, pd.concat([points, unmatched], ignore_index=True)
                     if len(unmatched) else points)
    if results:
        plot_limit(results, out_dir / "limit.png")
    wall = time.perf_counter() - t0
    write_limit_report(out_dir, points, results, specs, wall, computed, args.jobs, start_load)
    if not args.quiet and results:
        from .report import md_table

        print(md_table(summary_table(results)))
    print(f"[tfm limit] wrote {out_dir / 'REPORT.md'} in {wall:.0f} s", file=sys.stderr)
    return 0
